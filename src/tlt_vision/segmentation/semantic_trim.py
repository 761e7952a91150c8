"""Box-branch masks trimmed of the pixels the semantic head holds to be a thin part.

An end fitting sits on the end of its tube, at the tube's depth, and its mask from the box branch
(56x56 over its box) often takes in a band of that tube, enough that the cloud fails the
certificate even at the fitting's true pose; most end fittings seen well enough to certify whose
pose is not certified are refused so. No
depth cut separates them, but the semantic head, which classifies every pixel, knows tube from
fitting there. :func:`trim_by_semantic` takes from the masks of the ``labels`` given (box-branch
classes, none of the head's own) the pixels where the head's probability of any of its classes is
above ``above``. An instance left with no pixel is dropped.

A corner joint's mask takes in the frame sides it joins in the same way, but trimmed outright its
masks lose more (in mask AP50) than the certificate gains. So the classes in ``cores`` keep their masks whole
and :func:`semantic_cores` gives each its trimmed mask beside it as its *core*
(``core_masks``): where the whole mask's pose is refused, the pipeline fits the core's cloud from
that pose (:mod:`tlt_vision.pipeline`).
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
    cores: tuple[str, ...] = ()  # kept whole, their trimmed masks given beside them

    def labels(self, classes: Sequence[str]) -> tuple[int, ...]:
        """The 1-based labels of :attr:`classes` in a model's ``classes``."""
        return _labels(self.classes, classes)

    def core_labels(self, classes: Sequence[str]) -> tuple[int, ...]:
        """The 1-based labels of :attr:`cores` in a model's ``classes``."""
        return _labels(self.cores, classes)


def _labels(names: Sequence[str], classes: Sequence[str]) -> tuple[int, ...]:
    return tuple(classes.index(name) + 1 for name in names if name in classes)


def _thin(
    result: dict[str, torch.Tensor], chosen: torch.Tensor, semantic_labels: Sequence[int], above: float
) -> torch.Tensor | None:
    """Where the semantic head holds a pixel to be a thin part (H, W), or None when nothing of
    ``chosen`` (a row per detection) is to be looked at."""
    probs = result.get("semantic_probs")
    if probs is None or not bool(chosen.any()) or not semantic_labels:
        return None
    return probs[list(semantic_labels)].amax(dim=0) > above  # once a frame, for every mask


def _chosen(result: dict[str, torch.Tensor], labels: Sequence[int]) -> torch.Tensor:
    return torch.isin(result["labels"], torch.tensor(list(labels), dtype=result["labels"].dtype))


def trim_by_semantic(
    result: dict[str, torch.Tensor], labels: Sequence[int], semantic_labels: Sequence[int], above: float
) -> dict[str, torch.Tensor]:
    """``result`` (a detection result with ``semantic_probs`` (C, H, W), indexed by label) with the
    masks of ``labels`` (1-based) trimmed; the same object when nothing is to be trimmed."""
    masks = result["masks"]
    chosen = _chosen(result, labels)
    thin = _thin(result, chosen, semantic_labels, above)
    if thin is None:
        return result
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


def semantic_cores(
    result: dict[str, torch.Tensor], labels: Sequence[int], semantic_labels: Sequence[int], above: float
) -> dict[str, torch.Tensor]:
    """``result`` with ``core_masks`` (like its masks): for the detections of ``labels``, their
    masks less the pixels where the head's probability of a thin part is above ``above``; for the
    others, their masks. The same object when there is nothing to give a core."""
    chosen = _chosen(result, labels)
    thin = _thin(result, chosen, semantic_labels, above)
    if thin is None:
        return result
    cores = result["masks"].clone()
    rows = chosen.nonzero()[:, 0]
    cores[rows] = cores[rows] & ~thin
    return {**result, "core_masks": cores}


__all__ = ["SemanticTrim", "semantic_cores", "trim_by_semantic"]
