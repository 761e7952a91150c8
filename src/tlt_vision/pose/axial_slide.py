"""Place a part seen from its side along its own axis, by its mask.

An end fitting seen from the side shows a band of its cylinder and no face: the Chamfer fit of
C-3PO (and its certificate) is the same wherever along the model that band lies, so a certified
fitting can come out several millimetres along its axis even on the twin's own masks. The image
still says where the fitting ends. Slid too far, the posed model's near side overhangs its mask
where nothing in front hides it (the thinner tube, or the background, is what the camera saw
there); slid right, the overhang is only where an occluder stands in front.

:func:`slid_along_axis` tries the slides that keep the observed points on the model's span
(``step`` apart), counts for each the camera-facing model surface points that project outside the
mask where the camera saw something not ``hidden_margin`` nearer than the point, and
takes the slide with the fewest, when the pose as it was overhangs by ``min_overhang`` points or
more and the slide removes at least ``min_gain`` of that: a view whose overhang hardly changes
along the axis says nothing about it, and the pose stays. It raises the share of certified end
fittings within the ADD-S goal on held-out images, on the twin's masks and on Mask R-CNN's
(models/vision/history.md). config/vision/node.yaml ``axial_slide`` turns it on for end fittings.
It needs masks that end where the part does: a mask that stops short of the fitting's end slides
a good fitting out of its place on the tube, which ``bench/inspection.py`` shows as good struts
rejected.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tlt_vision.pointcloud import PinholeIntrinsics, pixels_in_image
from tlt_vision.pose.estimator import PoseEstimate


@dataclass(frozen=True)
class AxialSlide:
    """The slide's settings (config/vision/node.yaml ``axial_slide``)."""

    classes: tuple[str, ...] = ("end_fitting",)
    step: float = 0.001  # m between the slides tried
    hidden_margin: float = 0.003  # m nearer than a model point before the depth hides it
    min_gain: float = 0.25  # share of the overhang a slide must remove to be taken
    min_overhang: int = 10  # surface points off the mask below which a pose stays as it is
    samples: int = 512  # surface points of the model projected


DEFAULT = AxialSlide()


def overhangs(
    mask: np.ndarray,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    points: np.ndarray,
    normals: np.ndarray,
    hidden_margin: float,
) -> np.ndarray:
    """For each of S placings of camera-frame surface ``points`` (S, N, 3), with their ``normals``
    (N, 3): how many face the camera and project into the image outside ``mask`` where the depth
    seen is not ``hidden_margin`` nearer than them; (S,). All placings at once: the slides tried
    for one fitting are tens, and one by one their per-call overhead would be most of the cost."""
    placings, n = points.shape[:2]
    flat = points.reshape(-1, 3)
    facing = np.flatnonzero(np.einsum("sij,ij->si", points, normals).reshape(-1) < 0)
    uv, index = pixels_in_image(flat[facing], intrinsics, mask.shape)
    which = facing[index]
    seen = depth[uv[:, 1], uv[:, 0]]
    # Only what the camera saw there counts against the pose: no depth (no return, or the arm's own
    # end effector taken out of the image) says nothing.
    with np.errstate(invalid="ignore"):
        against = np.isfinite(seen) & (seen > 0) & (seen >= flat[which, 2] - hidden_margin)
    off = ~mask[uv[:, 1], uv[:, 0]] & against
    return np.bincount(which[off] // n, minlength=placings)


def slid_along_axis(
    estimate: PoseEstimate,
    observed: np.ndarray,
    mask: np.ndarray,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    surface: tuple[np.ndarray, np.ndarray],
    slide: AxialSlide,
) -> tuple[PoseEstimate, float]:
    """``estimate`` moved along its model's z axis as the mask says (module docstring), and the
    slide (m, 0 when it stays). ``observed``: the cloud posed (N, 3), camera frame; ``surface``: the
    model's surface sample and its normals (M, 3) each, model frame."""
    rot, t = np.asarray(estimate.rotation, float), np.asarray(estimate.translation, float)
    axis = rot[:, 2]
    points, normals = surface
    span = points[:, 2].min(), points[:, 2].max()
    along = (np.asarray(observed, float) - t) @ axis
    if not len(along):
        return estimate, 0.0
    # The observed points stay on the model's span (but for the 2 % at either end of the band).
    low, high = np.percentile(along, 98) - span[1], np.percentile(along, 2) - span[0]
    if high <= low:
        return estimate, 0.0
    steps = np.arange(np.ceil(low / slide.step), np.floor(high / slide.step) + 1)
    slides = np.union1d(steps * slide.step, [0.0])
    posed, turned = points @ rot.T + t, normals @ rot.T
    mask = np.asarray(mask, dtype=bool)
    counts = overhangs(
        mask, depth, intrinsics, posed[None] + slides[:, None, None] * axis, turned, slide.hidden_margin
    )
    here = counts[slides == 0.0][0]
    best = slides[counts == counts.min()]
    chosen = float(best[np.argmin(np.abs(best))])
    if chosen == 0.0 or here < slide.min_overhang or counts.min() > (1.0 - slide.min_gain) * here:
        return estimate, 0.0
    moved = chosen * axis
    return replace(estimate, translation=t + moved, keypoints=np.asarray(estimate.keypoints) + moved), chosen


__all__ = ["DEFAULT", "AxialSlide", "overhangs", "slid_along_axis"]
