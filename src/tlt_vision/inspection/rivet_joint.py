"""A riveted joint judged from one end-effector camera frame: its head present, seated and in the
right hole, or what is wrong with it, or that this frame cannot tell.

The paper (§V.C.3, §VII) left the check of a well-placed rivet to an operator; this is the vision
half of doing it autonomously. It reads only what a camera gives: the segmentation's rivet masks
on the RGB image (Mask R-CNN's ``rivet`` detections), the depth image and the intrinsics; and
where the joint should be, from the system's own model (the mission's joint, the member's axis,
the fitting the hole is in, the side the gun fired from), as a :class:`HoleView` in the camera's
optical frame.

:func:`judge_rivet_joint` backs each rivet mask near the hole into a point cloud and compares its
centre with where a seated head's visible surface would be: a head standing out of the fitting by
more than ``seated_tolerance`` did not seat (a proud head, a partial grip), one more than
``hole_tolerance`` along the fitting is in another hole, no rivet near a hole the camera sees
clearly is no head. A frame in which the hole is out of view, hidden behind something, without
depth, or whose head has too little depth to place, gives :data:`CANNOT_JUDGE`, never a pass: the
caller looks again from another pose. A loose joint looks good: the bay's compression test is its
check.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tlt_vision.detections import Detection
from tlt_vision.pointcloud import PinholeIntrinsics, masked_point_cloud

GOOD, NO_HEAD, UNSEATED, WRONG_HOLE, CANNOT_JUDGE = (
    "good",
    "no_head",
    "unseated",
    "wrong_hole",
    "cannot_judge",
)
VERDICTS = (GOOD, NO_HEAD, UNSEATED, WRONG_HOLE, CANNOT_JUDGE)


@dataclass(frozen=True)
class HoleView:
    """Where a seated rivet head's centre lies (``hole``, m), the fitting's outward normal there
    (``outward``: the side the gun fired from) and its axis (``along``), in the camera's optical
    frame (x right, y down, z forward)."""

    hole: np.ndarray
    outward: np.ndarray
    along: np.ndarray

    @classmethod
    def from_world(
        cls,
        hole: np.ndarray,
        outward: np.ndarray,
        along: np.ndarray,
        camera_position: np.ndarray,
        camera_rotation: np.ndarray,
    ) -> HoleView:
        """From world vectors and the optical frame's world pose (its axes as the columns of
        ``camera_rotation``); ``outward`` is made square to ``along``."""
        r = np.asarray(camera_rotation, dtype=float)
        a = np.asarray(along, dtype=float)
        a = a / np.linalg.norm(a)
        o = np.asarray(outward, dtype=float)
        o = o - (o @ a) * a
        o = o / np.linalg.norm(o)
        return cls(r.T @ (np.asarray(hole, dtype=float) - camera_position), r.T @ o, r.T @ a)


@dataclass(frozen=True)
class RivetJointLimits:
    """How the judgement decides (m unless named): the rivet head's radius; how far from the hole
    a rivet mask still counts as this joint's; how far out of the fitting (beyond a seated head)
    and along it a head may stand and still pass; how much nearer the camera than the hole the
    depth there may read before the view counts as blocked; the share of valid depth the hole's
    surroundings need; and the fewest points a head's cloud must have."""

    head_radius: float = 0.006
    search_radius: float = 0.025  # a head proud and in the neighbouring hole is still this joint's
    # Between a seated head (its visible cap, outside the fitting, reads a little out) and one that
    # gripped only partly (4 mm out on the twin's fastener); the neighbouring hole is 16 mm along.
    seated_tolerance: float = 0.003
    hole_tolerance: float = 0.008
    blocked_margin: float = 0.03
    min_valid_depth: float = 0.5
    min_points: int = 12


@dataclass(frozen=True)
class RivetJointJudgement:
    """The verdict (:data:`VERDICTS`), why, and the figures it rests on: the head's centre as
    seen (optical frame, m; None without one), how far it stands out of its seated place and along
    the fitting from the hole (m), and its mask's pixels."""

    verdict: str
    reason: str
    head: np.ndarray | None = None
    height_m: float = 0.0
    along_m: float = 0.0
    pixels: int = 0

    @property
    def good(self) -> bool:
        return self.verdict == GOOD

    @property
    def judged(self) -> bool:
        return self.verdict != CANNOT_JUDGE


