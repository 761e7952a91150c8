"""Thin-part instances split where the depth image jumps, each piece scored by its own pixels and size.

The semantic head's instances are connected regions of one class in the image
(:mod:`tlt_vision.segmentation.semantic`). Where a tube crosses in front of another, or a rack's
tube meets the frame side behind it, the two touch in the image and come out as one region whose
mask matches neither part: on bench/vision.py's held-out images, a quarter of the tubes and
two-fifths of the cross-frame sides the model missed were merged so. In the depth image the two
lie apart: neighbouring pixels of one part differ in depth by little, pixels of parts one in front
of the other by the gap between them. :func:`split_by_depth` cuts each region between neighbouring
pixels whose depths differ by more than ``jump + jump_per_m * depth`` and keeps each piece as an
instance of its own. A pixel without depth joins its neighbours (no jump can be seen there).

The head also draws many small regions on the machine and the racks, which are tube-like too (on
those images, two in three of its tube regions, most under 60 pixels), each scored by its mean
class probability, as high as a part's. A piece of ``area`` pixels is scored the mean probability
of its class over its own pixels (the result's ``semantic_probs``; the region's score without
them) times ``min(1, area / full_score_area)``: the ranking puts whole parts first, and with the
segmenter's ``min_score`` the fragments drop out. Pieces under ``min_area`` pixels are dropped.

The box branch's classes (end fittings, corner joints, rivets) are left as they are.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from tlt_vision.ops.boxes import boxes_from_masks

# Each pixel linked to its right, lower, lower-right and lower-left neighbours: 8-connectivity,
# as the head's regions.
_NEIGHBOURS = ((0, 1), (1, 0), (1, 1), (1, -1))


@dataclass(frozen=True)
class DepthSplit:
    """How a thin-part region is cut (metres, and pixels of the full image)."""

    jump: float = 0.02
    jump_per_m: float = 0.01
    min_area: int = 30
    full_score_area: int = 200


def depth_pieces(mask: np.ndarray, depth: np.ndarray, split: DepthSplit) -> list[np.ndarray]:
    """The pieces of ``mask`` (boolean masks of its shape): its pixels joined through neighbours
    whose depths differ by at most the jump, pieces under ``split.min_area`` pixels left out."""
    ys, xs = np.nonzero(mask)
    n = len(ys)
    if n == 0:
        return []
    h, w = mask.shape
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[ys, xs] = np.arange(n)
    z = depth[ys, xs].astype(np.float64)
    known = np.isfinite(z) & (z > 0)
    firsts, seconds = [], []
    for dy, dx in _NEIGHBOURS:
        y2, x2 = ys + dy, xs + dx
        inside = (y2 < h) & (x2 >= 0) & (x2 < w)
        a = np.flatnonzero(inside)
        b = index[y2[inside], x2[inside]]
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


def split_by_depth(result: dict[str, torch.Tensor], depth: np.ndarray | None, labels: Sequence[int],
                   split: DepthSplit) -> dict[str, torch.Tensor]:
    """Detections (``boxes``, ``labels``, ``scores``, ``masks`` (D, H, W) at the depth image's
    size, and ``semantic_probs`` (C, H, W) if the model gave them) with those of ``labels`` cut
    into their depth pieces and scored by their pixels and area; the others unchanged. Without a
    depth image, or one of another size, the detections are returned as they are: the cut needs
    depth, and a frame without it fails its pose later with that reason."""
    masks = result["masks"]
    if depth is None or len(masks) == 0 or tuple(depth.shape) != tuple(masks.shape[-2:]):
        return result
    thin = torch.isin(result["labels"], torch.tensor(list(labels), dtype=result["labels"].dtype))
    if not bool(thin.any()):
        return result
    kept = torch.nonzero(~thin).flatten()
    probs = result.get("semantic_probs")
    new_masks, new_labels, new_scores = [], [], []
    regions = torch.nonzero(thin).flatten()
    # Within each mask's own box: a thin part is a sliver of the frame, and whole-frame arrays for
    # each region took 38 ms a frame, against 21 ms so.
    for i, (x0, y0, x1, y1) in zip(regions.tolist(), boxes_from_masks(masks[regions]).int().tolist(),
                                   strict=True):
        box = np.s_[y0:y1, x0:x1]
        label = int(result["labels"][i])
        own = probs[label][box].cpu().numpy() if probs is not None else None
        for small in depth_pieces(masks[i][box].cpu().numpy(), depth[box], split):
            piece = np.zeros(masks.shape[-2:], dtype=bool)
            piece[box] = small
            new_masks.append(piece)
            new_labels.append(label)
            score = float(own[small].mean()) if own is not None else float(result["scores"][i])
            new_scores.append(score * min(1.0, small.sum() / split.full_score_area))
    out = {key: result[key][kept] for key in ("boxes", "labels", "scores", "masks")}
    if probs is not None:
        out["semantic_probs"] = probs
    if not new_masks:
        return out
    m = torch.from_numpy(np.stack(new_masks)).to(masks.device)
    added = {"boxes": boxes_from_masks(m), "labels": torch.tensor(new_labels),
             "scores": torch.tensor(new_scores), "masks": m}
    for key, value in added.items():
        out[key] = torch.cat([out[key], value.to(out[key].dtype)])
    return out


__all__ = ["DepthSplit", "depth_pieces", "split_by_depth"]
