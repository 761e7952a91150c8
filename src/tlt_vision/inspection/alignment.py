"""Placement alignment of a held part: the end pieces (corner joints, end fittings) its arm's EE
cameras see, against where they stand when the part is at its place (the mission's joint positions
of its member)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from tlt_vision.cad.models import strut_layout
from tlt_vision.inspection.report import Tolerances
from tlt_vision.inspection.rigid import rigid_fit, rotation_between


@dataclass(frozen=True)
class HeldAlignment:
    """Where a held part is against its place, from its end pieces seen (see
    :func:`held_part_alignment`). ``held`` is the tool pose (world, 4x4) that holds the part where
    it is seen, in the ARS convention; None when fewer than two pieces were matched."""

    aligned: bool
    position_error: float  # m, the part's centre
    angle_error: float  # rad
    matched: int
    held: np.ndarray | None
    reason: str = ""


PIECE_NAMES = {"cross_frame": "corner joint", "vertical": "end fitting", "diagonal": "end fitting"}


def expected_pieces(kind: str, joints: Sequence[Sequence[float]], parts: Mapping[str, Any]) -> np.ndarray:
    """Where the end pieces of a ``kind`` member at ``joints`` (its place) are: a cross frame's
    corner joints (the joints, in order), a strut's two end fittings (their centres, on the line
    between its joints, :func:`~tlt_vision.cad.models.strut_layout`)."""
    pts = np.asarray(joints, dtype=float)
    if kind == "cross_frame":
        return pts
    u = pts[1] - pts[0]
    length = float(np.linalg.norm(u))
    lay = strut_layout(length, parts)
    u /= length
    return np.array([pts[0] + lay["fitting_a"] * u, pts[0] + lay["fitting_b"] * u])


def corner_joint_prior(
    places: np.ndarray, camera_pose: np.ndarray
) -> Callable[[str, np.ndarray], np.ndarray]:
    """The pose prior of corner joints seen by a camera at ``camera_pose`` (for
    PartPipeline.observe; CheckAlignment of a held cross frame, InspectBay): a cloud's joint is
    expected at the place nearest it, its cube square to the tower (world axes; a cube's
    symmetries make any square turn the same)."""
    to_camera = np.linalg.inv(camera_pose)

    def prior(_cls: str, points: np.ndarray) -> np.ndarray:
        centre = camera_pose[:3, :3] @ np.median(points, axis=0) + camera_pose[:3, 3]
        place = np.eye(4)
        place[:3, 3] = places[int(np.argmin(np.linalg.norm(places - centre, axis=1)))]
        return to_camera @ place

    return prior


def held_part_alignment(
    kind: str,
    pieces: Sequence[Sequence[float]],
    seen: Sequence[Sequence[float]],
    tool: np.ndarray,
    tol: Tolerances,
    gate: float,
) -> HeldAlignment:
    """A held part's alignment from the certified end pieces its arm's EE cameras see.

    Held at its middle (a strut) or the middle of a side (a cross frame), a part fills the D405s'
    view too closely for its own pose (a tube or side centimetres away), but each D405 sees the end
    piece at its end: an end fitting, a corner joint. Each piece ``seen`` (world) is matched to the
    nearest of the part's ``pieces`` at its place (:func:`expected_pieces`) within ``gate``; the rigid
    motion of those matched onto those seen (two or more) moves the part from its place to where it
    is. Errors are its centre's distance and the motion's rotation angle. ``held``, in the ARS
    convention: a strut's tool at its middle, tool x along it (the sign of ``tool``'s), the tool's
    own roll kept (a tube's is not observed); a cross frame's at the middle of the side nearest
    ``tool``, x along that side (the sign of ``tool``'s), y into the frame, z = x cross y.
    """
    expected = np.asarray(pieces, dtype=float)
    pairs: dict[int, np.ndarray] = {}
    for p in np.asarray(seen, dtype=float).reshape(-1, 3):
        d = np.linalg.norm(expected - p, axis=1)
        k = int(np.argmin(d))
        if d[k] <= gate and (k not in pairs or d[k] < np.linalg.norm(pairs[k] - expected[k])):
            pairs[k] = p
    if len(pairs) < 2:
        return HeldAlignment(
            False, math.inf, math.inf, len(pairs), None,
            f"{len(pairs)} {PIECE_NAMES[kind]}(s) of the part seen within {gate * 1000:.0f} mm of their"
            " place; 2 needed",
        )  # fmt: skip
    idx = sorted(pairs)
    r, t = rigid_fit(expected[idx], np.array([pairs[k] for k in idx]))
    moved = expected @ r.T + t
    centre = moved.mean(0)
    pos_err = float(np.linalg.norm(centre - expected.mean(0)))
    ang_err = float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))
    tool = np.asarray(tool, dtype=float)
    held = np.eye(4)
    if kind == "cross_frame":
        mids = [(moved[i] + moved[(i + 1) % len(moved)]) / 2 for i in range(len(moved))]
        i = int(np.argmin([np.linalg.norm(m - tool[:3, 3]) for m in mids]))
        x = _signed_like(moved[(i + 1) % len(moved)] - moved[i], tool[:3, 0])
        y = (centre - mids[i]) / np.linalg.norm(centre - mids[i])
        held[:3, :3], held[:3, 3] = np.column_stack([x, y, np.cross(x, y)]), mids[i]
    else:
        x = _signed_like(moved[1] - moved[0], tool[:3, 0])
        held[:3, :3], held[:3, 3] = rotation_between(tool[:3, 0], x) @ tool[:3, :3], centre
    reasons = _misalignment(pos_err, ang_err, tol)
    return HeldAlignment(not reasons, pos_err, ang_err, len(pairs), held, "; ".join(reasons))


def _signed_like(v: np.ndarray, ref: np.ndarray) -> np.ndarray:
    v = v / np.linalg.norm(v)
    return -v if np.dot(v, ref) < 0 else v


def _misalignment(pos_err: float, ang_err: float, tol: Tolerances) -> list[str]:
    reasons = []
    if pos_err > tol.position:
        reasons.append(f"{pos_err * 1000:.1f} mm from its place (tolerance {tol.position * 1000:.1f} mm)")
    if ang_err > tol.angle:
        reasons.append(
            f"turned {math.degrees(ang_err):.1f} deg (tolerance {math.degrees(tol.angle):.1f} deg)"
        )
    return reasons
