"""Free-space check of a certified pose: the posed model must not stand where the camera saw past.

C-3PO's certificate (:mod:`tlt_vision.pose.certificate`) measures from the observed points to the
posed model only, so it cannot see model surface that nothing observed. Usually that surface is
hidden (the part's back, or behind whatever occludes it), but a pose can fit every observed point
and still put model surface in front of what the camera saw: a rivet seen end-on shows only its
head, a disc, and the rivet lying across that disc fits the disc as well (Chamfer p90 under its
3 mm threshold, both end keypoints near the disc) while its length stands out on either side,
in front of the tray behind: the certificate alone passes such poses 90 degrees off.

The depth image rules that out. The posed model's surface sample is projected into the image; a
point is *in free space* when the depth there is more than ``margin`` beyond it, the depth being
the nearest within ``window`` pixels, so that a point on the part's own silhouette is compared
with the part rather than with the background a pixel away. Points outside the image or where the
depth has no return are not counted either way. A certified pose with more than ``max_fraction``
of its projected points in free space loses its certificate, with that reason. ``max_fraction``
lies between the share a wrongly certified rivet puts in free space and the most a right pose
shows (a long tube's, at its silhouette); it was chosen on held-out renders
(models/vision/history.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from tlt_vision.pointcloud import PinholeIntrinsics, pixels_in_image
from tlt_vision.pose.estimator import PoseEstimate


@dataclass(frozen=True)
class FreeSpace:
    """The check's settings (config/vision/node.yaml ``free_space``)."""

    margin: float = 0.005  # m beyond the model point before the depth counts as seen past it
    max_fraction: float = 0.25  # of the projected points, above which the pose is not certified
    window: int = 5  # pixels (odd): the nearest depth in this square is compared
    samples: int = 512  # surface points of the model projected


DEFAULT = FreeSpace()


def nearest_depth(depth: np.ndarray, window: int) -> np.ndarray:
    """Per pixel, the nearest valid depth within a ``window`` x ``window`` square (inf where none)."""
    d = np.asarray(depth, dtype=np.float32)
    seen = np.where(np.isfinite(d) & (d > 0), d, np.inf).astype(np.float32)
    if window <= 1:
        return seen
    return cv2.erode(seen, np.ones((window, window), np.uint8), borderType=cv2.BORDER_REPLICATE)


def free_space_fraction(
    near: np.ndarray, intrinsics: PinholeIntrinsics, points: np.ndarray, margin: float
) -> float:
    """Share of camera-frame ``points`` (N, 3) that project into the image with ``near``
    (:func:`nearest_depth`) more than ``margin`` beyond them, among those that project onto a
    pixel with depth; 0 when none does."""
    p = np.asarray(points, dtype=float)
    uv, index = pixels_in_image(p, intrinsics, near.shape)
    seen = near[uv[:, 1], uv[:, 0]]
    z = p[index, 2]
    counted = np.isfinite(seen)
    if not counted.any():
        return 0.0
    return float(np.count_nonzero(z[counted] < seen[counted] - margin) / np.count_nonzero(counted))


def checked(
    estimate: PoseEstimate,
    near: np.ndarray,
    intrinsics: PinholeIntrinsics,
    surface: np.ndarray,
    check: FreeSpace,
) -> PoseEstimate:
    """``estimate`` as it is when it passes the check or is not certified; otherwise uncertified,
    with the fraction in the reason. ``surface``: the model's surface sample (M, 3), model frame."""
    if not estimate.certified:
        return estimate
    posed = surface @ estimate.rotation.T + estimate.translation
    fraction = free_space_fraction(near, intrinsics, posed, check.margin)
    if fraction <= check.max_fraction:
        return estimate
    reason = (
        f"posed model where the camera saw past it: {fraction:.0%} of its surface more than "
        f"{check.margin * 1000:.0f} mm in front of the depth seen (limit {check.max_fraction:.0%})"
    )
    return replace(
        estimate,
        certificate=replace(estimate.certificate, certified=False, reason=reason, depth_limited=False),
    )


__all__ = ["DEFAULT", "FreeSpace", "checked", "free_space_fraction", "nearest_depth"]
