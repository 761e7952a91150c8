"""Matching of anchors or proposals to ground-truth boxes, and balanced sampling of the matches."""

from __future__ import annotations

import torch

from tlt_vision.ops.boxes import box_iou

BACKGROUND = -1
IGNORE = -2


def match(
    gt_boxes: torch.Tensor, boxes: torch.Tensor, fg_iou: float, bg_iou: float, allow_low_quality: bool
) -> torch.Tensor:
    """Index of the matched ground truth for each box, or BACKGROUND / IGNORE.

    A box whose best IoU is at least ``fg_iou`` matches that ground truth; below ``bg_iou`` it is
    background; in between it is ignored. With ``allow_low_quality`` every ground truth also keeps
    the boxes it overlaps best, so a small object is never left without a positive anchor.
    """
    if gt_boxes.numel() == 0:
        return torch.full((boxes.shape[0],), BACKGROUND, dtype=torch.long, device=boxes.device)
    iou = box_iou(gt_boxes, boxes)  # (G, N)
    best, idx = iou.max(dim=0)
    out = idx.clone()
    out[best < fg_iou] = IGNORE
    out[best < bg_iou] = BACKGROUND
    if allow_low_quality:
        best_per_gt = iou.max(dim=1).values
        _, n = torch.nonzero((iou == best_per_gt[:, None]) & (best_per_gt[:, None] > 0), as_tuple=True)
        out[n] = idx[n]
    return out


def sample(
    matches: torch.Tensor, batch: int, positive_fraction: float, generator: torch.Generator | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Indices of positives (``matches >= 0``) and negatives (BACKGROUND) drawn for one image."""
    pos = torch.nonzero(matches >= 0).flatten()
    neg = torch.nonzero(matches == BACKGROUND).flatten()
    n_pos = min(pos.numel(), int(batch * positive_fraction))
    n_neg = min(neg.numel(), batch - n_pos)
    # The draw is made on the CPU (a generator's device must match) and moved to the indices'.
    pos = pos[torch.randperm(pos.numel(), generator=generator)[:n_pos].to(pos.device)]
    neg = neg[torch.randperm(neg.numel(), generator=generator)[:n_neg].to(neg.device)]
    return pos, neg


__all__ = ["BACKGROUND", "IGNORE", "match", "sample"]
