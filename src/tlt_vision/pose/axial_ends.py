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
from dataclasses import dataclass

import numpy as np

from tlt_vision.pointcloud import PinholeIntrinsics


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


def ends_seen(
    rotation: np.ndarray,
    translation: np.ndarray,
    radius: float,
    half_length: float,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
) -> tuple[str, ...] | None:
    """The ends (``"a"`` at the model's -z, ``"b"`` at +z) of a cylinder of ``radius`` and
    ``half_length`` posed at ``rotation``, ``translation`` (camera frame) that ``depth`` shows as
    its ends (module docstring); ``margin`` (m) widens both tolerances for the depth's noise. None
    when the axis faces the camera and the check does not apply."""
    votes = end_votes(rotation, translation, radius, half_length, depth, intrinsics, settings, margin)
    if votes is None:
        return None
    return tuple(name for name, (ends, read) in votes.items() if read and ends * 2 > read)


def end_face_seen(
    rotation: np.ndarray,
    translation: np.ndarray,
    radius: float,
    half_length: float,
    points: np.ndarray,
    tolerance: float,
    share: float = 0.1,
) -> bool:
    """Whether at least ``share`` of the cloud ``points`` (N, 3, camera frame) lie on an end face
    of the posed cylinder (within ``tolerance`` of its plane, inside its rim): seen end-on, the
    face places the part along its axis only if the cloud holds it, not a band of the side alone
    (a mask cut by the frame's border)."""
    rot, t = np.asarray(rotation, float), np.asarray(translation, float)
    local = (np.asarray(points, float) - t) @ rot
    if not len(local):
        return False
    on_face = (np.abs(np.abs(local[:, 2]) - half_length) <= tolerance) & (
        np.linalg.norm(local[:, :2], axis=1) <= radius + tolerance
    )
    return int(on_face.sum()) >= max(10, share * len(local))


def slide_to_an_end(
    rotation: np.ndarray,
    translation: np.ndarray,
    radius: float,
    half_length: float,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
    step: float = 0.001,
) -> float | None:
    """The slide (m, along the model's z axis, within a half length either way) that puts an end
    of the posed cylinder where the depth shows one: of the slides at which an end is seen, those
    where the most of its samples agree, their middle. None when no slide shows an end."""
    rot, t = np.asarray(rotation, float), np.asarray(translation, float)
    axis = rot[:, 2]
    scored = []
    for by in np.arange(-half_length, half_length + step / 2, step):
        votes = end_votes(rot, t + by * axis, radius, half_length, depth, intrinsics, settings, margin)
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
    votes = end_votes(rot, t + by * axis, radius, half_length, depth, intrinsics, settings, margin) or {}
    name = max(votes, key=lambda n: votes[n][0] / max(votes[n][1], 1))
    edge = _edge(rot, t + by * axis, radius, half_length, name, depth, intrinsics, settings, margin)
    return by if edge is None else by + (edge if name == "b" else -edge)


def _edge(
    rotation: np.ndarray,
    translation: np.ndarray,
    radius: float,
    half_length: float,
    name: str,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds,
    margin: float,
) -> float | None:
    """How far (m, outward along the axis) from the posed end ``name`` the surface stops in the
    depth: on each generator line, half a pixel's walk from the largest sample offset inside to
    as far beyond, the middle of the last step on the surface before the first farther than it;
    their median. None when no line shows such a step."""
    axis, centre = rotation[:, 2], translation
    sign = 1.0 if name == "b" else -1.0
    end, outward = centre + sign * half_length * axis, sign * axis
    towards = -(end - (end @ axis) * axis)
    towards /= max(float(np.linalg.norm(towards)), 1e-9)
    across = np.cross(axis, towards)
    edges = []
    for deg in settings.generators_deg:
        a = math.radians(deg)
        rim = end + radius * (math.cos(a) * towards + math.sin(a) * across)
        px_per_m = (
            float(np.linalg.norm(_project(rim + 0.01 * outward, intrinsics) - _project(rim, intrinsics)))
            / 0.01
        )
        if rim[2] <= 0 or px_per_m < 1e-4:
            continue
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


def end_votes(
    rotation: np.ndarray,
    translation: np.ndarray,
    radius: float,
    half_length: float,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    settings: AxialEnds = DEFAULT,
    margin: float = 0.0,
) -> dict[str, tuple[int, int]] | None:
    """For each end, how many of its samples show an end and how many could be read
    (:func:`ends_seen`); None when the axis faces the camera."""
    rot, centre = np.asarray(rotation, float), np.asarray(translation, float)
    axis = rot[:, 2]
    sight = centre / max(float(np.linalg.norm(centre)), 1e-9)
    if abs(float(axis @ sight)) > math.cos(math.radians(settings.end_on_deg)):
        return None
    out: dict[str, tuple[int, int]] = {}
    for name, sign in (("a", -1.0), ("b", 1.0)):
        end = centre + sign * half_length * axis
        towards = -(end - (end @ axis) * axis)  # from the axis towards the camera, across it
        towards /= max(float(np.linalg.norm(towards)), 1e-9)
        across = np.cross(axis, towards)
        outward = sign * axis
        votes = [0, 0]  # samples showing an end; samples read
        for deg in settings.generators_deg:
            a = math.radians(deg)
            rim = end + radius * (math.cos(a) * towards + math.sin(a) * across)
            if rim[2] <= 0:
                continue
            px_per_m = float(
                np.linalg.norm(_project(rim + 0.01 * outward, intrinsics) - _project(rim, intrinsics))
            )
            if px_per_m < 1e-6:
                continue
            px_per_m /= 0.01
            for offset in settings.offsets_px:
                step = offset / px_per_m * outward
                inside, beyond = rim - step, rim + step
                d_in = _depth_at(depth, _project(inside, intrinsics))
                d_out = _depth_at(depth, _project(beyond, intrinsics))
                if math.isnan(d_in) or abs(d_in - inside[2]) > settings.on_surface + margin:
                    continue  # the surface is not seen there: this sample says nothing
                if math.isnan(d_out):
                    continue
                votes[1] += 1
                if d_out > beyond[2] + settings.jump + margin:
                    votes[0] += 1
        out[name] = (votes[0], votes[1])
    return out


__all__ = ["DEFAULT", "AxialEnds", "end_face_seen", "end_votes", "ends_seen", "slide_to_an_end"]
