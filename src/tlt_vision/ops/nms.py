"""Greedy non-maximum suppression, single-class and per-class ("batched")."""

from __future__ import annotations

import numpy as np
import torch


def nms(
    boxes: torch.Tensor, scores: torch.Tensor, iou_threshold: float, max_keep: int | None = None
) -> torch.Tensor:
    """Indices of the boxes kept, highest score first (at most ``max_keep``).

    Walks the boxes from the highest score down; a box is dropped when its IoU with a box already
    kept is strictly greater than ``iou_threshold``. Ties in score keep the lower index first.
    """
    if boxes.numel() == 0:
        return torch.zeros(0, dtype=torch.long, device=boxes.device)
    order = torch.sort(scores, descending=True, stable=True).indices
    # The walk runs in numpy on the CPU, computing the overlaps of a box only once it is kept: the
    # full IoU matrix of an RPN's few thousand boxes would take most of the time, a torch op per step
    # costs microseconds, and on a GPU each step's branch would wait for the device.
    b = boxes[order].detach().to("cpu", torch.float32).numpy()
    x1, y1, x2, y2 = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    area = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)  # as ops.boxes.box_area
    n = len(b)
    suppressed = np.zeros(n, dtype=bool)
    keep: list[int] = []
    for i in range(n):
        if suppressed[i]:
            continue
        keep.append(i)
        if max_keep is not None and len(keep) >= max_keep:
            break
        w = np.clip(np.minimum(x2[i], x2[i + 1 :]) - np.maximum(x1[i], x1[i + 1 :]), 0, None)
        h = np.clip(np.minimum(y2[i], y2[i + 1 :]) - np.maximum(y1[i], y1[i + 1 :]), 0, None)
        inter = w * h
        union = area[i] + area[i + 1 :] - inter
        iou = np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)  # as ops.boxes.box_iou
        suppressed[i + 1 :] |= iou > iou_threshold
    return order[torch.tensor(keep, dtype=torch.long, device=order.device)]


def batched_nms(
    boxes: torch.Tensor,
    scores: torch.Tensor,
    labels: torch.Tensor,
    iou_threshold: float,
    max_keep: int | None = None,
) -> torch.Tensor:
    """NMS run independently per label: boxes of different labels never suppress each other."""
    if boxes.numel() == 0:
        return torch.zeros(0, dtype=torch.long, device=boxes.device)
    # Shift each label's boxes to a disjoint region so one NMS pass keeps the labels apart.
    offset = labels.to(boxes.dtype) * (boxes.max() - boxes.min() + 1.0)
    return nms(boxes + offset[:, None], scores, iou_threshold, max_keep)
