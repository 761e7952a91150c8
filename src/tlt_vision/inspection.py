"""Part and bay inspection from the pose pipeline's results (paper §V.E; Figs. 22, 26).

Reads :class:`Observation` s, one per segmented instance: its class and either a C-3PO
:class:`~tlt_vision.pose.estimator.PoseEstimate` (with its certificate) or the reason no estimate
could be made (empty mask, no depth, too few points, from :mod:`tlt_vision.pointcloud`). Returns an
:class:`InspectionReport` (tlt_interfaces/msg/InspectionReport): pass, or fail with every reason.
Only certified poses are trusted for geometry; an uncertified one is reported with its reason and
never counted as a found part.

* Strut: one straight strut tube and an end fitting at each end, on the tube's axis, at the
  strut's layout positions (:func:`tlt_vision.cad.models.strut_layout`), parallel to it. A tube
  that does not fit a straight tube (not observably correct although well seen) is a bent tube.
* Cross frame: the frame itself (its four sides) and a corner joint at each of its four corners.
* Placement alignment: a placed part's centre and axis, moved into the tower frame, against the
  mission's joint positions of its member; a held part from the end pieces (corner joints, end
  fittings) its arm's EE cameras see.
* Bay: the corner joints found match the mission's joint positions up to one rigid motion (the
  camera's pose drops out) within the position tolerance.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tlt_vision.cad.models import strut_layout
from tlt_vision.pose.estimator import PoseEstimate

# How far along its own axis a tube's pose alone may be off (m): its ends are inside the fittings.
TUBE_AXIAL_UNCERTAINTY = 0.015


@dataclass(frozen=True)
class Observation:
    """A segmented instance: its class, and its pose estimate or the reason there is none."""

    object_class: str
    estimate: PoseEstimate | None = None
    reason: str = ""
    object_id: str = ""


@dataclass(frozen=True)
class Tolerances:
    position: float  # m
    angle: float  # rad

    @classmethod
    def from_mission(cls, mission: Any) -> Tolerances:
        return cls(
            float(mission.inspection["position_tolerance"]), float(mission.inspection["angle_tolerance"])
        )


@dataclass(frozen=True)
class InspectionReport:
    """A verdict on one part or bay. ``cannot_judge``: not a verdict; the view showed nothing
    wrong but could not settle what it must (a part seen where it should be but not placed well
    enough to certify), and ``reasons`` say what: look again, never discard on it."""

    target_id: str
    target_kind: str
    passed: bool
    reasons: tuple[str, ...]
    poses: tuple[PoseEstimate, ...] = field(default=())
    cannot_judge: bool = False


# An uncertified end fitting posed within this distance (m) of where an end's fitting should be is
# that fitting, seen but not placed well enough to check: about half a fitting's length, far
# more than a certified pose's error and far less than the distance to a neighbour in a rack.
FITTING_SEEN_WITHIN = 0.03


def _split(observations: Sequence[Observation], cls: str) -> tuple[list[PoseEstimate], list[str]]:
    """Certified estimates of a class, and the reasons its other instances were not trusted."""
    good, bad = [], []
    for o in observations:
        if o.object_class != cls:
            continue
        if o.estimate is None:
            bad.append(f"{cls}: {o.reason or 'no pose estimate'}")
        elif not o.estimate.certified:
            bad.append(f"{cls}: pose not certified ({o.estimate.certificate.reason})")
        else:
            good.append(o.estimate)
    return good, bad


def _one_per_place(estimates: list[PoseEstimate], within: float) -> list[PoseEstimate]:
    """``estimates`` with those centred within ``within`` (m) of a better one left out: two
    overlapping masks of one fitting (Mask R-CNN's gun-and-fitting box beside its fitting-only
    box) give two certified poses of it, which are not two parts. The better one has the lower
    Chamfer 90th percentile."""
    kept: list[PoseEstimate] = []
    for e in sorted(estimates, key=lambda e: e.certificate.chamfer_p90):
        if all(np.linalg.norm(np.asarray(e.translation) - np.asarray(k.translation)) > within for k in kept):
            kept.append(e)
    return kept


def _axis(e: PoseEstimate) -> np.ndarray:
    return np.asarray(e.rotation)[:, 2]


def _angle_between_axes(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two undirected axes, rad."""
    return math.acos(min(1.0, abs(float(np.dot(a, b)))))


def _coaxial(f1: PoseEstimate, f2: PoseEstimate) -> tuple[float, float]:
    """Angle (rad) between two fittings' axes, and the larger angle of either axis from the line
    joining their centres: a straight strut's end fittings share one axis, the line between them.

    Angles rather than distances: a degree of axis error on a short fitting moves a point 0.65 m
    along its axis by 11 mm, which a distance tolerance would take for a defect.
    """
    a1, a2 = _axis(f1), _axis(f2)
    d = np.asarray(f2.translation) - np.asarray(f1.translation)
    chord = d / max(float(np.linalg.norm(d)), 1e-9)
    return _angle_between_axes(a1, a2), max(_angle_between_axes(a1, chord), _angle_between_axes(a2, chord))


