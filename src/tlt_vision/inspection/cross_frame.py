"""A cross frame's inspection: the frame itself (its four sides) and a corner joint at each of its
four corners, standing right relative to each other."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tlt_vision.inspection.report import (
    InspectionReport,
    Observation,
    Tolerances,
    joint_position_verdicts,
    judged_by_depth,
    split_certified,
    uncertified,
)
from tlt_vision.inspection.rigid import rigid_residuals


def inspect_cross_frame(
    target_id: str,
    bay_width: float,
    observations: Sequence[Observation],
    tol: Tolerances,
) -> InspectionReport:
    """A cross frame: the certified frame and a certified corner joint at each of its corners,
    standing right relative to each other.

    The frame's pose says which corner joint is at which corner (the nearest within four times
    the position tolerance); the best rigid fit of the square's corners onto those joints then
    judges where each stands. The frame's own pose is less precise than its corner joints' (C-3PO's
    pose of a 0.75 m frame can move a good frame's corners millimetres between two runs on one
    image), so it is not the reference for the corners' positions.

    On a noisy depth camera a corner joint refused only because the depth cannot place it to 2 %
    of its size (1.7 mm) is still judged where it is placed to three times its precision
    within the position tolerance (5 mm): a lifter ZED places a frame's far corner joints, 0.8-1
    m away, to 1-1.5 mm. Such a corner over the tolerance by less than the noise allows is a doubt
    ("cannot judge"), not a verdict.
    """
    used = tuple(o.estimate for o in observations if o.estimate is not None)
    if not any(o.object_class == "cross_frame" for o in observations):
        return InspectionReport(
            target_id, "cross_frame", False, ("part not in view: no cross frame detected",), used
        )
    frames, frame_bad = split_certified(observations, "cross_frame")
    reasons: list[str] = list(frame_bad)
    if len(frames) != 1:
        if len(frames) > 1:
            reasons.append(f"expected one cross frame, found {len(frames)}")
        return InspectionReport(target_id, "cross_frame", False, tuple(reasons), used)
    frame = frames[0]
    rot, t = np.asarray(frame.rotation), np.asarray(frame.translation)
    hw = bay_width / 2
    square = np.array([[x, y, 0.0] for x, y in ((-hw, -hw), (hw, -hw), (hw, hw), (-hw, hw))])
    joints, joint_bad = split_certified(observations, "corner_joint")
    refused = uncertified(observations, "corner_joint")
    why_refused = {id(o): r for o, r in zip(refused, joint_bad, strict=True)}
    by_depth = {id(o) for o in refused if judged_by_depth(o, tol.position)}
    joints += [o.estimate for o in refused if id(o) in by_depth and o.estimate is not None]
    others = [o for o in refused if id(o) not in by_depth]
    seen = [o for o in others if o.estimate is not None]
    taken: set[int] = set()  # ids of the uncertified joints taken as seen at their corner
    unsure: list[str] = []
    found: dict[int, int] = {}  # corner -> index into joints
    for i, c in enumerate(square @ rot.T + t):
        dists = [np.linalg.norm(np.asarray(j.translation) - c) for j in joints]
        order = [int(k) for k in np.argsort(dists) if k not in found.values()] if joints else []
        if order and dists[order[0]] <= tol.position * 4:
            found[i] = order[0]
            continue
        near = [o for o in seen if np.linalg.norm(np.asarray(o.estimate.translation) - c) <= tol.position * 4]
        if near:
            # The joint is there; the view could not place it well enough to check it.
            taken.update(id(o) for o in near)
            why = near[0].estimate.certificate.reason or "not certified"
            unsure.append(
                f"cannot judge the corner joint at corner {i}: seen there, its pose not certified ({why})"
            )
        else:
            reasons.append(f"missing corner joint at corner {i}")
    if any(r.startswith("missing corner joint") for r in reasons):
        reasons.extend(why_refused[id(o)] for o in others if id(o) not in taken)
    elif len(found) > 1:
        corners = list(found)
        residuals = rigid_residuals(
            square[corners], np.array([np.asarray(joints[found[i]].translation) for i in corners])
        )
        wrong, doubts = joint_position_verdicts(
            [(f"at corner {i}", r, joints[found[i]]) for i, r in zip(corners, residuals, strict=True)],
            tol.position,
        )
        reasons += wrong
        unsure += doubts
    if unsure and not reasons:
        return InspectionReport(target_id, "cross_frame", False, tuple(unsure), used, cannot_judge=True)
    reasons += unsure
    return InspectionReport(target_id, "cross_frame", not reasons, tuple(reasons), used)
