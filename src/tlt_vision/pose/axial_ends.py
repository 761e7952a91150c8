"""Is a round part's place along its own axis seen? Its ends in the depth image.

A cylinder seen from its side (an end fitting) fits its cloud equally well wherever along its axis
the model lies over the band the camera saw: the Chamfer certificate cannot tell, and the mask,
which :mod:`tlt_vision.pose.axial_slide` reads for it, is a learned guess that may stop short of
the part's end (Mask R-CNN's fitting masks do, where a fitting meets its corner joint). The depth
image says it without the mask: at a posed end that is the part's end, the camera-facing surface
is there just inside the end and gone just beyond it, where the camera sees farther (the thinner
tube behind, or the background). A pose slid along its axis has at its ends either more of the
same surface beyond (the part goes on) or something nearer (an occluder: the part may go on
behind it). Neither fixes the axial place, and the pose is not certified for it.

:func:`ends_seen` samples a few generator lines of the posed cylinder's camera-facing side at
each end, a few pixels inside and beyond the end along the axis's image, and calls an end seen
when most of the samples that can be read show the surface inside and something farther beyond.
Seen end-on (the axis within ``end_on`` of the line of sight), the depth of the end face itself
places the part along its axis, and the check does not apply: :func:`end_face_seen` asks instead
whether the cloud holds that face.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from tlt_vision.pointcloud import PinholeIntrinsics
from tlt_vision.pose.certificate import Certificate
from tlt_vision.pose.estimator import PoseEstimate


@dataclass(frozen=True)
class AxialEnds:
    """The check's settings (config/vision/node.yaml ``axial_ends``)."""

    classes: tuple[str, ...] = ("end_fitting",)
    offsets_px: tuple[float, ...] = (3.0, 5.0, 8.0)  # inside and beyond the end, along the axis's image
    generators_deg: tuple[float, ...] = (-45.0, 0.0, 45.0)  # about the camera-facing side
    on_surface: float = 0.004  # m: the depth inside the end is the surface within this
    jump: float = 0.004  # m: the depth beyond the end is farther than the surface by more than this
    end_on_deg: float = 45.0  # axis within this of the line of sight: the end face is seen


DEFAULT = AxialEnds()


@dataclass(frozen=True)
class PosedCylinder:
    """A cylinder of ``radius`` and ``half_length`` along its model's z axis, posed in the camera
    frame; end ``"a"`` at the model's -z, ``"b"`` at +z."""

    rotation: np.ndarray
    translation: np.ndarray
    radius: float
    half_length: float

    @property
    def axis(self) -> np.ndarray:
        return np.asarray(self.rotation, float)[:, 2]

    def slid(self, by: float) -> PosedCylinder:
        """This cylinder moved ``by`` (m) along its axis."""
        return replace(self, translation=np.asarray(self.translation, float) + by * self.axis)

    def end_on(self, settings: AxialEnds) -> bool:
        """Whether its axis lies within ``settings.end_on_deg`` of the line of sight."""
        centre = np.asarray(self.translation, float)
        sight = centre / max(float(np.linalg.norm(centre)), 1e-9)
        return abs(float(self.axis @ sight)) > math.cos(math.radians(settings.end_on_deg))

    def rims(
        self, end: str, settings: AxialEnds, intrinsics: PinholeIntrinsics
    ) -> list[tuple[np.ndarray, float]]:
        """The rim points at ``end`` on the generator lines of its camera-facing side
        (``settings.generators_deg``) in front of the camera, each with the pixels a metre along
        the axis there spans in the image."""
        axis = self.axis
        sign = 1.0 if end == "b" else -1.0
        centre = np.asarray(self.translation, float) + sign * self.half_length * axis
        towards = -(centre - (centre @ axis) * axis)  # from the axis towards the camera, across it
        towards /= max(float(np.linalg.norm(towards)), 1e-9)
        across = np.cross(axis, towards)
        rims = []
        for deg in settings.generators_deg:
            a = math.radians(deg)
            rim = centre + self.radius * (math.cos(a) * towards + math.sin(a) * across)
            if rim[2] <= 0:
                continue
            step = _project(rim + 0.01 * sign * axis, intrinsics) - _project(rim, intrinsics)
            px_per_m = float(np.linalg.norm(step)) / 0.01
            if px_per_m > 1e-4:
                rims.append((rim, px_per_m))
        return rims

    def outward(self, end: str) -> np.ndarray:
        return self.axis if end == "b" else -self.axis