def inspect_strut(
    target_id: str,
    kind: str,
    length: float,
    observations: Sequence[Observation],
    parts: Mapping[str, Any],
    tol: Tolerances,
) -> InspectionReport:
    """A strut (``kind`` vertical or diagonal, ``length`` m): one straight tube, two end fittings.

    Straightness is judged two ways: the tube must fit the straight-tube model (its certificate),
    and the two end fittings must share one axis (a kink turns one end, and its fitting, away).
    """
    reasons: list[str] = []
    used = tuple(o.estimate for o in observations if o.estimate is not None)
    tube_obs = [o for o in observations if o.object_class == "strut_tube"]
    if not tube_obs:
        return InspectionReport(target_id, kind, False, ("part not in view: no strut tube detected",), used)
    tubes, tube_bad = _split(observations, "strut_tube")
    for o in tube_obs:
        e = o.estimate
        c = e.certificate if e is not None else None
        if c is not None and not c.certified and c.non_degenerate and not c.observably_correct:
            reasons.append(
                f"bent tube: the tube does not fit a straight tube ({c.chamfer_p90 * 1000:.1f} mm "
                f"> {c.chamfer_threshold * 1000:.1f} mm at the 90th percentile)"
            )
    reasons.extend(r for r in tube_bad if not (reasons and "not observably correct" in r))
    if len(tubes) > 1:
        reasons.append(f"expected one strut tube, found {len(tubes)}: a broken or bent tube")
    fittings, fitting_bad = _split(observations, "end_fitting")
    fittings = _one_per_place(fittings, tol.position)
    unsure: list[str] = []
    if len(fittings) == 2:
        between, to_chord = _coaxial(*fittings)
        if between > tol.angle or to_chord > tol.angle:
            reasons.append(
                f"bent tube: the end fittings are not coaxial ({math.degrees(between):.1f} deg between "
                f"their axes, {math.degrees(to_chord):.1f} deg from the line joining them)"
            )
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
            for o, r in zip(_uncertified(observations, "end_fitting"), fitting_bad, strict=True)
            if id(o) not in taken
        ]
    elif len(fittings) < 2:
        reasons.append(f"missing end fitting: {len(fittings)} of 2 found")
    reasons.extend(fitting_bad)
    if reasons:
        return InspectionReport(target_id, kind, False, tuple(reasons + unsure), used)
    return InspectionReport(target_id, kind, not unsure, tuple(unsure), used, cannot_judge=bool(unsure))


def _uncertified(observations: Sequence[Observation], cls: str) -> list[Observation]:
    """The observations of ``cls`` :func:`_split` gives a reason for, in its order."""
    return [
        o for o in observations if o.object_class == cls and (o.estimate is None or not o.estimate.certified)
    ]


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
    reasons, missing = _on_tube(tube, fittings, length, parts, tol)
    unsure: list[str] = []
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
) -> tuple[list[str], dict[str, np.ndarray]]:
    """The fittings matched to the ends of ``tube``: the reasons against those out of place,
    doubled or misaligned, and where (camera frame) each end that has none should have one."""
    reasons = []
    axis = _axis(tube)
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
        angle = _angle_between_axes(_axis(f), axis)
        if angle > tol.angle:
            reasons.append(f"end fitting at end {end} misaligned by {math.degrees(angle):.1f} deg")
        found[end] = f
    ends = (("a", -1.0), ("b", 1.0))
    missing = {end: centre + sign * offset * axis for end, sign in ends if end not in found}
    return reasons, missing


