"""Region proposal network: objectness and box deltas per anchor on every FPN level."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from tlt_vision.ops.anchors import grid_anchors
from tlt_vision.ops.boxes import BoxCoder, clip_boxes
from tlt_vision.ops.nms import batched_nms
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.matching import match, sample


class RPNHead(nn.Module):
    def __init__(self, channels: int, num_anchors: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(channels, channels, 3, padding=1)
        self.objectness = nn.Conv2d(channels, num_anchors, 1)
        self.deltas = nn.Conv2d(channels, 4 * num_anchors, 1)
        for layer in (self.objectness, self.deltas):
            nn.init.normal_(layer.weight, std=0.01)
            nn.init.zeros_(layer.bias)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, H*W*A) logits and (B, H*W*A, 4) deltas, ordered row, column, anchor."""
        h = F.relu(self.conv(x))
        b, _, hh, ww = x.shape
        logits = self.objectness(h).permute(0, 2, 3, 1).reshape(b, -1)
        deltas = self.deltas(h).view(b, -1, 4, hh, ww).permute(0, 3, 4, 1, 2).reshape(b, -1, 4)
        return logits, deltas


class RPN(nn.Module):
    """Proposals for each image, and the RPN losses when ground-truth boxes are given."""

    def __init__(self, cfg: MaskRCNNConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.head = RPNHead(cfg.fpn_channels, len(cfg.anchor_ratios))
        self.coder = BoxCoder()

    def anchors(self, feats: list[torch.Tensor]) -> list[torch.Tensor]:
        cfg = self.cfg
        return [
            grid_anchors(tuple(f.shape[-2:]), s, size, cfg.anchor_ratios).to(f.device)
            for f, s, size in zip(feats, cfg.strides, cfg.anchor_sizes, strict=True)
        ]

    def forward(
        self,
        feats: list[torch.Tensor],
        image_size: tuple[int, int],
        gt_boxes: list[torch.Tensor] | None = None,
    ) -> tuple[list[torch.Tensor], dict[str, torch.Tensor]]:
        cfg = self.cfg
        anchors = self.anchors(feats)
        outs = [self.head(f) for f in feats]
        logits = torch.cat([o[0] for o in outs], dim=1)
        deltas = torch.cat([o[1] for o in outs], dim=1)
        all_anchors = torch.cat(anchors)
        levels = torch.cat(
            [torch.full((len(a),), i, dtype=torch.long, device=a.device) for i, a in enumerate(anchors)]
        )
        post = cfg.rpn_post_nms_top_n_train if self.training else cfg.rpn_post_nms_top_n_test
        proposals = []
        with torch.no_grad():
            for b in range(logits.shape[0]):
                boxes = clip_boxes(self.coder.decode(deltas[b].detach(), all_anchors), *image_size)
                scores = logits[b].detach()
                keep_idx = []
                for lv in range(len(anchors)):
                    idx = torch.nonzero(levels == lv).flatten()
                    k = min(cfg.rpn_pre_nms_top_n, idx.numel())
                    keep_idx.append(idx[scores[idx].topk(k).indices])
                idx = torch.cat(keep_idx)
                bx, sc, lv = boxes[idx], scores[idx], levels[idx]
                wh = bx[:, 2:] - bx[:, :2]
                ok = (wh >= cfg.min_box_size).all(dim=1)
                bx, sc, lv = bx[ok], sc[ok], lv[ok]
                keep = batched_nms(bx, sc, lv, cfg.rpn_nms_threshold, max_keep=post)
                proposals.append(bx[keep])
        losses: dict[str, torch.Tensor] = {}
        if gt_boxes is not None:
            losses = self._losses(logits, deltas, all_anchors, gt_boxes)
        return proposals, losses

    def _losses(
        self, logits: torch.Tensor, deltas: torch.Tensor, anchors: torch.Tensor, gt_boxes: list[torch.Tensor]
    ) -> dict[str, torch.Tensor]:
        cfg = self.cfg
        obj_terms, box_terms, count = [], [], 0
        for b, gt in enumerate(gt_boxes):
            m = match(gt, anchors, cfg.rpn_fg_iou, cfg.rpn_bg_iou, allow_low_quality=True)
            pos, neg = sample(m, cfg.rpn_batch_per_image, cfg.rpn_positive_fraction)
            idx = torch.cat([pos, neg])
            target = torch.cat([logits.new_ones(len(pos)), logits.new_zeros(len(neg))])
            obj_terms.append(F.binary_cross_entropy_with_logits(logits[b, idx], target, reduction="sum"))
            if len(pos):
                reg = self.coder.encode(gt[m[pos]], anchors[pos])
                box_terms.append(F.smooth_l1_loss(deltas[b, pos], reg, beta=1 / 9, reduction="sum"))
            count += len(idx)
        n = max(count, 1)
        zero = logits.sum() * 0.0
        return {
            "rpn_objectness": sum(obj_terms, zero) / n,
            "rpn_box": sum(box_terms, zero) / n,
        }


__all__ = ["RPN", "RPNHead"]
