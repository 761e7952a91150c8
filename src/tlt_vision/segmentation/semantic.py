"""Per-pixel classes for the thin parts, and their instances as connected regions.

A strut tube or a cross-frame side lying across the view is a line a few pixels wide: the anchors
of the region proposal network barely overlap its box, and a 28x28 mask stretched over that box
cannot draw it (models/vision/history.md). A per-pixel class map at
stride 2 draws such a line directly. Its regions of one class, split where they do not touch, are
that class's instances: tubes of one strut are separated by their end fittings, frame sides by
their corner joints, racked tubes that touch in the image by the gap the head is taught to leave
between them (:func:`label_map`).

``SemanticHead`` joins the FPN's finest level (P2, stride 4: what the pixel is) with the stem's
stride-2 features (where its edges are). ``semantic_loss`` is a weighted cross-entropy at the
input's size; ``instances_from_semantic`` turns the class probabilities of one image into
detections in the format of the box branch.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tlt_vision.segmentation.config import MaskRCNNConfig


class SemanticHead(nn.Module):
    """(stem (B, C1, H/2, W/2), P2 (B, F, H/4, W/4)) -> class logits (B, classes, H/2, W/2).

    What a pixel is comes from P2, in two convolutions at stride 4; where its edges are, from the
    stem, in one narrower convolution at stride 2 (at full size a stride-2 map is 320x240, and
    convolutions there cost four times those at stride 4: the CPU's frame time decides)."""

    def __init__(self, cfg: MaskRCNNConfig) -> None:
        super().__init__()
        c, fine = cfg.semantic_channels, max(cfg.semantic_channels // 2, 1)
        self.context = nn.Sequential(
            nn.Conv2d(cfg.fpn_channels, c, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(c, c, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(c, fine, 1),
        )
        self.from_stem = nn.Conv2d(cfg.backbone_channels[0], fine, 1)
        self.refine = nn.Sequential(nn.Conv2d(fine, fine, 3, padding=1), nn.ReLU())
        self.logits = nn.Conv2d(fine, cfg.num_classes, 1)

    def forward(self, stem: torch.Tensor, p2: torch.Tensor) -> torch.Tensor:
        x = F.interpolate(self.context(p2), size=stem.shape[-2:], mode="bilinear", align_corners=False)
        return self.logits(self.refine(x + self.from_stem(stem)))


def upsample_logits(logits: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Stride-2 logits at the input's ``size`` (bilinear)."""
    return F.interpolate(logits, size=size, mode="bilinear", align_corners=False)


def label_map(target: dict[str, torch.Tensor], size: tuple[int, int], gap: int = 0) -> torch.Tensor:
    """(H, W) long: each pixel's instance label, 0 where no instance is (instances' visible masks do
    not overlap; where they would, the later one wins). With ``gap``, an instance's pixels within
    ``gap`` pixels (a square window) of another instance of its class are background: two racked
    tubes touching in the image are then two regions of the map the head learns to draw, where
    they would be one (the twin's own map, cut so, gives better tube regions than uncut;
    models/vision/history.md)."""
    device = target["labels"].device
    labels = torch.zeros(size, dtype=torch.long, device=device)
    ids = torch.zeros(size, dtype=torch.long, device=device)
    for k, (mask, label) in enumerate(zip(target["masks"], target["labels"], strict=True)):
        labels[mask] = label
        ids[mask] = k + 1
    if gap <= 0:
        return labels
    window = 2 * gap + 1
    none = float(len(target["labels"]) + 1)
    cut = torch.zeros(size, dtype=torch.bool, device=device)
    for label in torch.unique(labels[labels > 0]).tolist():
        own = labels == label
        mine = torch.where(own, ids, 0).to(torch.float32)[None, None]
        # Another instance of the class in the window has a larger id than the pixel's, or a smaller.
        larger = F.max_pool2d(mine, window, stride=1, padding=gap)[0, 0]
        smaller = -F.max_pool2d(-torch.where(mine > 0, mine, none), window, stride=1, padding=gap)[0, 0]
        cut |= own & ((larger != mine[0, 0]) | (smaller != mine[0, 0]))
    labels[cut] = 0
    return labels


def semantic_loss(
    logits: torch.Tensor, targets: Sequence[dict[str, torch.Tensor]], fg_weight: float, gap: int = 0
) -> torch.Tensor:
    """Cross-entropy of stride-2 ``logits`` (B, classes, h, w) against every image's label map at
    the input's size, object pixels weighted ``fg_weight`` against background (a strut is a
    sliver of a frame; unweighted, a map of background alone is already a low loss), instances
    kept ``gap`` pixels apart (:func:`label_map`)."""
    size = tuple(targets[0]["masks"].shape[-2:]) if len(targets) else None
    if size is None or len(size) != 2:
        raise ValueError("semantic loss needs every target's masks (G, H, W)")
    labels = torch.stack([label_map(t, size, gap) for t in targets])  # type: ignore[arg-type]
    weight = torch.full((logits.shape[1],), float(fg_weight), device=logits.device, dtype=logits.dtype)
    weight[0] = 1.0
    return F.cross_entropy(upsample_logits(logits, size), labels, weight=weight)  # type: ignore[arg-type]


# Over this class probability the head is sure of a pixel (the part likelier than all else).
SURE = 0.5


def pixel_classes(probs: torch.Tensor, background_weight: float = 1.0) -> torch.Tensor:
    """(H, W) long: each pixel's class in the probabilities ``probs`` (C, H, W), class 0 the
    background, whose probability counts ``background_weight`` times (1: the most probable)."""
    # max, not argmax: torch's argmax over the leading dim of a (C, H, W) map is an order of
    # magnitude slower on the CPU than max's indices.
    if background_weight == 1.0:
        return probs.max(dim=0).indices
    best = probs[1:].max(dim=0)
    return torch.where(best.values > background_weight * probs[0], best.indices + 1, 0)


def instances_from_semantic(
    probs: torch.Tensor,
    labels: Sequence[int],
    min_area: int,
    background_weight: float = 1.0,
    vote: bool = False,
) -> dict[str, torch.Tensor]:
    """Detections of the classes ``labels`` in one image's class probabilities ``probs`` (C, H, W):
    each 8-connected region of pixels of the label (:func:`pixel_classes`, the background's
    probability weighted ``background_weight``), of at least ``min_area`` pixels and holding a
    pixel the head is sure of (over :data:`SURE`), is one instance. ``boxes`` (D, 4) are its
    pixel-edge bounds, ``scores`` the mean probability of its class over it, ``masks`` (D, H, W)
    bool. With the background weighted down, the pixels the head doubts join its sure ones into
    whole parts, and on their own make streaks of doubt on no part, which the last rule drops.

    With ``vote``, a region is one of pixels of any of ``labels`` (a thin part, of whatever
    class), of the label with the most probability summed over it, and its sure pixel one whose
    probabilities of ``labels`` together are over :data:`SURE`: the head's class wavers pixel by
    pixel along a part where tubes and frame sides look alike (a racked tube 0.41 tube and 0.41
    frame side on average), which without the vote breaks it into pieces of both classes."""
    h, w = probs.shape[-2:]
    best = pixel_classes(probs, background_weight).cpu().numpy()
    found: list[tuple[np.ndarray, int]] = []  # (regions, region number) of each instance
    out_labels: list[int] = []
    scores: list[float] = []
    boxes: list[tuple[int, int, int, int]] = []
    for group in [list(labels)] if vote else [[label] for label in labels]:
        count, regions, stats, _ = cv2.connectedComponentsWithStats(
            np.isin(best, group).astype(np.uint8), connectivity=8
        )
        if count <= 1:
            continue
        # The sums over the group's own pixels only: a tenth of the frame or less.
        inside = regions.ravel() > 0
        at = regions.ravel()[inside]
        p = probs[group].detach().cpu().numpy().reshape(len(group), -1)[:, inside]
        mass = np.stack([np.bincount(at, weights=q, minlength=count) for q in p])
        sure = np.bincount(at, weights=p.sum(axis=0) > SURE, minlength=count)
        area = stats[:, cv2.CC_STAT_AREA]
        for k in range(1, count):
            if area[k] >= min_area and sure[k] > 0:
                x, y = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
                boxes.append((x, y, x + stats[k, cv2.CC_STAT_WIDTH], y + stats[k, cv2.CC_STAT_HEIGHT]))
                found.append((regions, k))
                chosen = int(mass[:, k].argmax())
                out_labels.append(group[chosen])
                scores.append(float(mass[chosen, k] / area[k]))
    device = probs.device
    masks = np.zeros((len(found), h, w), dtype=bool)
    for i, ((regions, k), (x0, y0, x1, y1)) in enumerate(zip(found, boxes, strict=True)):
        masks[i, y0:y1, x0:x1] = regions[y0:y1, x0:x1] == k  # a region lies within its box
    return {
        "boxes": torch.tensor(boxes, dtype=torch.float32, device=device).reshape(-1, 4),
        "labels": torch.tensor(out_labels, dtype=torch.long, device=device),
        "scores": torch.tensor(scores, dtype=torch.float32, device=device),
        "masks": torch.from_numpy(masks).to(device),
    }


__all__ = [
    "SURE",
    "SemanticHead",
    "instances_from_semantic",
    "label_map",
    "pixel_classes",
    "semantic_loss",
    "upsample_logits",
]