def _depth_at(depth: np.ndarray, uv: np.ndarray, window: int = 1) -> float:
    """The median valid depth of the pixels within ``window`` of ``uv`` (3 x 3 by default); nan
    outside the image or where none."""
    h, w = depth.shape
    u, v = round(float(uv[0])), round(float(uv[1]))
    if not (window <= u < w - window and window <= v < h - window):
        return math.nan
    pixels = depth[v - window : v + window + 1, u - window : u + window + 1].astype(float)
    valid = pixels[np.isfinite(pixels) & (pixels > 0)]
    return float(np.median(valid)) if valid.size else math.nan


def _project(p: np.ndarray, k: PinholeIntrinsics) -> np.ndarray:
    return np.array([k.fx * p[0] / p[2] + k.cx, k.fy * p[1] / p[2] + k.cy])


def end_votes(
    cylinder: PosedCylinder,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
) -> dict[str, tuple[int, int]] | None:
    """For each end, how many of its samples show an end and how many could be read (module
    docstring); ``margin`` (m) widens both tolerances for the depth's noise. None when the axis
    faces the camera and the check does not apply."""
    if cylinder.end_on(settings):
        return None
    out: dict[str, tuple[int, int]] = {}
    for end in ("a", "b"):
        outward = cylinder.outward(end)
        ends = read = 0
        for rim, px_per_m in cylinder.rims(end, settings, intrinsics):
            for offset in settings.offsets_px:
                step = offset / px_per_m * outward
                inside, beyond = rim - step, rim + step
                d_in = _depth_at(depth, _project(inside, intrinsics))
                d_out = _depth_at(depth, _project(beyond, intrinsics))
                if math.isnan(d_in) or abs(d_in - inside[2]) > settings.on_surface + margin:
                    continue  # the surface is not seen there: this sample says nothing
                if math.isnan(d_out):
                    continue
                read += 1
                if d_out > beyond[2] + settings.jump + margin:
                    ends += 1
        out[end] = (ends, read)
    return out


def ends_seen(
    cylinder: PosedCylinder,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
) -> tuple[str, ...] | None:
    """The ends of ``cylinder`` that ``depth`` shows as its ends: those most of whose samples that
    could be read do (:func:`end_votes`). None when the axis faces the camera."""
    votes = end_votes(cylinder, depth, intrinsics, settings, margin)
    if votes is None:
        return None
    return tuple(end for end, (ends, read) in votes.items() if read and ends * 2 > read)


def end_face_seen(cylinder: PosedCylinder, points: np.ndarray, tolerance: float, share: float = 0.1) -> bool:
    """Whether at least ``share`` of the cloud ``points`` (N, 3, camera frame) lie on an end face
    of ``cylinder`` (within ``tolerance`` of its plane, inside its rim): seen end-on, the face
    places the part along its axis only if the cloud holds it, not a band of the side alone (a
    mask cut by the frame's border)."""
    rot, t = np.asarray(cylinder.rotation, float), np.asarray(cylinder.translation, float)
    local = (np.asarray(points, float) - t) @ rot
    if not len(local):
        return False
    on_face = (np.abs(np.abs(local[:, 2]) - cylinder.half_length) <= tolerance) & (
        np.linalg.norm(local[:, :2], axis=1) <= cylinder.radius + tolerance
    )
    return int(on_face.sum()) >= max(10, share * len(local))


