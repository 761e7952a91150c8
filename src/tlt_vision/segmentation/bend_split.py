"""A straight part's region that bends in space cut into the straight pieces it is made of.

The twin, like the pose pipeline, takes each side of a cross frame as an instance of its own; the
semantic head draws the pixels of two sides meeting at a corner joint as one region where the
joint's pixels do not part them (an L, or a U of three sides), and the depth does not jump there
(:mod:`tlt_vision.segmentation.depth_split`). Such a region matches none of its sides: on
``bench/vision.py``'s seed-950 images, 31 of the 329 frame sides were lost so, most of them the
large sides of a frame held close to the camera.

Every side is straight, and its points lie within about its radius of one line in space. A piece
whose points lie so about their principal axis (the ``quantile`` of their distances to it within
``tolerance`` radii) is left as it is. Otherwise the line that most of its points lie near is
found among lines through pairs of its points (a fixed draw, so a frame gives the same pieces
every time), fitted to those points again, and its points within ``tolerance`` radii of it
become a piece; the rest is cut again, until what is left is straight or smaller than
``min_area`` (then it is kept as it is: the cut must lose no pixel a part may own). A pixel
without depth goes with the nearest pixel that has one. Each piece is then taken apart into its
8-connected places, a place smaller than ``min_area`` joining the piece it touches most.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt
from scipy.ndimage import label as ndimage_label

from tlt_vision.pointcloud import Intrinsics, back_project

_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class BendSplit:
    """When a region is bent, and how near its line a point must lie (radii of the part)."""

    tolerance: float = 2.0
    quantile: float = 0.9
    min_area: int = 30
    hypotheses: int = 64
    # Points a line is scored on: a frame side held close is 5000 pixels or more.
    sample: int = 1500


def _distances(points: np.ndarray, centre: np.ndarray, direction: np.ndarray) -> np.ndarray:
    offset = points - centre
    return np.linalg.norm(offset - np.outer(offset @ direction, direction), axis=1)


def _principal(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre = points.mean(axis=0)
    return centre, np.linalg.svd(points - centre, full_matrices=False)[2][0]


def _best_line(points: np.ndarray, tol: float, split: BendSplit, rng: np.random.Generator
               ) -> np.ndarray:
    """The points (a boolean over ``points``) within ``tol`` of the line most of them lie near."""
    scored = points if len(points) <= split.sample else points[
        rng.choice(len(points), split.sample, replace=False)]
    a = rng.integers(0, len(scored), split.hypotheses)
    b = rng.integers(0, len(scored), split.hypotheses)
    best, best_count = None, -1
    for i, j in zip(a, b, strict=True):
        direction = scored[j] - scored[i]
        norm = float(np.linalg.norm(direction))
        if norm < 2 * tol:  # too short a base to fix a direction
            continue
        count = int((_distances(scored, scored[i], direction / norm) <= tol).sum())
        if count > best_count:
            best, best_count = (scored[i], direction / norm), count
    if best is None:
        return np.zeros(len(points), dtype=bool)
    near = _distances(points, *best) <= tol
    for _ in range(2):  # the line fitted to its own points, then those near it again
        if near.sum() < 2:
            break
        near = _distances(points, *_principal(points[near])) <= tol
    return near


def straight_pieces(mask: np.ndarray, depth: np.ndarray, camera_matrix: np.ndarray, radius: float,
                    split: BendSplit, top: int = 0, left: int = 0) -> list[np.ndarray]:
    """``mask`` (H, W) cut into the pieces that each lie along one line in space (boolean masks of
    its shape; ``[mask]`` when it is straight already). ``depth`` is the frame's depth over the
    same pixels; ``mask`` and ``depth`` may be a crop whose first pixel is (``top``, ``left``) of
    the image ``camera_matrix`` is for. ``radius`` is the part's, m."""
    ys, xs = np.nonzero(mask)
    z = depth[ys, xs]
    known = np.isfinite(z) & (z > 0)
    points = back_project(xs[known] + left, ys[known] + top, z[known], Intrinsics.from_matrix(camera_matrix))
    tol = split.tolerance * radius
    rng = np.random.default_rng(0)
    label = np.full(len(points), -1)
    left_over = np.arange(len(points))
    count = 0
    while len(left_over) >= split.min_area:
        rest = points[left_over]
        if np.quantile(_distances(rest, *_principal(rest)), split.quantile) <= tol:
            break
        near = _best_line(rest, tol, split, rng)
        if near.sum() < split.min_area or near.all():
            break
        label[left_over[near]] = count
        count += 1
        left_over = left_over[~near]
    if count == 0:
        return [mask]
    label[left_over] = count
    count += 1
    # Every pixel of the mask labelled: those with depth as above, the others as their nearest.
    grid = np.full(mask.shape, -1)
    grid[ys[known], xs[known]] = label
    if not known.all():
        nearest = distance_transform_edt(grid < 0, return_distances=False, return_indices=True)
        filled = grid[nearest[0], nearest[1]]
        grid[ys, xs] = filled[ys, xs]
    return _connected(mask, grid, count, split.min_area)


def _connected(mask: np.ndarray, grid: np.ndarray, count: int, min_area: int) -> list[np.ndarray]:
    """The labelled pixels' pieces, each 8-connected: a line's points may lie in more than one
    place of the region (the rest of a side past the corner's pixels the other line took), and a
    piece in two places is not one part. A place under ``min_area`` pixels goes to the piece it
    touches most, the smallest first, so that no pixel is lost."""
    places: list[np.ndarray] = []
    for k in range(count):
        found, n = ndimage_label(grid == k, structure=_EIGHT)
        places += [found == i for i in range(1, n + 1)]
    merged = True
    while merged:  # each pass merges one place away, or none and ends
        merged = False
        for small in sorted(range(len(places)), key=lambda i: int(places[i].sum())):
            if places[small].sum() >= min_area:
                break
            ring = binary_dilation(places[small], structure=_EIGHT) & mask & ~places[small]
            contact = [int((ring & p).sum()) if i != small else 0 for i, p in enumerate(places)]
            into = int(np.argmax(contact))
            if contact[into]:  # one that touches nothing else stays a piece of its own
                places[into] = places[into] | places[small]
                del places[small]
                merged = True
                break
    return places


__all__ = ["BendSplit", "straight_pieces"]
