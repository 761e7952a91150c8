"""Where each dispenser's AprilTag is mounted on it (config/vision/node.yaml ``tag_mount``), as the
twin mounts it: beyond one end of the rack, just above its top slot, facing up.

One rule for everyone who needs it: vision's LocateTag turns a seen tag into the dispenser's frame
with it, the ARS moves its coarse dispenser poses with the tags of the mission being built, and the
coarse pose search aims the EE camera at the tag with it. The rule's settings are the vision
configuration's (``tag_mount`` in node.yaml, the tag's size in apriltag.yaml); :class:`TagMounting`
reads just those, so that an agent other than the vision can use the rule without the vision.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.config_schema import Field, load_yaml, validate
from tlt_common.geometry.transforms import pose_matrix, rpy_matrix

REPO_ROOT = Path(__file__).resolve().parents[3]
VISION_CONFIG = REPO_ROOT / "config" / "vision" / "node.yaml"
APRILTAG_CONFIG = REPO_ROOT / "config" / "vision" / "apriltag.yaml"
CELLS = 8  # a 36h11 tag's black square: 6x6 data bits and a one-cell black border

# node.yaml's ``tag_mount`` (m and rad): how far beyond the rack's end the tag stands, how high
# above the top slot, where the slots are, and where a rivet feeder carries it.
TAG_MOUNT_SCHEMA = {
    "end_gap": Field("float", minimum=0.0),
    "above_top": Field("float"),
    "first_slot_height": Field("float"),
    "slot_pitch": Field("float", minimum=0.0),
    "rivet_top": Field("float"),
    "rivet_extent": Field("float", minimum=0.0),
    "rpy": Field("list", item=Field("float"), check=lambda v: None if len(v) == 3 else "expected 3 numbers"),
}
# The part of apriltag.yaml that sizes the tag.
_TAG_SIZE_SCHEMA = {
    "printed_size": Field("float", minimum=1e-3, doc="m, including the quiet zone"),
    "quiet_zone_cells": Field("int", minimum=0),
}


def black_square_side(printed: float, quiet_zone_cells: int) -> float:
    """Side of a tag's black square, m, from the printed plate's side ``printed`` (quiet zone
    of ``quiet_zone_cells`` cells on each side included)."""
    return printed * CELLS / (CELLS + 2 * quiet_zone_cells)


def printed_size(tag_side: float) -> float:
    """Side of the printed tag plate, m: the black square ``tag_side`` is 8 of its 10 cells."""
    return tag_side * 10 / 8


def tag_mount(mount: Mapping[str, Any], mission: Any, dispenser: str, tag_side: float) -> np.ndarray:
    """The tag's frame (x right, y up as printed, z out of the face) in ``dispenser``'s frame.

    ``mount`` is node.yaml's ``tag_mount``; ``tag_side`` the black square's side, m (the printed
    plate, quiet zone included, is 10 of its 8 cells). A rivet feeder carries its tag at a fixed
    height; a part rack just above its top slot, which depends on how many parts it was filled with.
    """
    disp = mission.dispensers[dispenser]
    printed = printed_size(tag_side)
    if disp.part_kind == "rivet":
        extent, top = mount["rivet_extent"], mount["rivet_top"]
    else:
        cross_frame = disp.part_kind == "cross_frame"
        extent = mission.bay_width if cross_frame else mission.strut_lengths[disp.part_kind]
        top = mount["first_slot_height"] + max(disp.count - 1, 0) * mount["slot_pitch"]
    centre = (-(extent / 2 + mount["end_gap"] + printed / 2), 0.0, top + mount["above_top"])
    return pose_matrix(centre, rpy_matrix(mount["rpy"]))


@dataclass(frozen=True)
class TagMounting:
    """The settings of :func:`tag_mount`: node.yaml's ``tag_mount`` and the black square's side."""

    mount: Mapping[str, Any]
    tag_side: float  # m

    @classmethod
    def load(
        cls, vision_config: str | Path = VISION_CONFIG, apriltag_config: str | Path = APRILTAG_CONFIG
    ) -> TagMounting:
        """Read the two settings from the vision's files; ConfigError names a missing or bad one."""
        vision = load_yaml(vision_config)
        section = vision.get("tag_mount") if isinstance(vision, dict) else None
        mount = validate(section, TAG_MOUNT_SCHEMA, source=vision_config, prefix="tag_mount")
        tags = load_yaml(apriltag_config)
        if isinstance(tags, dict):  # the detector's settings are the vision's alone
            tags = {k: v for k, v in tags.items() if k in _TAG_SIZE_SCHEMA}
        size = validate(tags, _TAG_SIZE_SCHEMA, source=apriltag_config)
        return cls(mount, black_square_side(size["printed_size"], size["quiet_zone_cells"]))

    def pose(self, mission: Any, dispenser: str) -> np.ndarray:
        """The tag's frame in ``dispenser``'s frame (:func:`tag_mount`)."""
        return tag_mount(self.mount, mission, dispenser, self.tag_side)


__all__ = [
    "APRILTAG_CONFIG",
    "CELLS",
    "TAG_MOUNT_SCHEMA",
    "VISION_CONFIG",
    "TagMounting",
    "black_square_side",
    "printed_size",
    "tag_mount",
]
