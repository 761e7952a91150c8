"""Thin-part instances cut where the depth image jumps, pieces of one straight part joined again.

The semantic head's instances are connected regions of one class in the image
(:mod:`tlt_vision.segmentation.semantic`). Where a tube crosses in front of another, or a rack's
tube meets the frame side behind it, the two touch in the image and come out as one region whose
mask matches neither part; many of the tubes and cross-frame sides the model misses are merged
so. In the depth image the two
lie apart: neighbouring pixels of one part differ in depth by little, pixels of parts one in front
of the other by the gap between them. :func:`split_by_depth` cuts each region between neighbouring
pixels whose depths differ by more than ``jump + jump_per_m * depth`` and keeps each piece as an
instance of its own. A pixel without depth takes the depth of the region's nearest pixel that has
one: a hole inside a part joins it, and the holes a stereo camera leaves along an edge (its
occlusion shadow, the matcher's window straddling two surfaces) do not bridge the part to what
lies behind it.

The head also draws many small regions on the machine and the racks, which are tube-like too
(most of its tube regions, most of them small), each scored by its mean class probability, as
high as a part's. A piece of ``area`` pixels is scored the mean probability
of its class over its own pixels (the result's ``semantic_probs``; the region's score without
them) times the share of them where that probability is over one half (:func:`piece_score`) times
``min(1, area / full_score_area)``: the ranking puts whole parts first, and with the segmenter's
``min_score`` the fragments drop out. Pieces under ``min_area`` pixels are dropped. The share
matters when the head's map is read generously (node.yaml ``semantic_background_weight``): the
pixels it doubts then keep a tube whole through its narrow stretches, but also join into streaks
of doubt on no part; a part is mostly pixels the head is sure of, so the share scores the
streaks down and the parts not.

A tube that something crosses in front of is seen in pieces, each too little of it to match it.
Given the camera matrix, :func:`split_by_depth` then joins pieces of one class that lie on one line
in space: directions within ``join_angle_deg``, each one's centre within ``join_offset`` of the
other's axis, their ends at most ``join_gap`` apart along it. A joined piece is scored the mean of
its pieces' scores, weighted by their areas. This raises the mask AP50 of tubes and of frame
sides on bench/vision.py's held-out images (models/vision/history.md).

Many of the head's regions that are no part at all are still tube-like in colour, but not as wide as
a part: among well-scored tube pieces, those that match no tube outnumber those that do, and a
matched piece is about as wide in the image as its tube at its depth where the unmatched ones
spread far narrower and wider. Given
``radii`` (each thin class's part radius), a piece whose mean width (its pixels over its length
along its principal image axis) is outside ``width_band`` times ``2 * radius * fx / depth`` (its
median depth) is scored ``width_penalty`` times lower. The width is measured in pixels, so the
depth's noise enters only as a scale: a ZED's percent at a few metres moves it by a percent.

Two sides of a cross frame meeting at a corner joint touch in the image and in depth alike; given
``radii`` and ``bend_tolerance``, a piece bent in space is cut into the straight pieces it is made
of before the join (:mod:`tlt_vision.segmentation.bend_split`).

The box branch's classes (end fittings, corner joints, rivets) are left as they are.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from tlt_vision.depth_noise import EXACT, DepthNoise
from tlt_vision.ops.boxes import boxes_from_masks
from tlt_vision.segmentation.bend_split import BendSplit, straight_pieces
from tlt_vision.segmentation.region_pixels import RegionPoints, neighbour_pairs
from tlt_vision.segmentation.semantic import SURE


def piece_score(own: np.ndarray) -> float:
    """A thin piece's score from its pixels' probabilities of its class: their mean times the share
    of them over :data:`SURE`."""
    return float(own.mean()) * float((own > SURE).mean())


def voted(probs: Sequence[np.ndarray], piece: np.ndarray) -> tuple[int, float]:
    """A thin piece's class, the index in ``probs`` (each thin class's probabilities over the
    piece's box) of the most probability over its pixels, and its score: :func:`piece_score` of the
    classes' probabilities together times that class's share of them. A part whose class the head
    wavers between along it scores as a thin part it is sure of, halved at an even split."""
    each = [q[piece] for q in probs]
    mass = np.array([float(q.sum()) for q in each])
    chosen = int(mass.argmax())
    share = mass[chosen] / mass.sum() if mass.sum() > 0 else 0.0
    return chosen, piece_score(np.sum(each, axis=0)) * float(share)


def _scores(own: np.ndarray | None, piece: np.ndarray) -> bool:
    """Whether a piece (a mask over ``own``, its class's probabilities) can score above 0; without
    the probabilities it keeps its region's score."""
    return own is None or bool((own[piece] > SURE).any())


@dataclass(frozen=True)
class DepthSplit:
    """How a thin-part region is cut (metres, and pixels of the full image)."""

    jump: float = 0.02
    jump_per_m: float = 0.01
    min_area: int = 30
    full_score_area: int = 200
    join_angle_deg: float = 5.0
    join_offset: float = 0.015
    join_gap: float = 0.3
    # (low, high) of a piece's mean image width over its part's at its depth; None: not checked.
    width_band: tuple[float, float] | None = None
    width_penalty: float = 0.3
    # A piece bent in space cut into straight ones, points within this many of its part's radius
    # of their line (needs ``radii``; :mod:`tlt_vision.segmentation.bend_split`); None: not cut.
    bend_tolerance: float | None = None
    # The depth camera's noise, which the bend cut allows for.
    depth_noise: DepthNoise = EXACT
    # Each piece of the class with the most probability summed over it, scored by the thin
    # classes' probabilities together times that class's share (:func:`voted`); False: of its
    # region's class, scored by that class's probabilities.
    vote: bool = False


def depth_pieces(mask: np.ndarray, depth: np.ndarray, split: DepthSplit) -> list[np.ndarray]:
    """The pieces of ``mask`` (boolean masks of its shape): its pixels joined through neighbours
    whose depths differ by at most the jump, pieces under ``split.min_area`` pixels left out."""
    ys, xs = np.nonzero(mask)
    n = len(ys)
    if n < split.min_area:  # no piece can be large enough
        return []
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[ys, xs] = np.arange(n)
    z = depth[ys, xs].astype(np.float64)
    known = np.isfinite(z) & (z > 0)
    if known.any() and not known.all():
        # A pixel without depth takes the depth of the region's nearest pixel that has one: a hole
        # inside a part joins it, and the band of holes a stereo camera leaves along an edge does
        # not bridge the part to what lies behind it.
        has = np.zeros(mask.shape, dtype=bool)
        has[ys[known], xs[known]] = True
        _, (iy, ix) = distance_transform_edt(~has, return_indices=True)
        z = np.where(known, z, depth[iy[ys, xs], ix[ys, xs]])
        known[:] = True
    firsts, seconds = [], []
    for a, y2, x2 in neighbour_pairs(ys, xs, mask.shape):
        b = index[y2, x2]
        a, b = a[b >= 0], b[b >= 0]
        za, zb = z[a], z[b]
        with np.errstate(invalid="ignore"):
            near = np.abs(za - zb) <= split.jump + split.jump_per_m * np.minimum(za, zb)
        linked = near | ~known[a] | ~known[b]
        firsts.append(a[linked])
        seconds.append(b[linked])
    a, b = np.concatenate(firsts), np.concatenate(seconds)
    links = coo_matrix((np.ones(len(a), dtype=bool), (a, b)), shape=(n, n))
    count, label = connected_components(links, directed=False)
    sizes = np.bincount(label, minlength=count)
    pieces = []
    for k in np.flatnonzero(sizes >= split.min_area):
        piece = np.zeros(mask.shape, dtype=bool)
        own = label == k
        piece[ys[own], xs[own]] = True
        pieces.append(piece)
    return pieces


@dataclass(frozen=True)
class _Axis:
    centre: np.ndarray
    direction: np.ndarray
    half_length: float


def _axis(points: np.ndarray) -> _Axis | None:
    """The principal axis of a piece's points (None for too few to tell)."""
    if len(points) < 10:
        return None
    centre = points.mean(axis=0)
    direction = np.linalg.svd(points - centre, full_matrices=False)[2][0]
    along = (points - centre) @ direction
    return _Axis(centre, direction, float(along.max() - along.min()) / 2)


def _on_one_line(a: _Axis | None, b: _Axis | None, split: DepthSplit) -> bool:
    if a is None or b is None:
        return False
    if abs(float(a.direction @ b.direction)) < np.cos(np.radians(split.join_angle_deg)):
        return False
    offset = b.centre - a.centre
    along = float(offset @ a.direction)
    if np.linalg.norm(offset - along * a.direction) > split.join_offset:
        return False
    return abs(along) - a.half_length - b.half_length <= split.join_gap


def join_collinear(
    masks: list[np.ndarray],
    scores: list[float],
    depth: np.ndarray,
    k: np.ndarray,
    split: DepthSplit,
    points: list[np.ndarray] | None = None,
) -> tuple[list[np.ndarray], list[float], list[np.ndarray]]:
    """Pieces of one class (masks and scores) with those on one line in space joined, pass after
    pass until no two are; a joined piece's score is its pieces' mean weighted by area. ``points``,
    each piece's back-projected pixels, if the caller has them already; returned joined too."""
    masks, scores = list(masks), list(scores)
    points = list(points) if points is not None else [RegionPoints.of(m, depth, k).points for m in masks]
    areas = [np.count_nonzero(m) for m in masks]  # full-frame masks: several times sum()'s speed
    axes = [_axis(p) for p in points]
    joined = True
    while joined:
        joined = False
        i = 0
        while i < len(masks):
            j = i + 1
            while j < len(masks):
                if not _on_one_line(axes[i], axes[j], split):
                    j += 1
                    continue
                masks[i] = masks[i] | masks[j]
                scores[i] = (scores[i] * areas[i] + scores[j] * areas[j]) / (areas[i] + areas[j])
                areas[i] += areas[j]
                points[i] = np.concatenate([points[i], points[j]])
                axes[i] = _axis(points[i])
                for kept in (masks, scores, areas, points, axes):
                    del kept[j]
                joined = True
            i += 1
    return masks, scores, points


def width_ratio(points: np.ndarray, k: np.ndarray, radius: float) -> float | None:
    """A piece's mean width in the image (its pixels over its extent along its principal axis),
    from its back-projected pixels ``points`` (N, 3) and the camera matrix ``k``, over a
    cylinder's of ``radius`` at the piece's median depth (``2 * radius * fx / depth``); None for
    a piece too small to tell."""
    if len(points) < 10:
        return None
    z = points[:, 2]
    pixels = np.stack([k[0, 0] * points[:, 0] / z, k[1, 1] * points[:, 1] / z], axis=1)
    pixels -= pixels.mean(axis=0)
    along = pixels @ np.linalg.eigh(pixels.T @ pixels)[1][:, -1]
    length = float(along.max() - along.min()) + 1.0
    return (len(points) / length) / (2.0 * radius * float(k[0, 0]) / float(np.median(z)))


def radii_by_label(classes: Sequence[str], radii: Mapping[str, float]) -> dict[int, float]:
    """``radii`` (class name: radius) keyed by the model's labels, 1-based in ``classes``' order,
    as :func:`split_by_depth` takes them."""
    classes = list(classes)
    return {classes.index(c) + 1: r for c, r in radii.items() if c in classes}


def split_by_depth(
    result: dict[str, torch.Tensor],
    depth: np.ndarray | None,
    labels: Sequence[int],
    split: DepthSplit,
    camera_matrix: np.ndarray | None = None,
    radii: Mapping[int, float] | None = None,
) -> dict[str, torch.Tensor]:
    """Detections (``boxes``, ``labels``, ``scores``, ``masks`` (D, H, W) at the depth image's
    size, and ``semantic_probs`` (C, H, W) if the model gave them) with those of ``labels`` cut
    into their depth pieces and scored by their pixels and area, and with ``camera_matrix`` (3x3)
    the pieces on one line in space joined again and, with ``radii`` (label: part radius, m),
    pieces bent in space first cut into straight ones (``split.bend_tolerance``) and, with
    ``split.width_band``, those not as wide as their part scored down; the others unchanged.
    Without a depth image, or one of another size, the detections are returned as they are: the
    cut needs depth, and a frame without it fails its pose later with that reason."""
    masks = result["masks"]
    if depth is None or len(masks) == 0 or tuple(depth.shape) != tuple(masks.shape[-2:]):
        return result
    thin = torch.isin(result["labels"], torch.tensor(list(labels), dtype=result["labels"].dtype))
    if not bool(thin.any()):
        return result
    kept = torch.nonzero(~thin).flatten()
    probs = result.get("semantic_probs")
    pieces: dict[int, tuple[list[np.ndarray], list[float], list[np.ndarray]]] = {
        label: ([], [], []) for label in labels
    }
    regions = torch.nonzero(thin).flatten()
    bend = (
        BendSplit(tolerance=split.bend_tolerance, depth_noise=split.depth_noise, min_area=split.min_area)
        if split.bend_tolerance is not None
        else None
    )
    # Within each mask's own box: a thin part is a sliver of the frame, and whole-frame arrays for
    # each region cost nearly twice the time a frame.
    for i, (x0, y0, x1, y1) in zip(
        regions.tolist(), boxes_from_masks(masks[regions]).int().tolist(), strict=True
    ):
        box = np.s_[y0:y1, x0:x1]
        label = int(result["labels"][i])
        own = probs[label][box].cpu().numpy() if probs is not None else None
        if split.vote and probs is not None:
            each = [probs[other][box].cpu().numpy() for other in labels]
            own = np.sum(each, axis=0)  # a piece is kept when sure of being a thin part
        region = masks[i][box].cpu().numpy()
        # A piece without a pixel the head is sure of scores nothing (piece_score): not kept, and
        # not searched for bends, the cut's costliest step.
        smalls = [s for s in depth_pieces(region, depth[box], split) if _scores(own, s)]
        seen = (
            RegionPoints.of(region, depth[box], camera_matrix, y0, x0) if camera_matrix is not None else None
        )
        radius = (radii or {}).get(label)
        if bend is not None and seen is not None and radius is not None:
            smalls = [
                straight
                for small in smalls
                for straight in straight_pieces(small, seen, radius, bend)
                if straight.sum() >= split.min_area and _scores(own, straight)
            ]
        for small in smalls:
            piece = np.zeros(masks.shape[-2:], dtype=bool)
            piece[box] = small
            if split.vote and probs is not None:
                chosen, score = voted(each, small)
                into = labels[chosen]
            else:
                score = piece_score(own[small]) if own is not None else float(result["scores"][i])
                into = label
            pieces[into][0].append(piece)
            pieces[into][1].append(score * min(1.0, small.sum() / split.full_score_area))
            if seen is not None:
                pieces[into][2].append(seen.of_pixels(small))
    new_masks, new_labels, new_scores = [], [], []
    for label, (class_masks, class_scores, class_points) in pieces.items():
        if camera_matrix is not None:
            class_masks, class_scores, class_points = join_collinear(
                class_masks, class_scores, depth, camera_matrix, split, class_points
            )
            radius = (radii or {}).get(label)
            if split.width_band is not None and radius is not None:
                low, high = split.width_band
                for k, piece_points in enumerate(class_points):
                    ratio = width_ratio(piece_points, camera_matrix, radius)
                    if ratio is not None and not low <= ratio <= high:
                        class_scores[k] *= split.width_penalty
        new_masks += class_masks
        new_labels += [label] * len(class_masks)
        new_scores += class_scores
    out = {key: result[key][kept] for key in ("boxes", "labels", "scores", "masks")}
    if probs is not None:
        out["semantic_probs"] = probs
    if not new_masks:
        return out
    m = torch.from_numpy(np.stack(new_masks)).to(masks.device)
    added = {
        "boxes": boxes_from_masks(m),
        "labels": torch.tensor(new_labels),
        "scores": torch.tensor(new_scores),
        "masks": m,
    }
    for key, value in added.items():
        out[key] = torch.cat([out[key], value.to(out[key].dtype)])
    return out


__all__ = [
    "DepthSplit",
    "depth_pieces",
    "join_collinear",
    "piece_score",
    "radii_by_label",
    "split_by_depth",
    "voted",
    "width_ratio",
]
