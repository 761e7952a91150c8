"""Box-branch masks trimmed of the pixels the semantic head holds to be a thin part.

An end fitting sits on the end of its tube, at the tube's depth, and its mask from the box branch
(56x56 over its box) often takes in a band of that tube: on bench/vision.py's seed 900, 18 of the 23
end fittings seen well enough to certify whose pose was not certified had masks whose clouds fail
the certificate even at the fitting's true pose (30-200 pixels of tube in a 60-650 pixel mask). No
depth cut separates them, but the semantic head, which classifies every pixel, knows tube from
fitting there. :func:`trim_by_semantic` takes from the masks of the ``labels`` given (box-branch
classes, none of the head's own) the pixels where the head's probability of any of its classes is
above ``above``. An instance left with no pixel is dropped.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class SemanticTrim:
    """Which box-branch classes are trimmed (names), and above which probability of a thin part."""

    classes: tuple[str, ...]
    above: float

    def labels(self, classes: Sequence[str]) -> tuple[int, ...]:
        """The 1-based labels of :attr:`classes` in a model's ``classes``."""
        return tuple(classes.index(name) + 1 for name in self.classes if name in classes)


def trim_by_semantic(
    result: dict[str, torch.Tensor], labels: Sequence[int], semantic_labels: Sequence[int], above: float
) -> dict[str, torch.Tensor]:
    """``result`` (a detection result with ``semantic_probs`` (C, H, W), indexed by label) with the
    masks of ``labels`` (1-based) trimmed; the same object when nothing is to be trimmed."""
    probs = result.get("semantic_probs")
    masks = result["masks"]
    if probs is None or not len(masks) or not labels or not semantic_labels:
        return result
    chosen = torch.isin(result["labels"], torch.tensor(list(labels), dtype=result["labels"].dtype))
    if not bool(chosen.any()):
        return result
    thin = probs[list(semantic_labels)].amax(dim=0) > above  # once a frame, for every mask
    rows = chosen.nonzero()[:, 0]
    masks = masks.clone()
    masks[rows] = masks[rows] & ~thin
    # An empty mask goes, trimmed or not; amax of the bytes is many times torch's any over a row.
    kept = masks.flatten(1).view(torch.uint8).amax(dim=1) > 0
    out = dict(result)
    for key in ("boxes", "labels", "scores"):
        out[key] = result[key][kept]
    out["masks"] = masks[kept]
    return out


__all__ = ["SemanticTrim", "trim_by_semantic"]
