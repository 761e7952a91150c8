"""Pose a refused compact part again on the larger of two pieces of its cloud.

Racked end fittings stand side by side, nearer than the cloud's link (``detached.links``) parts
them, and a learned mask sometimes takes in a neighbour's pixels (up to more than half of the
mask): the fit then lies across the two parts and the certificate rightly
refuses it. The mask's instance still has most of its pixels on its own part. So a cloud of the
classes in ``classes`` whose pose was not certified is parted in two about two centres (a 2-means
in space); where each piece holds at least ``min_share`` of the points and the centres lie at
least ``min_separation`` of the part's size apart, the larger piece is posed and judged as any
cloud is (certificate, axial slide, free space), and its pose is taken only when certified and
when the posed model, where the camera could see it, lies within the mask: at least ``in_mask``
of its visible surface points project into the mask grown by ``mask_margin`` pixels. A half of
one part posed off its place spills out of the mask; without that check such a half, fitted
tens of degrees off, can pass the certificate.

On held-out image sets it raises the share of views certified on the model's masks
(models/vision/history.md). Some of the poses it adds lie a few millimetres along their axis
(the piece left out is where the fitting ends); none is grossly wrong.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tlt_vision.pointcloud import PinholeIntrinsics, project


@dataclass(frozen=True)
class Parting:
    """The parting's settings (config/vision/node.yaml ``parting``)."""

    classes: tuple[str, ...] = ("end_fitting",)
    min_share: float = 0.2  # of the cloud's points in the smaller piece
    min_separation: float = 0.3  # between the pieces' centres, a fraction of the part's size
    in_mask: float = 0.9  # of the posed model's visible surface points inside the mask
    mask_margin: int = 2  # pixels the mask is grown by for that count
    hidden_margin: float = 0.01  # m behind the depth seen at which a model point counts as hidden


DEFAULT = Parting()


def larger_piece(points: np.ndarray, min_share: float, min_separation: float) -> np.ndarray | None:
    """Boolean (N,): the points of the larger of two pieces of ``points`` (N, 3) parted about two
    centres (Lloyd's 2-means from the two points farthest apart along the cloud), or None when
    the smaller piece holds under ``min_share`` of the points or the centres lie under
    ``min_separation`` (m) apart: one part, not two."""
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        return None
    a = p[np.argmax(np.linalg.norm(p - p.mean(0), axis=1))]
    b = p[np.argmax(np.linalg.norm(p - a, axis=1))]
    in_b = np.zeros(len(p), dtype=bool)
    for _ in range(50):
        in_b = np.linalg.norm(p - a, axis=1) > np.linalg.norm(p - b, axis=1)
        if in_b.all() or not in_b.any():
            return None
        a_new, b_new = p[~in_b].mean(0), p[in_b].mean(0)
        if np.allclose(a_new, a) and np.allclose(b_new, b):
            break
        a, b = a_new, b_new
    share = float(in_b.mean())
    if min(share, 1.0 - share) < min_share or np.linalg.norm(a - b) < min_separation:
        return None
    return in_b if share > 0.5 else ~in_b


def visible_share_in_mask(
    surface: np.ndarray,
    mask: np.ndarray,
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    margin_px: int,
    hidden_margin: float,
) -> float:
    """Of the posed model's ``surface`` points (camera frame) that project into the image where it
    has depth and are not hidden (not more than ``hidden_margin`` behind that depth), the share
    that fall in ``mask`` grown by ``margin_px`` pixels; 0 when none is visible."""
    s = np.asarray(surface, dtype=np.float64)
    s = s[s[:, 2] > 0]
    if not len(s):
        return 0.0
    uv = np.round(project(s, intrinsics)).astype(int)
    h, w = mask.shape
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    uv, z = uv[inside], s[inside, 2]
    seen = depth[uv[:, 1], uv[:, 0]]
    with np.errstate(invalid="ignore"):
        visible = z <= seen + hidden_margin  # where there is no depth (NaN) the image says nothing
    if not visible.any():
        return 0.0
    size = 2 * margin_px + 1
    grown = cv2.dilate(np.asarray(mask, dtype=np.uint8), np.ones((size, size), np.uint8)).astype(bool)
    return float(grown[uv[visible, 1], uv[visible, 0]].mean())


__all__ = ["DEFAULT", "Parting", "larger_piece", "visible_share_in_mask"]
