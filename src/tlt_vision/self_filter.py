"""The arms' own end effectors taken out of a frame's depth before the parts in it are posed.

A part presented for inspection sits in the jaws of an end effector whose rivet guns hang right
beside its end fittings. A learned mask strays onto them (an end-fitting mask can take in a whole
gun, far past the certificate's threshold; a tube mask the jaws closed on the tube), and no depth
cut can tell a gun from the fitting at its side. The arms' joint states
say where every EE body is, so, as robots filter their own bodies out of their sensors, the pixels
whose depth falls inside an EE body (grown by ``margin``) are given no depth: nothing of them
reaches a cloud, and the free-space check (:mod:`tlt_vision.pose.free_space`) does not count them
either. A detection lying almost wholly on those pixels is of the end effector itself (a rivet gun
taken for an end fitting, whose mask keeps a fringe of depth at its edge and would fail a good strut
for "no depth"): :func:`off_own_ee` sets it aside before the part is chosen (``own_share``).

The bodies are configured in the flange frame with the width joint at 0 (node.yaml
``ee_self_filter``): boxes for the rigid ones, and a capsule for each jaw, turned about its hinge
(flange x) by its grasp joint. Those on gripper b ride the width slide along flange x, as the EE
cameras on it do (:mod:`tlt_vision.frames`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

from tlt_common.geometry.transforms import rot_x
from tlt_vision.detections import Detection
from tlt_vision.pointcloud import PinholeIntrinsics, back_project


@dataclass(frozen=True)
class EeBox:
    """One rigid body of an end effector: a box in the flange frame (width joint at 0)."""

    name: str
    centre: np.ndarray  # (3,) m
    half: np.ndarray  # (3,) half extents, m, along the flange axes
    on_width_slide: bool


@dataclass(frozen=True)
class EeJaw:
    """One jaw: a capsule from its hinge to its tip, hinged about flange x (width joint at 0)."""

    side: str  # "a" or "b": the grasp joint that turns it (the EE driver's grasp_left, grasp_right)
    hinge: np.ndarray  # (3,) m
    tip: np.ndarray  # (3,) m, with the grasp joint at 0 rad
    radius: float  # m
    on_width_slide: bool


class Shape(Protocol):
    def holds(self, points: np.ndarray, margin: float) -> np.ndarray: ...

    def bounds(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        """The corners (lowest, highest) of an axis-aligned box in the camera frame that holds
        every point :meth:`holds` takes."""
        ...


class PlacedBox(NamedTuple):
    """A box in the camera's optical frame: its axes (3x3 columns), centre and half extents."""

    rotation: np.ndarray
    centre: np.ndarray
    half: np.ndarray

    def holds(self, points: np.ndarray, margin: float) -> np.ndarray:
        local = (points - self.centre) @ self.rotation
        return np.all(np.abs(local) <= self.half + margin, axis=1)

    def bounds(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        reach = np.abs(self.rotation) @ (self.half + margin)
        return self.centre - reach, self.centre + reach


class PlacedCapsule(NamedTuple):
    """A capsule in the camera's optical frame: the segment ``start``-``end`` grown by ``radius``."""

    start: np.ndarray
    end: np.ndarray
    radius: float

    def holds(self, points: np.ndarray, margin: float) -> np.ndarray:
        d = self.end - self.start
        t = np.clip((points - self.start) @ d / float(d @ d), 0.0, 1.0)
        return np.linalg.norm(points - self.start - t[:, None] * d, axis=1) <= self.radius + margin

    def bounds(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        grow = self.radius + margin
        return np.minimum(self.start, self.end) - grow, np.maximum(self.start, self.end) + grow


@dataclass(frozen=True)
class EeSelfFilter:
    """The end effector's bodies (node.yaml ``ee_self_filter``) and the margin that grows them."""

    boxes: tuple[EeBox, ...]
    jaws: tuple[EeJaw, ...]
    margin: float
    own_share: float = 0.9  # of a detection's pixels on the end effectors: a detection of them

    @classmethod
    def from_config(cls, raw: Mapping[str, Any]) -> EeSelfFilter:
        """From the validated ``ee_self_filter`` of node.yaml."""
        boxes = tuple(
            EeBox(name, np.asarray(e["centre"], float), np.asarray(e["half"], float), e["on_width_slide"])
            for name, e in raw["boxes"].items()
        )
        jaws = tuple(
            EeJaw(
                side,
                np.asarray(e["hinge"], float),
                np.asarray(e["tip"], float),
                float(e["radius"]),
                bool(e["on_width_slide"]),
            )
            for side, e in raw.get("jaws", {}).items()
        )
        return cls(boxes, jaws, float(raw["margin"]), float(raw["own_share"]))

    @property
    def empty(self) -> bool:
        return not self.boxes and not self.jaws

    def place(
        self, camera_pose: np.ndarray, flange_pose: np.ndarray, width: float, jaw_angles: Mapping[str, float]
    ) -> list[Shape]:
        """Every body in the camera's optical frame; ``camera_pose`` and ``flange_pose`` are world
        poses (4x4), ``width`` the EE's width joint (m), ``jaw_angles`` its grasp joints by side
        (rad)."""
        to_camera = np.linalg.inv(camera_pose) @ flange_pose
        rot, origin = to_camera[:3, :3], to_camera[:3, 3]
        slide = np.array([width, 0.0, 0.0])

        def in_camera(p: np.ndarray, on_slide: bool) -> np.ndarray:
            return rot @ (p + slide if on_slide else p) + origin

        placed: list[Shape] = [
            PlacedBox(rot, in_camera(b.centre, b.on_width_slide), b.half) for b in self.boxes
        ]
        for jaw in self.jaws:
            tip = jaw.hinge + rot_x(jaw_angles[jaw.side]) @ (jaw.tip - jaw.hinge)
            placed.append(
                PlacedCapsule(
                    in_camera(jaw.hinge, jaw.on_width_slide), in_camera(tip, jaw.on_width_slide), jaw.radius
                )
            )
        return placed


def drop_inside(
    depth: np.ndarray, intrinsics: PinholeIntrinsics, placed: Iterable[Shape], margin: float
) -> tuple[np.ndarray, int]:
    """A copy of ``depth`` with no depth (0) wherever the point seen lies inside one of the
    ``placed`` shapes grown by ``margin``; and how many pixels that was.

    Each shape is tested only on the pixels that can see into its bounding box (a window of the
    image, and depths within the box's): the bodies cover a small part of a frame, and testing
    every pixel of a 640x480 frame against the twenty-odd bodies of two end effectors would take
    seconds."""
    d = np.asarray(depth, dtype=np.float32)
    out = d.copy()
    dropped = np.zeros(d.shape, dtype=bool)
    for shape in placed:
        window = _window(shape.bounds(margin), intrinsics, d.shape)
        if window is None:
            continue
        (v0, v1, u0, u1), (z_lo, z_hi) = window
        seen = d[v0:v1, u0:u1]
        v, u = np.nonzero(np.isfinite(seen) & (seen > 0) & (seen >= z_lo) & (seen <= z_hi))
        v, u = v + v0, u + u0
        inside = shape.holds(back_project(u, v, d[v, u].astype(float), intrinsics), margin)
        dropped[v[inside], u[inside]] = True
    out[dropped] = 0.0
    return out, int(np.count_nonzero(dropped))


def _window(
    bounds: tuple[np.ndarray, np.ndarray], intrinsics: PinholeIntrinsics, shape: tuple[int, ...]
) -> tuple[tuple[int, int, int, int], tuple[float, float]] | None:
    """The rows ``v0:v1`` and columns ``u0:u1`` whose pixels can see a point of the camera-frame
    box ``bounds``, and the depths they would see it at; None when it is all behind the camera."""
    (x_lo, y_lo, z_lo), (x_hi, y_hi, z_hi) = bounds
    height, width = shape[:2]
    if z_hi <= 0:
        return None
    if z_lo <= 0:  # the box reaches the camera's plane: a point of it may be seen anywhere
        return (0, height, 0, width), (z_lo, z_hi)
    # x / z over the box is extreme at its corners (z > 0), and a pixel's point has u = fx x / z + cx.
    us = [intrinsics.fx * x / z + intrinsics.cx for x in (x_lo, x_hi) for z in (z_lo, z_hi)]
    vs = [intrinsics.fy * y / z + intrinsics.cy for y in (y_lo, y_hi) for z in (z_lo, z_hi)]
    u0, u1 = max(int(np.floor(min(us))), 0), min(int(np.ceil(max(us))) + 1, width)
    v0, v1 = max(int(np.floor(min(vs))), 0), min(int(np.ceil(max(vs))) + 1, height)
    if u0 >= u1 or v0 >= v1:
        return None
    return (v0, v1, u0, u1), (z_lo, z_hi)


def own_pixels(depth: np.ndarray | None, filtered: np.ndarray | None) -> np.ndarray | None:
    """The pixels :func:`drop_inside` took out: a depth in ``depth``, none in ``filtered``."""
    if depth is None or filtered is None:
        return None
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0) & ~(filtered > 0)


def off_own_ee(detections: Sequence[Detection], own: np.ndarray | None, share: float) -> list[Detection]:
    """The ``detections`` with less than ``share`` of their mask's pixels among ``own`` (the end
    effectors' pixels, :func:`own_pixels`): the others are of the end effectors themselves. A part's
    mask that strays onto a gun beside it keeps most of its pixels off the gun, and stays."""
    if own is None or not own.any():
        return list(detections)
    kept = []
    for d in detections:
        pixels = np.count_nonzero(d.mask)
        if pixels == 0 or np.count_nonzero(d.mask & own) < share * pixels:
            kept.append(d)
    return kept


__all__ = [
    "EeBox",
    "EeJaw",
    "EeSelfFilter",
    "PlacedBox",
    "PlacedCapsule",
    "drop_inside",
    "off_own_ee",
    "own_pixels",
]
