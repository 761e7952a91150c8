"""A thin-part region's pixels as the cuts see them: pairs of neighbours, and the points they see.

Both cuts of a semantic-head region work on its pixels as a graph (:mod:`~tlt_vision.segmentation.
depth_split` links neighbours at one depth; :mod:`~tlt_vision.segmentation.bend_split` gives a
small place of a piece to the place it shares most neighbours with) and on the points its pixels
see in space (the bend cut's lines, then the join's axes and the width check of each piece): both
here, so that the two agree on what a neighbour is and each pixel is back-projected once a frame.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from tlt_vision.pointcloud import Intrinsics, back_project

# Each pixel and its right, lower, lower-right and lower-left neighbours: every pair of
# 8-neighbours once, as the head's regions are 8-connected.
_NEIGHBOURS = ((0, 1), (1, 0), (1, 1), (1, -1))


def neighbour_pairs(
    ys: np.ndarray, xs: np.ndarray, shape: tuple[int, ...]
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """For each of the four directions: the indices into ``ys``, ``xs`` of the pixels whose
    neighbour that way lies inside an image of ``shape``, and that neighbour's rows and columns.
    Whether the neighbour is one of the pixels too is the caller's to look up."""
    h, w = shape[:2]
    for dy, dx in _NEIGHBOURS:
        y2, x2 = ys + dy, xs + dx
        inside = (y2 < h) & (x2 >= 0) & (x2 < w)
        yield np.flatnonzero(inside), y2[inside], x2[inside]


@dataclass(frozen=True)
class RegionPoints:
    """The camera-frame points a region's pixels see: ``points`` (N, 3), and ``index`` (H, W),
    each pixel's row of ``points``, -1 for a pixel outside the region or without depth."""

    points: np.ndarray
    index: np.ndarray

    @classmethod
    def of(
        cls, mask: np.ndarray, depth: np.ndarray, camera_matrix: np.ndarray, top: int = 0, left: int = 0
    ) -> RegionPoints:
        """``mask``'s pixels with a depth, back-projected; ``mask`` and ``depth`` may be a crop
        whose first pixel is (``top``, ``left``) of the image ``camera_matrix`` (3x3) is for."""
        ys, xs = np.nonzero(mask)
        z = depth[ys, xs]
        known = np.isfinite(z) & (z > 0)
        index = np.full(mask.shape, -1, dtype=np.int64)
        index[ys[known], xs[known]] = np.arange(int(known.sum()))
        intrinsics = Intrinsics.from_matrix(camera_matrix)
        points = back_project(xs[known] + left, ys[known] + top, z[known], intrinsics)
        return cls(points, index)

    def of_pixels(self, mask: np.ndarray) -> np.ndarray:
        """The points (M, 3) of ``mask``'s pixels (a mask of the region's shape) that have one, in
        the pixels' raster order."""
        rows = self.index[mask]
        return self.points[rows[rows >= 0]]


__all__ = ["RegionPoints", "neighbour_pairs"]
