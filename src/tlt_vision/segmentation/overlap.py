"""Pixels two box-branch masks of one class both claim, given to the one more sure of them.

Each Mask R-CNN mask is predicted in its own box, on its own: two end fittings side by side in a
strut rack, or two rivets in a feeder, get masks that each take in part of the other; most of the
end fittings seen well enough to certify whose clouds fail the certificate even at their true pose
share pixels with another end-fitting detection. :func:`resolve_overlaps` gives each pixel that two
masks of one of the chosen classes share to the one whose mask probability there is higher, as a
panoptic merge does, and leaves every other pixel where it was. Two masks that share more than
``duplicate`` of the smaller one are two detections of one part, not two parts: splitting them would
leave that part two halves, so they are left as they are (splitting every overlap lowers the end
fittings' mask AP50). It needs the model's ``mask_probs`` of its box branch's detections, (B, H, W)
for the first B, a semantic head's regions after them (no class of theirs can be named); a result
without them is returned as it is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from tlt_vision.ops.boxes import boxes_from_masks


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
        rows = (result["labels"][: len(probs)] == label).nonzero()[:, 0]
        if len(rows) < 2:
            continue
        for a, b in _split_pairs(masks[rows], duplicate):
            if out is None:
                out = dict(result, masks=masks.clone())
            i, j = int(rows[a]), int(rows[b])
            both = out["masks"][i] & out["masks"][j]
            first = probs[i][both] >= probs[j][both]
            out["masks"][i][both], out["masks"][j][both] = first, ~first
    return result if out is None else out


def _split_pairs(masks: torch.Tensor, duplicate: float) -> list[tuple[int, int]]:
    """The pairs (a < b, in order) of ``masks`` (N, H, W) that share a pixel but not more than
    ``duplicate`` of the smaller; counted within the two boxes' intersection, since masks share no
    pixel outside it (over whole frames, as floats, these counts would cost milliseconds a frame)."""
    boxes = boxes_from_masks(masks).int().tolist()
    areas = [int(m[y0:y1, x0:x1].sum()) for m, (x0, y0, x1, y1) in zip(masks, boxes, strict=True)]
    pairs = []
    for a in range(len(boxes)):
        for b in range(a + 1, len(boxes)):
            x0, y0 = max(boxes[a][0], boxes[b][0]), max(boxes[a][1], boxes[b][1])
            x1, y1 = min(boxes[a][2], boxes[b][2]), min(boxes[a][3], boxes[b][3])
            if x1 <= x0 or y1 <= y0:
                continue
            shared = int((masks[a, y0:y1, x0:x1] & masks[b, y0:y1, x0:x1]).sum())
            if 0 < shared <= duplicate * max(min(areas[a], areas[b]), 1):
                pairs.append((a, b))
    return pairs


__all__ = ["ExclusiveOverlaps", "resolve_overlaps"]
