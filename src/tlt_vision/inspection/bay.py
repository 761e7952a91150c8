"""A bay's inspection: the corner joints found match the mission's joint positions up to one rigid
motion (the camera's pose drops out) within the position tolerance (paper §V.E)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tlt_vision.inspection.report import (
    InspectionReport,
    Observation,
    Tolerances,
    joint_position_verdicts,
    judged_by_depth,
    split_certified,
)
from tlt_vision.inspection.rigid import rigid_residuals
from tlt_vision.pose.estimator import PoseEstimate


def inspect_bay(
    bay: int,
    expected: Mapping[str, Sequence[float]],
    observations: Sequence[Observation],
    tol: Tolerances,
    gate: float,
    min_joints: int,
) -> InspectionReport:
    """The bay's corner joints (:func:`bay_joints`) against where they should stand (name -> xyz,
    in the observations' frame).

    A certified corner joint pose counts for the expected joint nearest it when within ``gate``
    (m): the inward views also show the dispensers' stacked cross frames, and matched to any
    joints in view a good bay would fail with every joint "off by" tens of centimetres. Of two poses for one
    joint the better certified counts. The bay passes when at least ``min_joints`` joints are
    matched, from both of its frames (the verticals' lengths are then in the check), and, after
    the best rigid fit of their places onto them, none is off by more than ``tol.position``: the
    corner joints stand right relative to each other (paper §V.E). Joints out of view do not fail
    the bay while enough are seen.

    On a noisy depth camera a corner joint refused only for the noise counts where the depth
    places it to three times its precision within ``tol.position``
    (:func:`~tlt_vision.inspection.report.judged_by_depth`), and a joint off by less than that band
    over the tolerance is a doubt: the bay cannot be judged, rather than fail.
    """
    target = f"bay{bay}"
    used = tuple(o.estimate for o in observations if o.estimate is not None)
    joints, bad = split_certified(observations, "corner_joint")
    joints += [
        o.estimate
        for o in observations
        if o.object_class == "corner_joint" and o.estimate is not None and not o.estimate.certified
        and judged_by_depth(o, tol.position)
    ]  # fmt: skip
    names = list(expected)
    exp = np.array([expected[n] for n in names], dtype=float)
    matched: dict[str, PoseEstimate] = {}
    for e in sorted(joints, key=lambda e: (not e.certified, e.certificate.chamfer_p90)):
        gaps = np.linalg.norm(exp - np.asarray(e.translation, dtype=float), axis=1)
        name = names[int(np.argmin(gaps))]
        if gaps.min() <= gate and name not in matched:
            matched[name] = e
    frames = {n.split("/", 1)[0] for n in names}
    seen_frames = {n.split("/", 1)[0] for n in matched}
    if len(matched) < min_joints or seen_frames != frames:
        if not any(o.object_class == "corner_joint" for o in observations):
            reason = "part not in view: no corner joint detected"
            return InspectionReport(target, "bay", False, (reason,), used)
        unseen = ", ".join(n for n in names if n not in matched)
        reasons = [
            f"only {len(matched)} of {len(names)} corner joints seen where the bay stands (at least"
            f" {min_joints} needed, from both of its frames; not seen: {unseen})",
            *bad,
        ]
        return InspectionReport(target, "bay", False, tuple(reasons), used)
    order = list(matched)
    residuals = rigid_residuals(
        np.array([expected[n] for n in order], dtype=float),
        np.array([np.asarray(matched[n].translation, dtype=float) for n in order]),
    )
    reasons, unsure = joint_position_verdicts(
        [(n, r, matched[n]) for n, r in zip(order, residuals, strict=True)], tol.position
    )
    if unsure and not reasons:
        return InspectionReport(target, "bay", False, tuple(unsure), used, cannot_judge=True)
    reasons += unsure
    return InspectionReport(target, "bay", not reasons, tuple(reasons), used)


def bay_joints(mission: Any, bay: int) -> dict[str, tuple[float, float, float]]:
    """The corner joints of bay ``bay`` from the mission: its own cross frame's (``bay<N>/x?_y?``,
    the bottom one) and those of the frame above it (``bay<N-1>/``, the payload's for bay 1)."""
    out = {k: v for k, v in mission.joints.items() if k.startswith((f"bay{bay}/", f"bay{bay - 1}/"))}
    if not any(k.startswith(f"bay{bay}/") for k in out):
        raise KeyError(f"mission {mission.name} has no joints for bay {bay}")
    return out
