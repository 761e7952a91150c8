"""Mask average precision at IoU 0.5 (mask AP50), per class and mean over classes.

For each class, detections of all images are ranked by score; a detection is a true positive when
its mask IoU with a not-yet-matched ground-truth mask of the same class and image is at least 0.5
(greedy, best IoU first), otherwise a false positive. AP is the area under the precision-recall
curve with precision made monotone (the all-points interpolation of PASCAL VOC 2010 onward). The
mean is over classes that have ground truth; a class with detections but no ground truth is not
counted (nothing to recall).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch


def mask_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """IoU (N, M) between boolean masks a (N, H, W) and b (M, H, W)."""
    af = a.flatten(1).to(torch.float32)
    bf = b.flatten(1).to(torch.float32)
    inter = af @ bf.T
    union = af.sum(1)[:, None] + bf.sum(1)[None, :] - inter
    return torch.where(union > 0, inter / union.clamp(min=1.0), torch.zeros_like(union))


def average_precision(tp: Sequence[bool], scores: Sequence[float], num_gt: int) -> float:
    """All-points interpolated AP of ranked detections (``tp`` flags) against ``num_gt`` objects."""
    if num_gt == 0:
        raise ValueError("AP is undefined without ground truth")
    order = sorted(range(len(tp)), key=lambda i: -scores[i])
    flags = torch.tensor([bool(tp[i]) for i in order], dtype=torch.float64)
    if flags.numel() == 0:
        return 0.0
    ctp = torch.cumsum(flags, 0)
    cfp = torch.cumsum(1 - flags, 0)
    recall = ctp / num_gt
    precision = ctp / (ctp + cfp)
    r = torch.cat([torch.tensor([0.0], dtype=torch.float64), recall])
    p = torch.cat([precision, torch.tensor([0.0], dtype=torch.float64)])
    p = torch.flip(torch.cummax(torch.flip(p, [0]), 0).values, [0])  # monotone envelope
    return float(((r[1:] - r[:-1]) * p[:-1]).sum())


def match_image(
    pred: dict[str, torch.Tensor], gt: dict[str, torch.Tensor], label: int, iou_threshold: float = 0.5
) -> tuple[list[bool], list[float], int]:
    """One image's detections of class ``label``: (true-positive flag, score) per detection, and
    the number of ground-truth objects of that class. Greedy in score order, each detection taking
    the unmatched ground truth it overlaps most. Kept per image so that a long evaluation need not
    hold every image's full-size masks at once."""
    g = gt["masks"][gt["labels"] == label]
    sel = pred["labels"] == label
    pm, ps = pred["masks"][sel], pred["scores"][sel]
    order = torch.argsort(ps, descending=True)
    used = torch.zeros(len(g), dtype=torch.bool)
    iou = mask_iou(pm[order], g) if len(g) and len(order) else None
    tp: list[bool] = []
    scores: list[float] = []
    for rank, i in enumerate(order.tolist()):
        hit = False
        if iou is not None:
            cand = iou[rank].clone()
            cand[used] = -1.0
            best = int(cand.argmax())
            if cand[best] >= iou_threshold:
                used[best] = True
                hit = True
        tp.append(hit)
        scores.append(float(ps[i]))
    return tp, scores, len(g)


class MaskAP:
    """Mask AP accumulated image by image: ``add(pred, gt)`` for each, then ``result()``."""

    def __init__(self, num_classes: int, iou_threshold: float = 0.5) -> None:
        self.num_classes = num_classes
        self.iou_threshold = iou_threshold
        self.tp: dict[int, list[bool]] = {c: [] for c in range(1, num_classes + 1)}
        self.scores: dict[int, list[float]] = {c: [] for c in range(1, num_classes + 1)}
        self.num_gt = dict.fromkeys(range(1, num_classes + 1), 0)

    def add(self, pred: dict[str, torch.Tensor], gt: dict[str, torch.Tensor]) -> None:
        for label in range(1, self.num_classes + 1):
            tp, scores, n = match_image(pred, gt, label, self.iou_threshold)
            self.tp[label] += tp
            self.scores[label] += scores
            self.num_gt[label] += n

    def result(self) -> dict[str, float | dict[int, float]]:
        """``{"map": mean AP, "per_class": {label: AP}}`` over the classes with ground truth."""
        per_class = {c: average_precision(self.tp[c], self.scores[c], n) for c, n in self.num_gt.items() if n}
        mean = sum(per_class.values()) / len(per_class) if per_class else 0.0
        return {"map": mean, "per_class": per_class}


def mask_ap50(
    predictions: Sequence[dict[str, torch.Tensor]],
    ground_truth: Sequence[dict[str, torch.Tensor]],
    num_classes: int,
    iou_threshold: float = 0.5,
) -> dict[str, float | dict[int, float]]:
    """``{"map": mean AP, "per_class": {label: AP}}`` over labels ``1..num_classes``."""
    if len(predictions) != len(ground_truth):
        raise ValueError("one prediction per ground-truth image is needed")
    acc = MaskAP(num_classes, iou_threshold)
    for pred, gt in zip(predictions, ground_truth, strict=True):
        acc.add(pred, gt)
    return acc.result()


__all__ = ["MaskAP", "average_precision", "mask_ap50", "mask_iou", "match_image"]
