"""A strut's inspection: one straight strut tube and an end fitting at each end, on the tube's
axis, at the strut's layout positions (:func:`tlt_vision.cad.models.strut_layout`), parallel to it.
A tube that does not fit a straight tube (not observably correct although well seen) is a bent tube."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tlt_vision.cad.models import strut_layout
from tlt_vision.inspection.report import (
    InspectionReport,
    Observation,
    Tolerances,
    angle_between_axes,
    axis_of,
    one_per_place,
    split_certified,
    uncertified,
)
from tlt_vision.pose.estimator import PoseEstimate

# How far along its own axis a tube's pose alone may be off (m): its ends are inside the fittings.
TUBE_AXIAL_UNCERTAINTY = 0.015

# An uncertified end fitting posed within this distance (m) of where an end's fitting should be is
# that fitting, seen but not placed well enough to check: about half a fitting's length, far
# more than a certified pose's error and far less than the distance to a neighbour in a rack.
FITTING_SEEN_WITHIN = 0.03


# Standard errors of a fit's turn (the certificate's ``rotation_precision``) an axis may be off by
# for the depth's noise before an angle over the tolerance is a verdict: good struts' fittings 0.58
# m from a realistic ZED came out up to about four of them off (docs/vision.md).
AXIS_SIGMAS = 4.0


def _axis_doubt(e: PoseEstimate, parts: Mapping[str, Any]) -> float:
    """How far (rad) a fitting's posed axis may be off for the depth's noise: its ends each that
    much (the certificate's allowance) across its length, or ``AXIS_SIGMAS`` times the turn the
    fit's precision leaves it (:mod:`tlt_vision.pose.precision`), whichever is more. 0 on exact
    depth."""
    ends = math.atan2(2.0 * e.certificate.allowance, float(parts["fitting_length"]))
    return max(ends, AXIS_SIGMAS * e.certificate.rotation_precision)


def _angle_verdict(angle: float, doubt: float, tol: Tolerances, what: str) -> tuple[str | None, str | None]:
    """A reason against ``what`` when ``angle`` (rad) is over the tolerance by more than the
    noise's ``doubt``; a doubt when it is over the tolerance within it (neither when within)."""
    if angle <= tol.angle:
        return None, None
    text = f"{what} by {math.degrees(angle):.1f} deg"
    if angle > tol.angle + doubt:
        return text, None
    return None, (
        f"cannot judge: {text}, within the depth noise's {math.degrees(doubt):.1f} deg of the "
        f"{math.degrees(tol.angle):.1f} deg tolerance"
    )


def _coaxial(f1: PoseEstimate, f2: PoseEstimate) -> tuple[float, float]:
    """Angle (rad) between two fittings' axes, and the larger angle of either axis from the line
    joining their centres: a straight strut's end fittings share one axis, the line between them.

    Angles rather than distances: a degree of axis error on a short fitting moves a point 0.65 m
    along its axis by 11 mm, which a distance tolerance would take for a defect.
    """
    a1, a2 = axis_of(f1), axis_of(f2)
    d = np.asarray(f2.translation) - np.asarray(f1.translation)
    chord = d / max(float(np.linalg.norm(d)), 1e-9)
    return angle_between_axes(a1, a2), max(angle_between_axes(a1, chord), angle_between_axes(a2, chord))


def inspect_strut(
    target_id: str,
    kind: str,
    length: float,
    observations: Sequence[Observation],
    parts: Mapping[str, Any],
    tol: Tolerances,
) -> InspectionReport:
    """A strut (``kind`` vertical or diagonal, ``length`` m): one straight tube, two end fittings.

    Cannot judge (``cannot_judge``, not passed) when nothing is wrong but something could not be
    settled: the tube or a fitting seen but not certified (:func:`_fittings_on_tube`).
    Straightness is judged two ways: the tube must fit the straight-tube model (its certificate),
    and the two end fittings must share one axis (a kink turns one end, and its fitting, away).
    """
    reasons: list[str] = []
    used = tuple(o.estimate for o in observations if o.estimate is not None)
    tube_obs = [o for o in observations if o.object_class == "strut_tube"]
    if not tube_obs:
        return InspectionReport(target_id, kind, False, ("part not in view: no strut tube detected",), used)
    tubes, tube_bad = split_certified(observations, "strut_tube")
    for o in tube_obs:
        e = o.estimate
        c = e.certificate if e is not None else None
        if c is not None and not c.certified and c.non_degenerate and not c.observably_correct:
            reasons.append(
                f"bent tube: the tube does not fit a straight tube ({c.chamfer_p90 * 1000:.1f} mm "
                f"> {c.chamfer_threshold * 1000:.1f} mm at the 90th percentile)"
            )
    unsure: list[str] = []
    # A tube posed but not certified, and not for a shape that is wrong, was seen too little to
    # place (one end hidden by the gripper or the other arm, or out of the frame) or through depth
    # too noisy: a doubt. Without its pose, where the fittings should be is not known either.
    tube_in_doubt = not tubes and not reasons and all(o.estimate is not None for o in tube_obs)
    if tube_in_doubt:
        unsure.extend(f"cannot judge the {r}" for r in tube_bad)
    else:
        reasons.extend(r for r in tube_bad if not (reasons and "not observably correct" in r))
    if len(tubes) > 1:
        reasons.append(f"expected one strut tube, found {len(tubes)}: a broken or bent tube")
    fittings, fitting_bad = split_certified(observations, "end_fitting")
    fittings = one_per_place(fittings, tol.position)
    if len(fittings) == 2:
        between, to_chord = _coaxial(*fittings)
        doubt = _axis_doubt(fittings[0], parts) + _axis_doubt(fittings[1], parts)
        bent, unsure_bent = _angle_verdict(max(between, to_chord), doubt, tol, "end fittings off coaxial")
        if bent is not None:
            reasons.append(
                f"bent tube: the end fittings are not coaxial ({math.degrees(between):.1f} deg between "
                f"their axes, {math.degrees(to_chord):.1f} deg from the line joining them)"
            )
        elif unsure_bent is not None:
            unsure.append(unsure_bent)
    elif len(fittings) > 2:
        reasons.append(f"expected two end fittings, found {len(fittings)}")
    if len(tubes) == 1:
        seen = [
            o
            for o in observations
            if o.object_class == "end_fitting" and o.estimate is not None and not o.estimate.certified
        ]
        placed, unplaced, accounted = _fittings_on_tube(tubes[0], fittings, seen, length, parts, tol)
        reasons.extend(placed)
        unsure.extend(unplaced)
        taken = {id(o) for o in accounted}
        fitting_bad = [
            r
            for o, r in zip(uncertified(observations, "end_fitting"), fitting_bad, strict=True)
            if id(o) not in taken
        ]
    elif tube_in_doubt:
        if len(fittings) < 2:
            found = len(fittings)
            unsure.append(f"cannot judge the end fittings: {found} of 2 certified, the tube not placed")
        unsure.extend(f"cannot judge the {r}" for r in fitting_bad)
        fitting_bad = []
    elif len(fittings) < 2:
        reasons.append(f"missing end fitting: {len(fittings)} of 2 found")
    reasons.extend(fitting_bad)
    if reasons:
        return InspectionReport(target_id, kind, False, tuple(reasons + unsure), used)
    return InspectionReport(target_id, kind, not unsure, tuple(unsure), used, cannot_judge=bool(unsure))


def _fittings_on_tube(
    tube: PoseEstimate,
    fittings: list[PoseEstimate],
    seen: Sequence[Observation],
    length: float,
    parts: Mapping[str, Any],
    tol: Tolerances,
) -> tuple[list[str], list[str], list[Observation]]:
    """Why the certified ``fittings`` are not one at each end of ``tube``, on its axis, parallel
    to it; for an end without one where an uncertified fitting of ``seen`` stands within
    :data:`FITTING_SEEN_WITHIN` of its place, why it cannot be judged instead (the fitting is
    there; the view cannot place it well enough to check it); and the observations so taken."""
    reasons, unsure, missing = _on_tube(tube, fittings, length, parts, tol)
    accounted: list[Observation] = []
    for where in missing.values():
        # A tube is the same end for end: "a" and "b" follow the estimated axis, so the reason
        # also says where the fitting should be.
        xyz = ", ".join(f"{v:.3f}" for v in where)
        near = [
            o
            for o in seen
            if np.linalg.norm(np.asarray(o.estimate.translation) - where) <= FITTING_SEEN_WITHIN
        ]
        if near:
            accounted.extend(near)
            why = near[0].estimate.certificate.reason or "not certified"
            unsure.append(
                f"cannot judge the end fitting at ({xyz}) m in the camera frame: seen there, "
                f"its pose not certified ({why})"
            )
            continue
        reasons.append(
            f"missing end fitting: {2 - len(missing)} of 2 found, none at ({xyz}) m in the camera frame"
        )
    return reasons, unsure, accounted


def _on_tube(
    tube: PoseEstimate, fittings: list[PoseEstimate], length: float, parts: Mapping[str, Any], tol: Tolerances
) -> tuple[list[str], list[str], dict[str, np.ndarray]]:
    """The fittings matched to the ends of ``tube``: the reasons against those out of place,
    doubled or misaligned, the doubts on those whose misalignment is within the depth noise's
    reach of the tolerance, and where (camera frame) each end that has none should have one."""
    reasons: list[str] = []
    doubts: list[str] = []
    axis = axis_of(tube)
    lay = strut_layout(length, parts)
    offset = lay["fitting_b"] - lay["tube_centre"]  # fittings at -offset (end a) and +offset (end b)
    centre = np.asarray(tube.translation, dtype=float)
    if len(fittings) == 2:
        # The tube's ends are hidden inside the fittings, so its position along its own axis is
        # seen only to a few millimetres; with both fittings found, their midpoint fixes it.
        mid = (np.asarray(fittings[0].translation) + np.asarray(fittings[1].translation)) / 2
        centre = centre + float((mid - centre) @ axis) * axis
    elif len(fittings) == 1:
        # One fitting fixes it as well, when it lies within what the tube alone tells: read
        # against the tube alone, a good fitting would be "out of place" by millimetres along the
        # axis, and the missing one's place as far off.
        axial = float((np.asarray(fittings[0].translation) - centre) @ axis)
        slip = axial - math.copysign(offset, axial)
        if abs(slip) <= TUBE_AXIAL_UNCERTAINTY:
            centre = centre + slip * axis
    found: dict[str, PoseEstimate] = {}
    for f in fittings:
        rel = np.asarray(f.translation) - centre
        axial = float(rel @ axis)
        radial = float(np.linalg.norm(rel - axial * axis))
        end = "a" if axial < 0 else "b"
        axial_err = abs(abs(axial) - offset)
        if radial > tol.position or axial_err > tol.position:
            reasons.append(
                f"end fitting out of place: {radial * 1000:.1f} mm off the tube axis, "
                f"{axial_err * 1000:.1f} mm off its position along it (bent tube or loose fitting)"
            )
            continue
        if end in found:
            reasons.append(f"two end fittings at end {end}")
            continue
        angle = angle_between_axes(axis_of(f), axis)
        wrong, doubt = _angle_verdict(
            angle, _axis_doubt(f, parts), tol, f"end fitting at end {end} misaligned"
        )
        if wrong is not None:
            reasons.append(wrong)
        elif doubt is not None:
            doubts.append(doubt)
        found[end] = f
    ends = (("a", -1.0), ("b", 1.0))
    missing = {end: centre + sign * offset * axis for end, sign in ends if end not in found}
    return reasons, doubts, missing


def missing_fitting_places(
    length: float, observations: Sequence[Observation], parts: Mapping[str, Any], tol: Tolerances
) -> np.ndarray:
    """Where (camera frame, (n, 3) m) a strut's end fittings should be and none was found, as
    :func:`inspect_strut` judges ``observations``; empty unless exactly one tube is certified (no
    tube, no place to look)."""
    tubes, _ = split_certified(observations, "strut_tube")
    if len(tubes) != 1:
        return np.zeros((0, 3))
    fittings = one_per_place(split_certified(observations, "end_fitting")[0], tol.position)
    _, _, missing = _on_tube(tubes[0], fittings, length, parts, tol)
    return np.array(list(missing.values()), dtype=float).reshape(-1, 3)
