"""What the generator made, for the scene and the assembly physics: the parts with their local
geometry, the cross frames grippers and rivets can hold, the tower's origin and the posts."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.mission.schema import Mission
from tlt_sim.model.scenario import Defect, Scenario


@dataclass
class PartInfo:
    """A loose part: where its features lie in its own body frame."""

    name: str  # <dispenser>/<index>
    body: str
    kind: str  # cross_frame, vertical, diagonal
    dispenser: str
    index: int
    length: float
    ends: dict[str, np.ndarray]  # strut: 'a', 'b'; cross frame: corner numbers as str
    grasps: list[tuple[np.ndarray, np.ndarray]]  # (point, axis) in the body frame
    slot_pos: np.ndarray
    slot_quat: np.ndarray
    defect: Defect | None = None
    # Half the length of tube along each grasp line, either side of its point: jaws close on it there.
    grasp_span: float = 0.0


@dataclass
class ModelInfo:
    xml_path: Path
    out_dir: Path
    edu: dict[str, Any]
    mission: Mission
    scenario: Scenario
    parts: dict[str, PartInfo] = field(default_factory=dict)
    cross_frames: list[str] = field(default_factory=list)  # bodies with corners: payload + cross frames
    top_level: float = 0.0
    tower_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    dispenser_tags: dict[str, int] = field(default_factory=dict)
    post_xy: list[np.ndarray] = field(default_factory=list)

    @property
    def struts(self) -> list[str]:
        return [p.body for p in self.parts.values() if p.kind != "cross_frame"]


__all__ = ["ModelInfo", "PartInfo"]
