"""Pixels two box-branch masks of one class both claim, given to the one more sure of them.

Each Mask R-CNN mask is predicted in its own box, on its own: two end fittings side by side in a
strut rack, or two rivets in a feeder, get masks that each take in part of the other. On
bench/vision.py's seed 900, 5 of the 7 end fittings seen well enough to certify whose clouds
failed the certificate even at their true pose shared 17-1210 pixels with another end-fitting
detection. :func:`resolve_overlaps` gives each pixel that two masks of one of the chosen classes
share to the one whose mask probability there is higher, as a panoptic merge does, and leaves
every other pixel where it was. Two masks that share more than ``duplicate`` of the smaller one
are two detections of one part, not two parts: splitting them would leave that part two halves,
so they are left as they are (seed 900 with every overlap split: end-fitting mask AP50 0.842 ->
0.753). It needs the model's ``mask_probs`` (D, H, W); a result without them is returned as it is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class ExclusiveOverlaps:
    """Which box-branch classes' masks may not share pixels (names), and above which share of the
    smaller mask two masks are duplicates, left alone."""

    classes: tuple[str, ...]
    duplicate: float

    def labels(self, classes: Sequence[str]) -> tuple[int, ...]:
        """The 1-based labels of :attr:`classes` in a model's ``classes``."""
        return tuple(classes.index(name) + 1 for name in self.classes if name in classes)


def resolve_overlaps(
    result: dict[str, torch.Tensor], labels: Sequence[int], duplicate: float
) -> dict[str, torch.Tensor]:
    """``result`` with each pixel two masks of one of ``labels`` (1-based) share left in the one
    more probable there, but for duplicates (see the module docstring); the same object when no
    such pixel is found."""
    probs, masks = result.get("mask_probs"), result["masks"]
    if probs is None or len(masks) < 2:
        return result
    out = None
    for label in labels:
        rows = (result["labels"] == label).nonzero()[:, 0]
        if len(rows) < 2:
            continue
        flat = masks[rows].flatten(1).to(torch.float32)
        shared = flat @ flat.T
        smaller = torch.minimum(flat.sum(1)[:, None], flat.sum(1)[None, :]).clamp(min=1.0)
        split = (shared > 0) & (shared <= duplicate * smaller)
        for a, b in torch.triu(split, diagonal=1).nonzero().tolist():
            if out is None:
                out = dict(result, masks=masks.clone())
            i, j = int(rows[a]), int(rows[b])
            both = out["masks"][i] & out["masks"][j]
            first = probs[i][both] >= probs[j][both]
            out["masks"][i][both], out["masks"][j][both] = first, ~first
    return result if out is None else out


__all__ = ["ExclusiveOverlaps", "resolve_overlaps"]