def slide_to_an_end(
    cylinder: PosedCylinder,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
    step: float = 0.001,
) -> float | None:
    """The slide (m, along the axis, within a half length either way) that puts an end of
    ``cylinder`` where the depth shows one: of the slides at which an end is seen, those where
    the most of its samples agree, their middle, then to the pixel where the surface stops
    (:func:`_edge`). None when no slide shows an end."""
    scored = []
    h = cylinder.half_length
    for by in np.arange(-h, h + step / 2, step):
        votes = end_votes(cylinder.slid(float(by)), depth, intrinsics, settings, margin)
        if votes is None:
            return None
        best = max((ends / read for ends, read in votes.values() if read and ends * 2 > read), default=0.0)
        if best:
            scored.append((best, float(by)))
    if not scored:
        return None
    top = max(score for score, _ in scored)
    slides = [by for score, by in scored if score == top]
    by = slides[len(slides) // 2]
    # The votes place the end to a few of their sample offsets; where the surface stops along
    # the generator lines places it to a pixel.
    there = cylinder.slid(by)
    votes = end_votes(there, depth, intrinsics, settings, margin) or {}
    end = max(votes, key=lambda n: votes[n][0] / max(votes[n][1], 1))
    edge = _edge(there, end, depth, intrinsics, settings, margin)
    return by if edge is None else by + (edge if end == "b" else -edge)


def placed_along_axis(
    candidates: Sequence[PoseEstimate],
    points: np.ndarray,
    radius: float,
    half_length: float,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    certify: Callable[[np.ndarray, np.ndarray], Certificate],
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
) -> PoseEstimate:
    """Of ``candidates`` (certified poses of one cylinder's cloud ``points``: the pose slid by its
    mask, then as fitted), the first whose ends the depth shows, or, seen end-on, whose cloud holds
    an end face; when none, the first slid to where the depth shows an end and certified again
    (``certify(rotation, translation)``); when none either, the first, not certified: its place
    along its axis is not seen."""
    first = candidates[0]
    face = settings.on_surface + margin
    for e in candidates:
        if not e.certified:
            continue
        posed = PosedCylinder(e.rotation, e.translation, radius, half_length)
        seen = ends_seen(posed, depth, intrinsics, settings, margin)
        if seen or (seen is None and end_face_seen(posed, points, face)):
            return e
    posed = PosedCylinder(first.rotation, first.translation, radius, half_length)
    by = slide_to_an_end(posed, depth, intrinsics, settings, margin)
    if by is not None:
        moved = by * posed.axis
        slid = replace(
            first,
            translation=np.asarray(first.translation) + moved,
            keypoints=np.asarray(first.keypoints) + moved,
        )
        certificate = certify(slid.rotation, slid.translation)
        if certificate.certified:
            return replace(slid, certificate=certificate)
    why = "degenerate view: neither end of the part seen in the depth (its place along its axis is open)"
    reason = "; ".join(r for r in (first.certificate.reason, why) if r)
    return replace(
        first, certificate=replace(first.certificate, certified=False, reason=reason, depth_limited=False)
    )


def _edge(
    cylinder: PosedCylinder,
    end: str,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds,
    margin: float,
) -> float | None:
    """How far (m, outward along the axis) from ``end`` the surface stops in the depth: on each
    generator line, half a pixel's walk from the largest sample offset inside to as far beyond,
    the middle of the last step on the surface before the first farther than it; their median.
    None when no line shows such a step."""
    outward = cylinder.outward(end)
    edges = []
    for rim, px_per_m in cylinder.rims(end, settings, intrinsics):
        reach = max(settings.offsets_px) / px_per_m
        last_on = None
        for s in np.arange(-reach, reach, 0.5 / px_per_m):
            p = rim + s * outward
            d = _depth_at(depth, _project(p, intrinsics), window=0)
            if math.isnan(d):
                continue
            if abs(d - p[2]) <= settings.on_surface + margin:
                last_on = float(s)
            elif d > p[2] + settings.jump + margin and last_on is not None:
                edges.append((last_on + float(s)) / 2)
                break
    return float(np.median(edges)) if edges else None


__all__ = [
    "DEFAULT",
    "AxialEnds",
    "PosedCylinder",
    "end_face_seen",
    "end_votes",
    "ends_seen",
    "slide_to_an_end",
]
