"""The arms' own end effectors taken out of a frame's depth before the parts in it are posed.

A part presented for inspection sits in the jaws of an end effector whose rivet guns hang right
beside its end fittings. A learned mask strays onto them (Mask R-CNN's end-fitting masks took in a
whole gun: Chamfer p90 32 mm against a 2.5 mm threshold; its tube masks took in the jaws closed on
the tube), and no depth cut can tell a gun from the fitting at its side. The arms' joint states
say where every EE body is, so, as robots filter their own bodies out of their sensors, the pixels
whose depth falls inside an EE body (grown by ``margin``) are given no depth: nothing of them
reaches a cloud, and the free-space check (:mod:`tlt_vision.pose.free_space`) does not count them
either.

The bodies are configured in the flange frame with the width joint at 0 (node.yaml
``ee_self_filter``): boxes for the rigid ones, and a capsule for each jaw, turned about its hinge
(flange x) by its grasp joint. Those on gripper b ride the width slide along flange x, as the EE
cameras on it do (:mod:`tlt_vision.frames`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

from tlt_ars.planning.kinematics import rot_x
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


class PlacedBox(NamedTuple):
    """A box in the camera's optical frame: its axes (3x3 columns), centre and half extents."""

    rotation: np.ndarray
    centre: np.ndarray
    half: np.ndarray

    def holds(self, points: np.ndarray, margin: float) -> np.ndarray:
        local = (points - self.centre) @ self.rotation
        return np.all(np.abs(local) <= self.half + margin, axis=1)


class PlacedCapsule(NamedTuple):
    """A capsule in the camera's optical frame: the segment ``start``-``end`` grown by ``radius``."""

    start: np.ndarray
    end: np.ndarray
    radius: float

    def holds(self, points: np.ndarray, margin: float) -> np.ndarray:
        d = self.end - self.start
        t = np.clip((points - self.start) @ d / float(d @ d), 0.0, 1.0)
        return np.linalg.norm(points - self.start - t[:, None] * d, axis=1) <= self.radius + margin


@dataclass(frozen=True)
class EeSelfFilter:
    """The end effector's bodies (node.yaml ``ee_self_filter``) and the margin that grows them."""

    boxes: tuple[EeBox, ...]
    jaws: tuple[EeJaw, ...]
    margin: float

    @classmethod
    def from_config(cls, raw: Mapping[str, Any]) -> EeSelfFilter:
        """From the validated ``ee_self_filter`` of node.yaml."""
        boxes = tuple(
            EeBox(name, np.asarray(e["centre"], float), np.asarray(e["half"], float), e["on_width_slide"])
            for name, e in raw["boxes"].items()
        )
        jaws = tuple(
            EeJaw(side, np.asarray(e["hinge"], float), np.asarray(e["tip"], float), float(e["radius"]),
                  bool(e["on_width_slide"]))
            for side, e in raw.get("jaws", {}).items()
        )
        return cls(boxes, jaws, float(raw["margin"]))

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
    ``placed`` shapes grown by ``margin``; and how many pixels that was."""
    d = np.asarray(depth, dtype=np.float32)
    valid = np.isfinite(d) & (d > 0)
    v, u = np.nonzero(valid)
    points = back_project(u, v, d[v, u].astype(float), intrinsics)
    inside = np.zeros(len(points), dtype=bool)
    for shape in placed:
        inside |= shape.holds(points, margin)
    out = d.copy()
    out[v[inside], u[inside]] = 0.0
    return out, int(np.count_nonzero(inside))


__all__ = ["EeBox", "EeJaw", "EeSelfFilter", "PlacedBox", "PlacedCapsule", "drop_inside"]
