"""Axis-aligned boxes: area, pairwise IoU, clipping, and the Faster R-CNN delta coding.

Boxes are ``(x1, y1, x2, y2)`` with ``x2 >= x1`` and ``y2 >= y1``; widths are ``x2 - x1`` (no
"+1" pixel convention), so a box's area is its continuous area in pixel units.
"""

from __future__ import annotations

import math

import torch

# Largest log-scale delta accepted on decode: exp(4.135) ~ 62.5, i.e. a box may grow at most
# 1000/16 times its anchor, which keeps an untrained head from producing inf boxes.
DEFAULT_SCALE_CLAMP = math.log(1000.0 / 16)


def box_area(boxes: torch.Tensor) -> torch.Tensor:
    """Area of each box, ``(N,)``; degenerate boxes (x2 < x1) count as zero."""
    return (boxes[:, 2] - boxes[:, 0]).clamp(min=0) * (boxes[:, 3] - boxes[:, 1]).clamp(min=0)


def box_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Pairwise intersection over union, ``(N, M)``; 0 where the union is empty."""
    area_a, area_b = box_area(a), box_area(b)
    lt = torch.maximum(a[:, None, :2], b[None, :, :2])
    rb = torch.minimum(a[:, None, 2:], b[None, :, 2:])
    wh = (rb - lt).clamp(min=0)
    inter = wh[..., 0] * wh[..., 1]
    union = area_a[:, None] + area_b[None, :] - inter
    return torch.where(union > 0, inter / union.clamp(min=1e-12), torch.zeros_like(union))


def clip_boxes(boxes: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Boxes clipped to the image ``[0, width] x [0, height]``."""
    x = boxes[:, 0::2].clamp(0, width)
    y = boxes[:, 1::2].clamp(0, height)
    return torch.stack([x[:, 0], y[:, 0], x[:, 1], y[:, 1]], dim=1)


class BoxCoder:
    """Encodes a target box relative to a reference box as ``(dx, dy, dw, dh)`` and back.

    ``dx = wx * (cx_t - cx_r) / w_r``, ``dw = ww * log(w_t / w_r)`` (same for y, h), the
    parametrisation of Faster R-CNN; ``weights`` scale the deltas so that their spread suits the
    regression loss. ``decode(encode(t, r), r) == t`` for boxes of positive size.
    """

    def __init__(
        self,
        weights: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0),
        scale_clamp: float = DEFAULT_SCALE_CLAMP,
    ) -> None:
        self.weights = weights
        self.scale_clamp = scale_clamp

    def encode(self, targets: torch.Tensor, references: torch.Tensor) -> torch.Tensor:
        """Deltas ``(N, 4)`` that move each reference box onto its target box."""
        wx, wy, ww, wh = self.weights
        rw = references[:, 2] - references[:, 0]
        rh = references[:, 3] - references[:, 1]
        rcx = references[:, 0] + 0.5 * rw
        rcy = references[:, 1] + 0.5 * rh
        tw = targets[:, 2] - targets[:, 0]
        th = targets[:, 3] - targets[:, 1]
        tcx = targets[:, 0] + 0.5 * tw
        tcy = targets[:, 1] + 0.5 * th
        return torch.stack(
            [
                wx * (tcx - rcx) / rw,
                wy * (tcy - rcy) / rh,
                ww * torch.log(tw / rw),
                wh * torch.log(th / rh),
            ],
            dim=1,
        )

    def decode(self, deltas: torch.Tensor, references: torch.Tensor) -> torch.Tensor:
        """Boxes ``(N, 4)`` given by applying ``deltas`` to ``references``."""
        wx, wy, ww, wh = self.weights
        rw = references[:, 2] - references[:, 0]
        rh = references[:, 3] - references[:, 1]
        rcx = references[:, 0] + 0.5 * rw
        rcy = references[:, 1] + 0.5 * rh
        dx, dy = deltas[:, 0] / wx, deltas[:, 1] / wy
        dw = (deltas[:, 2] / ww).clamp(max=self.scale_clamp)
        dh = (deltas[:, 3] / wh).clamp(max=self.scale_clamp)
        cx, cy = dx * rw + rcx, dy * rh + rcy
        w, h = torch.exp(dw) * rw, torch.exp(dh) * rh
        return torch.stack([cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h], dim=1)


def boxes_from_masks(masks: torch.Tensor) -> torch.Tensor:
    """Tight (x1, y1, x2, y2) pixel-edge boxes (N, 4) of non-empty masks (N, H, W)."""
    if masks.shape[0] == 0:
        return torch.zeros((0, 4), device=masks.device)
    # amax of the bytes: torch's any over one axis of a (N, H, W) bool is many times slower on the CPU.
    as_bytes = masks.to(torch.bool).view(torch.uint8)
    rows, cols = as_bytes.amax(dim=2) > 0, as_bytes.amax(dim=1) > 0
    h, w = masks.shape[-2:]
    ar_h = torch.arange(h, device=masks.device)
    ar_w = torch.arange(w, device=masks.device)
    y1 = torch.where(rows, ar_h, h).min(dim=1).values
    y2 = torch.where(rows, ar_h, -1).max(dim=1).values + 1
    x1 = torch.where(cols, ar_w, w).min(dim=1).values
    x2 = torch.where(cols, ar_w, -1).max(dim=1).values + 1
    return torch.stack([x1, y1, x2, y2], dim=1).to(torch.float32)


__all__ = ["DEFAULT_SCALE_CLAMP", "BoxCoder", "box_area", "box_iou", "boxes_from_masks", "clip_boxes"]
