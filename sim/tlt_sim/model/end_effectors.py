"""The ARS end effectors' signals and tool points in the twin: limit switch, rivet guns, grasp.

What an end effector's GPIO and its holder report (the width limit switch, a rivet gun loaded and
fired, the part in the grasp) and where its tool points lie in the EE frame at the present width.
The joins themselves (grasps, rivets) follow :mod:`tlt_sim.model.assembly`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tlt_sim.model import names
from tlt_sim.model.assembly import Assembly, RivetShot
from tlt_sim.model.servos import Servos


class EndEffectors:
    """The end effectors of the arms: their dimensions from the EDU description ``edu``, their
    width from ``servos``, their grasps and rivets from ``assembly``."""

    def __init__(self, edu: dict[str, Any], servos: Servos, assembly: Assembly) -> None:
        self.edu, self.servos, self.assembly = edu, servos, assembly

    def ee_point(self, arm: str, which: str) -> np.ndarray:
        """EE-frame point of ``which``: 'grasp' (midway between the grippers at the present width),
        'gun_a' or 'gun_b' (the rivet gun muzzles)."""
        e = self.edu["end_effector"]
        w = self.servos.position(names.width_joint(arm))
        s, d, g = e["grip_spacing"], e["grasp_depth"], e["rivet_gun_offset"]
        points = {"grasp": (w / 2, 0.0, d), "gun_a": (-s / 2 - g, 0.0, d), "gun_b": (s / 2 + w + g, 0.0, d)}
        return np.array(points[which])

    def limit_switch(self, arm: str) -> bool:
        """The EE limit switch: pressed while the width joint is at its zero."""
        return self.servos.position(names.width_joint(arm)) < self.edu["end_effector"]["limit_switch_below"]

    def load_rivet(self, arm: str, side: str) -> bool:
        return self.assembly.load_rivet(arm, side)

    def rivet_loaded(self, arm: str, side: str) -> bool:
        return self.assembly.loaded[(arm, side)]

    def fire_rivet(self, arm: str, side: str) -> RivetShot:
        return self.assembly.fire_rivet(arm, side)

    def holding(self, arm: str) -> str | None:
        return self.assembly.held[arm]


__all__ = ["EndEffectors"]
