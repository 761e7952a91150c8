"""The arms' own end effectors taken out of a frame's depth before the parts in it are posed.

A part presented for inspection sits in the jaws of an end effector whose rivet guns hang right
beside its end fittings. A learned mask strays onto them (Mask R-CNN's end-fitting masks took in a
whole gun: Chamfer p90 32 mm against a 2.5 mm threshold), and no depth cut can tell a gun from the
fitting at its side. The arms' joint states say where every EE body is, so, as robots filter
their own bodies out of their sensors, the pixels whose depth falls inside an EE box (grown by
``margin``) are given no depth: nothing of them reaches a cloud, and the free-space check
(:mod:`tlt_vision.pose.free_space`) does not count them either.

The boxes are configured in the flange frame with the width joint at 0 (node.yaml
``ee_self_filter``); a box on gripper b rides the width slide along flange x, as the EE cameras on
it do (:mod:`tlt_vision.frames`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from tlt_vision.pointcloud import PinholeIntrinsics


@dataclass(frozen=True)
class EeBox:
    """One body of an end effector: a box in the flange frame (width joint at 0)."""

    name: str
    centre: np.ndarray  # (3,) m
    half: np.ndarray  # (3,) half extents, m, along the flange axes
    on_width_slide: bool


def load_boxes(entries: Mapping[str, Mapping[str, Any]]) -> tuple[EeBox, ...]:
    """The validated ``ee_self_filter.boxes`` of node.yaml."""
    return tuple(
        EeBox(name, np.asarray(e["centre"], float), np.asarray(e["half"], float), bool(e["on_width_slide"]))
        for name, e in entries.items()
    )


def boxes_in_camera(
    boxes: Iterable[EeBox], camera_pose: np.ndarray, flange_pose: np.ndarray, width: float
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each box as its rotation (3x3) and centre (3) in the camera's optical frame, and its half
    extents; ``camera_pose`` and ``flange_pose`` are world poses (4x4), ``width`` the EE's width
    joint (m)."""
    to_camera = np.linalg.inv(camera_pose) @ flange_pose
    rot, origin = to_camera[:3, :3], to_camera[:3, 3]
    placed = []
    for box in boxes:
        centre = box.centre + (np.array([width, 0.0, 0.0]) if box.on_width_slide else 0.0)
        placed.append((rot, rot @ centre + origin, box.half))
    return placed


def drop_inside(
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    placed: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]],
    margin: float,
) -> tuple[np.ndarray, int]:
    """A copy of ``depth`` with no depth (0) wherever the point seen lies inside one of the
    ``placed`` boxes (:func:`boxes_in_camera`) grown by ``margin``; and how many pixels that was."""
    d = np.asarray(depth, dtype=np.float32)
    valid = np.isfinite(d) & (d > 0)
    v, u = np.nonzero(valid)
    z = d[v, u].astype(float)
    points = np.column_stack(
        [(u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z]
    )
    inside = np.zeros(len(points), dtype=bool)
    for rot, centre, half in placed:
        local = (points - centre) @ rot  # box frame = flange axes
        inside |= np.all(np.abs(local) <= half + margin, axis=1)
    out = d.copy()
    out[v[inside], u[inside]] = 0.0
    return out, int(np.count_nonzero(inside))


__all__ = ["EeBox", "boxes_in_camera", "drop_inside", "load_boxes"]
