"""A straight part's region that bends in space cut into the straight pieces it is made of.

The twin, like the pose pipeline, takes each side of a cross frame as an instance of its own; the
semantic head draws the pixels of two sides meeting at a corner joint as one region where the
joint's pixels do not part them (an L, or a U of three sides), and the depth does not jump there
(:mod:`tlt_vision.segmentation.depth_split`). Such a region matches none of its sides, and a
frame side is lost so, most often the large sides of a frame held close to the camera.

Every side is straight, and its points lie within about its radius of one line in space. A piece
whose points lie so about their principal axis (the ``quantile`` of their distances to it within
``tolerance`` radii) is left as it is. Otherwise the line that most of its points lie near is
found among lines through pairs of its points (a fixed draw, so a frame gives the same pieces
every time), fitted to those points again, and its points within ``tolerance`` radii of it
become a piece; the rest is cut again, until what is left is straight or smaller than
``min_area`` (then it is kept as it is: the cut must lose no pixel a part may own). A pixel
without depth goes with the nearest pixel that has one. Each piece is then taken apart into its
8-connected places, a place smaller than ``min_area`` joining the piece it touches most.

A real depth camera's noise moves a point along its ray, by more than a part's radius at a few
metres (a ZED's 1 %, 2 cm at 2 m): given ``depth_noise`` (that fraction), a point may lie twice it
further from its line. Without that allowance, noisy depth cuts straight tubes apart; with it,
the cut recovers frame sides on noisy depth and costs next to nothing on exact depth
(models/vision/history.md). The straightness is measured in space, not in the image, where the
noise would be only a scale: two sides seen at a slant lie nearer one line in the image than in
space.
"""

from __future__ import annotations

import heapq
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.ndimage import label as ndimage_label

from tlt_vision.depth_noise import EXACT, DepthNoise
from tlt_vision.segmentation.region_pixels import RegionPoints, neighbour_pairs

_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class BendSplit:
    """When a region is bent, and how near its line a point must lie (radii of the part)."""

    tolerance: float = 2.0
    # The camera's depth noise (1 sigma at each point's depth): a point may lie twice that further
    # from its line.
    depth_noise: DepthNoise = EXACT
    quantile: float = 0.9
    min_area: int = 30
    hypotheses: int = 64
    # Points a line is scored on: a frame side held close is 5000 pixels or more.
    sample: int = 500


def _distances(points: np.ndarray, centre: np.ndarray, direction: np.ndarray) -> np.ndarray:
    offset = points - centre
    return np.linalg.norm(offset - np.outer(offset @ direction, direction), axis=1)


def _principal(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre = points.mean(axis=0)
    return centre, np.linalg.svd(points - centre, full_matrices=False)[2][0]


def _best_line(points: np.ndarray, tol: np.ndarray, split: BendSplit, rng: np.random.Generator) -> np.ndarray:
    """The points (a boolean over ``points``) within their ``tol`` of the line most of them lie
    near."""
    scored = (
        np.arange(len(points))
        if len(points) <= split.sample
        else rng.choice(len(points), split.sample, replace=False)
    )
    a = rng.choice(scored, split.hypotheses)
    b = rng.choice(scored, split.hypotheses)
    direction = points[b] - points[a]
    norm = np.linalg.norm(direction, axis=1)
    fixed = norm >= 2 * tol[a]  # a base too short fixes no direction
    if not fixed.any():
        return np.zeros(len(points), dtype=bool)
    centre, direction = points[a[fixed]], direction[fixed] / norm[fixed, None]
    # Every line's squared distance to every scored point at once, (points, lines), as the squared
    # offset from the line's point less its square along the line: no (lines, points, 3) array.
    # About the points' mean, so that the squares are of centimetres, not metres.
    origin = points[scored].mean(axis=0)
    p, c = points[scored] - origin, centre - origin
    along = p @ direction.T - (c * direction).sum(axis=1)
    squared = (p * p).sum(axis=1)[:, None] - 2.0 * p @ c.T + (c * c).sum(axis=1) - along * along
    best = int((squared <= (tol[scored] ** 2)[:, None]).sum(axis=0).argmax())
    near = _distances(points, centre[best], direction[best]) <= tol
    for _ in range(2):  # the line fitted to its own points, then those near it again
        if near.sum() < 2:
            break
        near = _distances(points, *_principal(points[near])) <= tol
    return near


def straight_pieces(
    mask: np.ndarray, seen: RegionPoints, radius: float, split: BendSplit
) -> list[np.ndarray]:
    """``mask`` (H, W) cut into the pieces that each lie along one line in space (boolean masks of
    its shape; ``[mask]`` when it is straight already). ``seen`` holds the points its pixels see,
    over the same pixels (a region ``mask`` is part of, or ``mask`` itself). ``radius`` is the
    part's, m."""
    ys, xs = np.nonzero(mask)
    rows = seen.index[ys, xs]
    known = rows >= 0
    points = seen.points[rows[known]]
    tol = split.tolerance * radius + 2 * split.depth_noise.sigma(points[:, 2])
    rng = np.random.default_rng(0)
    label = np.full(len(points), -1)
    left_over = np.arange(len(points))
    count = 0
    while len(left_over) >= split.min_area:
        rest, rest_tol = points[left_over], tol[left_over]
        if np.quantile(_distances(rest, *_principal(rest)) - rest_tol, split.quantile) <= 0:
            break
        near = _best_line(rest, rest_tol, split, rng)
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
    piece in two places is not one part. A place under ``min_area`` pixels goes to the place it
    touches most, the smallest first, so that no pixel is lost."""
    place = np.full(mask.shape, -1)
    n = 0
    for k in range(count):
        found, m = ndimage_label(grid == k, structure=_EIGHT)
        place[found > 0] = found[found > 0] - 1 + n
        n += m
    sizes = np.bincount(place[mask], minlength=n)
    # How many neighbouring pixel pairs each two places share.
    contact: list[Counter[int]] = [Counter() for _ in range(n)]
    ys, xs = np.nonzero(mask)
    for first, y2, x2 in neighbour_pairs(ys, xs, mask.shape):
        a, b = place[ys[first], xs[first]], place[y2, x2]
        differ = (b >= 0) & (a != b)
        pairs, counts = np.unique(np.stack([a[differ], b[differ]], axis=1), axis=0, return_counts=True)
        for (i, j), c in zip(pairs.tolist(), counts.tolist(), strict=True):
            contact[i][j] += c
            contact[j][i] += c
    into = list(range(n))
    small = [(int(sizes[i]), i) for i in range(n) if sizes[i] < min_area]
    heapq.heapify(small)
    while small:
        size, i = heapq.heappop(small)
        if into[i] != i or size != sizes[i] or not contact[i]:
            continue  # merged away, grown since, or touching nothing: a piece of its own
        j = max(contact[i], key=contact[i].__getitem__)
        into[i] = j
        sizes[j] += sizes[i]
        for k, c in list(contact[i].items()):
            del contact[k][i]
            if k != j:
                contact[j][k] += c
                contact[k][j] += c
        contact[i] = Counter()
        if sizes[j] < min_area:
            heapq.heappush(small, (int(sizes[j]), j))

    def root(i: int) -> int:
        while into[i] != i:
            i = into[i]
        return i

    final = np.array([root(i) for i in range(n)])
    owner = np.full(mask.shape, -1)
    owner[mask] = final[place[mask]]
    return [owner == r for r in sorted(set(final.tolist()))]


__all__ = ["BendSplit", "straight_pieces"]
