"""Where each dispenser's AprilTag is mounted on it (config/vision/node.yaml ``tag_mount``), as the
twin mounts it: beyond one end of the rack, just above its top slot, facing up.

One rule for everyone who needs it: vision's LocateTag turns a seen tag into the dispenser's frame
with it, and the ARS's coarse pose search aims the EE camera at the tag with it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from tlt_common.geometry.transforms import pose_matrix, rpy_matrix


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