def judge_rivet_joint(
    detections: Sequence[Detection],
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    view: HoleView,
    limits: RivetJointLimits | None = None,
) -> RivetJointJudgement:
    """Judge the joint at ``view`` from one frame's ``detections`` (only class ``rivet`` counts),
    ``depth`` (m, 0 or NaN where none) and ``intrinsics`` (see the module docstring)."""
    lim = limits or RivetJointLimits()
    depth = np.asarray(depth, dtype=float)
    hole = np.asarray(view.hole, dtype=float)
    if hole[2] <= 0.0:
        return RivetJointJudgement(CANNOT_JUDGE, "the joint is behind the camera")
    h, w = depth.shape
    u = intrinsics.fx * hole[0] / hole[2] + intrinsics.cx
    v = intrinsics.fy * hole[1] / hole[2] + intrinsics.cy
    span = max(2, int(np.ceil(2 * lim.head_radius * intrinsics.fx / hole[2])))  # a head's width, px
    if not (span <= u < w - span and span <= v < h - span):
        return RivetJointJudgement(
            CANNOT_JUDGE, f"the joint projects to ({u:.0f}, {v:.0f}), outside the view"
        )
    window = depth[int(v) - span : int(v) + span + 1, int(u) - span : int(u) + span + 1]
    valid = window[np.isfinite(window) & (window > 0)]
    if valid.size < lim.min_valid_depth * window.size:
        return RivetJointJudgement(
            CANNOT_JUDGE, f"depth missing at the joint ({valid.size} of {window.size} px)"
        )
    nearest = float(np.median(valid))
    if nearest < hole[2] - lim.blocked_margin:
        return RivetJointJudgement(
            CANNOT_JUDGE,
            f"view blocked: something at {nearest:.3f} m in front of the joint at {hole[2]:.3f} m",
        )
    # Where a seated head's visible surface centres: half a radius from its centre towards the camera.
    expected = hole - 0.5 * lim.head_radius * hole / np.linalg.norm(hole)
    best: tuple[float, np.ndarray, int] | None = None
    unplaced = 0
    for det in detections:
        if det.object_class != "rivet":
            continue
        cloud = masked_point_cloud(
            det.mask, depth, intrinsics, min_points=lim.min_points, extent=4 * lim.head_radius
        )
        if not cloud.ok:
            if _near_in_image(det.mask, u, v, span):
                unplaced += 1
            continue
        centre = np.median(cloud.points, axis=0)
        distance = float(np.linalg.norm(centre - hole))
        if distance <= lim.search_radius and (best is None or distance < best[0]):
            best = (distance, centre, int(np.count_nonzero(det.mask)))
    if best is None:
        if unplaced:
            return RivetJointJudgement(
                CANNOT_JUDGE, "a rivet is seen at the joint but its depth cannot place it"
            )
        return RivetJointJudgement(NO_HEAD, "no rivet head at the hole, which the camera sees clearly")
    _, centre, pixels = best
    offset = centre - expected
    height, along = float(offset @ view.outward), float(offset @ view.along)
    figures = {"head": centre, "height_m": height, "along_m": along, "pixels": pixels}
    if abs(along) > lim.hole_tolerance:
        return RivetJointJudgement(
            WRONG_HOLE, f"head {1000 * along:+.1f} mm along the fitting from its hole", **figures
        )
    if height > lim.seated_tolerance:
        return RivetJointJudgement(
            UNSEATED, f"head stands {1000 * height:.1f} mm proud of its seat", **figures
        )
    return RivetJointJudgement(
        GOOD,
        f"head seated in its hole ({1000 * height:+.1f} mm out, {1000 * along:+.1f} mm along)",
        **figures,
    )


def _near_in_image(mask: np.ndarray, u: float, v: float, span: int) -> bool:
    rows, cols = np.nonzero(mask)
    return bool(len(rows)) and bool(np.min(np.hypot(cols - u, rows - v)) <= 3 * span)


__all__ = [
    "CANNOT_JUDGE",
    "GOOD",
    "NO_HEAD",
    "UNSEATED",
    "VERDICTS",
    "WRONG_HOLE",
    "HoleView",
    "RivetJointJudgement",
    "RivetJointLimits",
    "judge_rivet_joint",
]
