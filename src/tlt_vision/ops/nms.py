"""Greedy non-maximum suppression, single-class and per-class ("batched")."""

from __future__ import annotations

import torch

from tlt_vision.ops.boxes import box_iou


def nms(boxes: torch.Tensor, scores: torch.Tensor, iou_threshold: float) -> torch.Tensor:
    """Indices of the boxes kept, highest score first.

    Walks the boxes from the highest score down; a box is dropped when its IoU with a box already
    kept is strictly greater than ``iou_threshold``. Ties in score keep the lower index first.
    """
    if boxes.numel() == 0:
        return torch.zeros(0, dtype=torch.long, device=boxes.device)
    order = torch.sort(scores, descending=True, stable=True).indices
    iou = box_iou(boxes[order], boxes[order])
    n = order.numel()
    suppressed = torch.zeros(n, dtype=torch.bool)
    keep = []
    # The O(n^2) IoU matrix is computed once; the loop only reads it, so n of a few thousand is cheap.
    for i in range(n):
        if suppressed[i]:
            continue
        keep.append(i)
        suppressed |= iou[i] > iou_threshold
    return order[torch.tensor(keep, dtype=torch.long)]


def batched_nms(
    boxes: torch.Tensor, scores: torch.Tensor, labels: torch.Tensor, iou_threshold: float
) -> torch.Tensor:
    """NMS run independently per label: boxes of different labels never suppress each other."""
    if boxes.numel() == 0:
        return torch.zeros(0, dtype=torch.long, device=boxes.device)
    # Shift each label's boxes to a disjoint region so one NMS pass keeps the labels apart.
    offset = labels.to(boxes.dtype) * (boxes.max() - boxes.min() + 1.0)
    return nms(boxes + offset[:, None], scores, iou_threshold)


__all__ = ["batched_nms", "nms"]