def missing_fitting_places(
    length: float, observations: Sequence[Observation], parts: Mapping[str, Any], tol: Tolerances
) -> np.ndarray:
    """Where (camera frame, (n, 3) m) a strut's end fittings should be and none was found, as
    :func:`inspect_strut` judges ``observations``; empty unless exactly one tube is certified (no
    tube, no place to look)."""
    tubes, _ = _split(observations, "strut_tube")
    if len(tubes) != 1:
        return np.zeros((0, 3))
    fittings = _one_per_place(_split(observations, "end_fitting")[0], tol.position)
    _, missing = _on_tube(tubes[0], fittings, length, parts, tol)
    return np.array(list(missing.values()), dtype=float).reshape(-1, 3)


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
    """
    used = tuple(o.estimate for o in observations if o.estimate is not None)
    if not any(o.object_class == "cross_frame" for o in observations):
        return InspectionReport(
            target_id, "cross_frame", False, ("part not in view: no cross frame detected",), used
        )
    frames, frame_bad = _split(observations, "cross_frame")
    reasons: list[str] = list(frame_bad)
    if len(frames) != 1:
        if len(frames) > 1:
            reasons.append(f"expected one cross frame, found {len(frames)}")
        return InspectionReport(target_id, "cross_frame", False, tuple(reasons), used)
    frame = frames[0]
    rot, t = np.asarray(frame.rotation), np.asarray(frame.translation)
    hw = bay_width / 2
    square = np.array([[x, y, 0.0] for x, y in ((-hw, -hw), (hw, -hw), (hw, hw), (-hw, hw))])
    joints, joint_bad = _split(observations, "corner_joint")
    seen = [o for o in _uncertified(observations, "corner_joint") if o.estimate is not None]
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
        reasons.extend(
            r
            for o, r in zip(_uncertified(observations, "corner_joint"), joint_bad, strict=True)
            if id(o) not in taken
        )
    elif len(found) > 1:
        corners = list(found)
        residuals = _rigid_residuals(
            square[corners], np.array([np.asarray(joints[found[i]].translation) for i in corners])
        )
        reasons += [f"corner joint at corner {i} off by {r * 1000:.1f} mm"
                    for i, r in zip(corners, residuals, strict=True) if r > tol.position]  # fmt: skip
    if unsure and not reasons:
        return InspectionReport(target_id, "cross_frame", False, tuple(unsure), used, cannot_judge=True)
    reasons += unsure
    return InspectionReport(target_id, "cross_frame", not reasons, tuple(reasons), used)


def _rigid_fit(expected: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``R``, ``t`` with ``R e_i + t ~ o_i`` (least squares). For two points the smallest rotation
    that turns one's direction into the other's: the roll about their line is not observed."""
    ce, co = expected.mean(0), observed.mean(0)
    if len(expected) == 2:
        r = _rotation_between(expected[1] - expected[0], observed[1] - observed[0])
    else:
        h = (expected - ce).T @ (observed - co)
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
        r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, co - r @ ce


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``a`` onto direction ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis normal to a
        n = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        n /= np.linalg.norm(n)
        return 2.0 * np.outer(n, n) - np.eye(3)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def _rigid_residuals(expected: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Residual distances after the best rigid fit of ``expected`` (n, 3) onto ``observed``."""
    r, t = _rigid_fit(expected, observed)
    return np.linalg.norm(expected @ r.T + t - observed, axis=1)


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
    r, t = _rigid_fit(expected[idx], np.array([pairs[k] for k in idx]))
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
        held[:3, :3], held[:3, 3] = _rotation_between(tool[:3, 0], x) @ tool[:3, :3], centre
    reasons = _misalignment(pos_err, ang_err, tol)
    return HeldAlignment(not reasons, pos_err, ang_err, len(pairs), held, "; ".join(reasons))


def _signed_like(v: np.ndarray, ref: np.ndarray) -> np.ndarray:
    v = v / np.linalg.norm(v)
    return -v if np.dot(v, ref) < 0 else v


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
    """
    target = f"bay{bay}"
    used = tuple(o.estimate for o in observations if o.estimate is not None)
    joints, bad = _split(observations, "corner_joint")
    names = list(expected)
    exp = np.array([expected[n] for n in names], dtype=float)
    matched: dict[str, PoseEstimate] = {}
    for e in sorted(joints, key=lambda e: e.certificate.chamfer_p90):
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
    residuals = _rigid_residuals(
        np.array([expected[n] for n in order], dtype=float),
        np.array([np.asarray(matched[n].translation, dtype=float) for n in order]),
    )
    reasons = [f"corner joint {n} off by {r * 1000:.1f} mm" for n, r in zip(order, residuals, strict=True)
               if r > tol.position]  # fmt: skip
    return InspectionReport(target, "bay", not reasons, tuple(reasons), used)


def _misalignment(pos_err: float, ang_err: float, tol: Tolerances) -> list[str]:
    reasons = []
    if pos_err > tol.position:
        reasons.append(f"{pos_err * 1000:.1f} mm from its place (tolerance {tol.position * 1000:.1f} mm)")
    if ang_err > tol.angle:
        reasons.append(
            f"turned {math.degrees(ang_err):.1f} deg (tolerance {math.degrees(tol.angle):.1f} deg)"
        )
    return reasons


def bay_joints(mission: Any, bay: int) -> dict[str, tuple[float, float, float]]:
    """The corner joints of bay ``bay`` from the mission: its own cross frame's (``bay<N>/x?_y?``,
    the bottom one) and those of the frame above it (``bay<N-1>/``, the payload's for bay 1)."""
    out = {k: v for k, v in mission.joints.items() if k.startswith((f"bay{bay}/", f"bay{bay - 1}/"))}
    if not any(k.startswith(f"bay{bay}/") for k in out):
        raise KeyError(f"mission {mission.name} has no joints for bay {bay}")
    return out


__all__ = [
    "HeldAlignment",
    "InspectionReport",
    "Observation",
    "Tolerances",
    "bay_joints",
    "corner_joint_prior",
    "expected_pieces",
    "held_part_alignment",
    "inspect_bay",
    "inspect_cross_frame",
    "inspect_strut",
    "missing_fitting_places",
]
