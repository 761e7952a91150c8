"""Fixtures of the twin model tests: a scene per test and an arm mover built on the model's IK."""

from __future__ import annotations

import numpy as np
import pytest
from tlt_sim.model import ik, names
from tlt_sim.model.scene import Scene

from tlt_common.geometry.transforms import frame_from_axes as frame


@pytest.fixture
def scene(tmp_path):
    with Scene(out_dir=tmp_path / "model") as s:
        yield s


class Mover:
    """Moves an arm to Cartesian EE poses through the model's planner stand-in (ik.plan)."""

    def __init__(self, scene: Scene, arm: str) -> None:
        self.scene, self.arm = scene, arm

    def to(self, position, rotation, which: str = "grasp") -> None:
        s = self.scene
        waypoints = ik.plan(s.model, s.data.qpos, self.arm, position, rotation, s.ee_point(self.arm, which))
        assert waypoints is not None, f"no clear way to {position}"
        assert s.move_arm(self.arm, waypoints), "the arm did not reach its waypoints"

    def load_rivet(self, side: str, feeder: str) -> None:
        """Push gun ``side`` into ``feeder`` (tool down, the first heading with a clear way) and
        take a rivet."""
        s = self.scene
        pickup = s.site_position(f"dispenser/{feeder}/pickup")
        point = s.ee_point(self.arm, f"gun_{side}")
        for yaw in np.arange(8) * np.pi / 4:
            rotation = frame([np.cos(yaw), np.sin(yaw), 0.0], [0.0, 0.0, -1.0])
            waypoints = ik.plan(s.model, s.data.qpos, self.arm, pickup, rotation, point)
            if waypoints is not None:
                assert s.move_arm(self.arm, waypoints), "the arm did not reach its waypoints"
                assert s.load_rivet(self.arm, side)
                return
        raise AssertionError(f"no clear way to {feeder}'s pickup for gun {side}")

    def jaws(self, close: bool, settle_s: float = 0.8) -> None:
        opened, closed = self.scene.edu["end_effector"]["jaw_range"]
        for side in ("a", "b"):
            self.scene.command_position(names.grasp_joint(self.arm, side), closed if close else opened)
        self.scene.advance(settle_s)

    def pick(self, part: str, along: float = 0.0) -> None:
        """Grasp ``part`` where it lies, ``along`` its grasp line from its grasp point: tool down,
        grasp line along the part's axis."""
        s = self.scene
        info = s.part(part)
        pos, rot = s.body_pose(info.body)
        point, axis = info.grasps[0]
        target = pos + rot @ point + along * (rot @ axis)
        r = frame(rot @ axis, [0.0, 0.0, -1.0])
        self.to(target + np.array([0.0, 0.0, 0.1]), r)
        self.to(target, r)
        self.jaws(True)


@pytest.fixture
def mover():
    return Mover
