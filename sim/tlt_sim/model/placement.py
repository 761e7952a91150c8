"""Where a part lies against the mission's places: the twin's truth of a placement.

An ARS lets go of a part once its EE cameras measured it within the mission's tolerances of its
member's place (CheckAlignment). The twin knows where the part really is, so each release is
judged here against the truth, in the mission's own terms: the part's joint points (a strut's two
ends, a cross frame's four corners), each matched to the nearest joint of a member of the part's
kind, give the part's centre error and the angle of the rigid motion between the two point sets.
A part released nowhere near a place (a discard) belongs to no member.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from tlt_common.mission.schema import Mission

# A part whose centre lies farther than this from every place of its kind was not placed.
PLACE_REACH_M = 0.05


@dataclass(frozen=True)
class Placement:
    """A released part against the nearest place of its kind: ``member`` (None when none lies
    within :data:`PLACE_REACH_M`), the part's centre error (m), the angle of its rotation from the
    place (rad) and each joint point's distance from its joint (m)."""

    part: str
    member: str | None
    position_error: float
    angle_error: float
    point_errors: tuple[float, ...]

    def within(self, position: float, angle: float) -> bool:
        return self.member is not None and self.position_error <= position and self.angle_error <= angle

    def describe(self) -> str:
        if self.member is None:
            return f"{self.part} at no place (nearest {1000 * self.position_error:.0f} mm away)"
        points = ", ".join(f"{1000 * e:.1f}" for e in self.point_errors)
        return (
            f"{self.part} as {self.member}: centre {1000 * self.position_error:.1f} mm, "
            f"{np.degrees(self.angle_error):.2f} deg from its place (joint points {points} mm)"
        )

    def as_dict(self) -> dict[str, object]:
        """For JSON: a figure not measured (no member, no place of the kind) is null."""

        def figure(x: float) -> float | None:
            return x if math.isfinite(x) else None

        return {
            "part": self.part,
            "member": self.member,
            "position_error_m": figure(self.position_error),
            "angle_error_rad": figure(self.angle_error),
            "point_errors_m": list(self.point_errors),
        }


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation of the best rigid fit of centred points ``a`` onto ``b`` (n, 3);
    for two points, the angle between their directions (the roll about their line is not seen)."""
    if len(a) == 2:
        u, v = a[1] - a[0], b[1] - b[0]
        cos = float(u @ v / (np.linalg.norm(u) * np.linalg.norm(v)))
        return float(np.arccos(np.clip(cos, -1.0, 1.0)))
    h = (a - a.mean(0)).T @ (b - b.mean(0))
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))


def placement_of(
    part: str,
    kind: str,
    points: Sequence[np.ndarray],
    mission: Mission,
    joint_world: Callable[[str], np.ndarray],
) -> Placement:
    """Judge ``part`` (of ``kind``, its joint ``points`` in the world) against every member of
    ``kind`` in ``mission`` (their joints placed by ``joint_world``); the nearest by centre wins."""
    pts = np.asarray(points, dtype=float)
    best: tuple[float, str, np.ndarray] | None = None  # centre error, member, its joints matched
    for member in mission.members:
        if member.kind != kind:
            continue
        joints = np.array([joint_world(j) for j, _ in member.joints])
        centre = float(np.linalg.norm(pts.mean(0) - joints.mean(0)))
        if best is None or centre < best[0]:
            matched = joints[[int(np.argmin(np.linalg.norm(joints - p, axis=1))) for p in pts]]
            best = (centre, member.id, matched)
    if best is None or best[0] > PLACE_REACH_M:
        return Placement(part, None, best[0] if best is not None else math.inf, math.nan, ())
    centre, member_id, matched = best
    errors = tuple(float(e) for e in np.linalg.norm(pts - matched, axis=1))
    return Placement(part, member_id, centre, rotation_angle(matched, pts), errors)


__all__ = ["PLACE_REACH_M", "Placement", "placement_of", "rotation_angle"]
