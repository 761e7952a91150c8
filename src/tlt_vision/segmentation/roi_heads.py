"""Box and mask heads of Mask R-CNN on RoIAlign features from the FPN level suiting each box."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from tlt_vision.ops.boxes import BoxCoder, clip_boxes
from tlt_vision.ops.nms import batched_nms
from tlt_vision.ops.roi_align import roi_align
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.matching import BACKGROUND, match, sample

# FPN level assignment (Lin et al.): a box of sqrt(area) = CANONICAL_SIZE pools from level
# CANONICAL_LEVEL, each halving of its size one level finer. Levels are indices 0..3 = P2..P5.
CANONICAL_SIZE = 112.0
CANONICAL_LEVEL = 2


def assign_levels(boxes: torch.Tensor, num_levels: int) -> torch.Tensor:
    """FPN level index (0 = finest) for each box."""
    size = torch.sqrt(((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])).clamp(min=1e-6))
    lv = torch.floor(CANONICAL_LEVEL + torch.log2(size / CANONICAL_SIZE) + 1e-6)
    return lv.clamp(0, num_levels - 1).long()


def multilevel_roi_align(
    feats: list[torch.Tensor], boxes: list[torch.Tensor], strides: tuple[int, ...], size: int
) -> torch.Tensor:
    """RoIAlign of every image's boxes, each from its own level; (R, C, size, size) in box order."""
    rois = torch.cat([torch.cat([b.new_full((len(b), 1), float(i)), b], dim=1) for i, b in enumerate(boxes)])
    out = feats[0].new_zeros((rois.shape[0], feats[0].shape[1], size, size))
    if rois.shape[0] == 0:
        return out
    levels = assign_levels(rois[:, 1:], len(feats))
    for lv, (f, s) in enumerate(zip(feats, strides, strict=False)):
        idx = torch.nonzero(levels == lv).flatten()
        if idx.numel():
            out[idx] = roi_align(f, rois[idx], (size, size), 1.0 / s, 2, aligned=True)
    return out


class BoxHead(nn.Module):
    def __init__(self, cfg: MaskRCNNConfig) -> None:
        super().__init__()
        c, p, r = cfg.fpn_channels, cfg.box_pool, cfg.representation
        self.fc = nn.Sequential(nn.Flatten(), nn.Linear(c * p * p, r), nn.ReLU(), nn.Linear(r, r), nn.ReLU())
        self.cls = nn.Linear(r, cfg.num_classes)
        self.box = nn.Linear(r, cfg.num_classes * 4)
        nn.init.normal_(self.cls.weight, std=0.01)
        nn.init.normal_(self.box.weight, std=0.001)
        nn.init.zeros_(self.cls.bias)
        nn.init.zeros_(self.box.bias)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.fc(x)
        return self.cls(h), self.box(h).view(x.shape[0], -1, 4)


class MaskHead(nn.Module):
    """(R, C, 14, 14) RoI features -> (R, classes, 28, 28) mask logits."""

    def __init__(self, cfg: MaskRCNNConfig) -> None:
        super().__init__()
        c = cfg.fpn_channels
        layers: list[nn.Module] = []
        for _ in range(cfg.mask_convs):
            layers += [nn.Conv2d(c, c, 3, padding=1), nn.ReLU()]
        self.convs = nn.Sequential(*layers)
        self.up = nn.ConvTranspose2d(c, c, 2, stride=2)
        self.logits = nn.Conv2d(c, cfg.num_classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.logits(F.relu(self.up(self.convs(x))))


def paste_masks(probs: torch.Tensor, boxes: torch.Tensor, image_size: tuple[int, int]) -> torch.Tensor:
    """Mask probabilities (D, M, M) in their boxes -> (D, H, W) over the whole image.

    Each mask is sampled (bilinear, zero outside the mask) over its box and a margin of one mask
    cell and a pixel, beyond which every sample is zero: sampling a frame's thirty masks over
    the whole image would take a tenth of its segmentation time."""
    h, w = image_size
    out = probs.new_zeros((probs.shape[0], h, w))
    cells = probs.shape[-1]
    for i, (x0, y0, x1, y1) in enumerate(boxes.tolist()):
        bw, bh = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)
        c0, c1 = max(math.floor(x0 - bw / cells - 1), 0), min(math.ceil(x1 + bw / cells + 1), w)
        r0, r1 = max(math.floor(y0 - bh / cells - 1), 0), min(math.ceil(y1 + bh / cells + 1), h)
        if c1 <= c0 or r1 <= r0:
            continue
        xs = torch.arange(c0, c1, dtype=probs.dtype, device=probs.device) + 0.5
        ys = torch.arange(r0, r1, dtype=probs.dtype, device=probs.device) + 0.5
        gx = (xs - x0) / bw * 2 - 1
        gy = (ys - y0) / bh * 2 - 1
        grid = torch.stack([gx[None, :].expand(r1 - r0, -1), gy[:, None].expand(-1, c1 - c0)], dim=-1)
        out[i, r0:r1, c0:c1] = F.grid_sample(
            probs[i, None, None], grid[None], align_corners=False, padding_mode="zeros"
        )[0, 0]
    return out


class RoIHeads(nn.Module):
    """Classification, class-specific box refinement and masks for the proposals."""

    def __init__(self, cfg: MaskRCNNConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.box_head = BoxHead(cfg)
        self.mask_head = MaskHead(cfg)
        self.coder = BoxCoder(cfg.box_weights)

    def losses(
        self,
        feats: list[torch.Tensor],
        proposals: list[torch.Tensor],
        targets: list[dict[str, torch.Tensor]],
    ) -> dict[str, torch.Tensor]:
        cfg = self.cfg
        boxes, labels, reg_targets, matched_gt = [], [], [], []
        for props, tgt in zip(proposals, targets, strict=True):
            # The ground truth joins the proposals so each object has well-placed training boxes.
            props = torch.cat([props, tgt["boxes"]])
            m = match(tgt["boxes"], props, cfg.roi_fg_iou, cfg.roi_fg_iou, allow_low_quality=False)
            pos, neg = sample(m, cfg.roi_batch_per_image, cfg.roi_positive_fraction)
            idx = torch.cat([pos, neg])
            lab = idx.new_zeros(len(idx))
            lab[: len(pos)] = tgt["labels"][m[pos]]
            gt_idx = idx.new_full((len(idx),), BACKGROUND)
            gt_idx[: len(pos)] = m[pos]
            reg = props.new_zeros((len(idx), 4))
            if len(pos):
                reg[: len(pos)] = self.coder.encode(tgt["boxes"][m[pos]], props[pos])
            boxes.append(props[idx])
            labels.append(lab)
            reg_targets.append(reg)
            matched_gt.append(gt_idx)
        x = multilevel_roi_align(feats, boxes, cfg.strides, cfg.box_pool)
        cls_logits, deltas = self.box_head(x)
        lab = torch.cat(labels)
        reg = torch.cat(reg_targets)
        fg = torch.nonzero(lab > 0).flatten()
        loss_cls = F.cross_entropy(cls_logits, lab)
        loss_box = F.smooth_l1_loss(deltas[fg, lab[fg]], reg[fg], beta=1.0, reduction="sum") / max(
            lab.numel(), 1
        )
        # Masks: positive boxes only, target = the ground-truth mask resampled into each box.
        mask_boxes, mask_labels, mask_targets = [], [], []
        for b_boxes, b_lab, b_gt, tgt in zip(boxes, labels, matched_gt, targets, strict=True):
            pos = torch.nonzero(b_lab > 0).flatten()
            mask_boxes.append(b_boxes[pos])
            mask_labels.append(b_lab[pos])
            if len(pos):
                gt_masks = tgt["masks"][b_gt[pos]].to(torch.float32)[:, None]  # (P, 1, H, W)
                rois = torch.cat(
                    [
                        torch.arange(len(pos), dtype=b_boxes.dtype, device=b_boxes.device)[:, None],
                        b_boxes[pos],
                    ],
                    dim=1,
                )
                m = cfg.mask_pool * 2
                mask_targets.append(roi_align(gt_masks, rois, (m, m), 1.0, 2, aligned=True)[:, 0] >= 0.5)
        mlab = torch.cat(mask_labels)
        if mlab.numel():
            mx = multilevel_roi_align(feats, mask_boxes, cfg.strides, cfg.mask_pool)
            logits = self.mask_head(mx)[torch.arange(mlab.numel(), device=mlab.device), mlab]
            loss_mask = F.binary_cross_entropy_with_logits(logits, torch.cat(mask_targets).to(logits.dtype))
        else:
            loss_mask = cls_logits.sum() * 0.0
        return {"roi_cls": loss_cls, "roi_box": loss_box, "roi_mask": loss_mask}

    @torch.no_grad()
    def detect(
        self,
        feats: list[torch.Tensor],
        proposals: list[torch.Tensor],
        image_size: tuple[int, int],
        skip_labels: tuple[int, ...] = (),
    ) -> list[dict[str, torch.Tensor]]:
        """Detections per image; none of the classes ``skip_labels`` (found another way)."""
        cfg = self.cfg
        x = multilevel_roi_align(feats, proposals, cfg.strides, cfg.box_pool)
        cls_logits, deltas = self.box_head(x)
        probs = F.softmax(cls_logits, dim=1)
        results = []
        start = 0
        nc = cfg.num_classes
        for props in proposals:
            n = len(props)
            p = probs[start : start + n, 1:]  # (n, C - 1)
            d = deltas[start : start + n, 1:]  # (n, C - 1, 4)
            start += n
            ref = props[:, None, :].expand(-1, nc - 1, -1).reshape(-1, 4)
            boxes = clip_boxes(self.coder.decode(d.reshape(-1, 4), ref), *image_size)
            scores = p.reshape(-1)
            labels = torch.arange(1, nc, device=props.device).repeat(n)
            keep = scores > cfg.score_threshold
            wh = boxes[:, 2:] - boxes[:, :2]
            keep &= (wh >= cfg.min_box_size).all(dim=1)
            for label in skip_labels:
                keep &= labels != label
            boxes, scores, labels = boxes[keep], scores[keep], labels[keep]
            k = batched_nms(boxes, scores, labels, cfg.detection_nms, max_keep=cfg.detections_per_image)
            results.append({"boxes": boxes[k], "scores": scores[k], "labels": labels[k]})
        mx = multilevel_roi_align(feats, [r["boxes"] for r in results], cfg.strides, cfg.mask_pool)
        side = cfg.mask_pool * 2
        mask_logits = self.mask_head(mx) if mx.shape[0] else mx.new_zeros((0, nc, side, side))
        start = 0
        for r in results:
            n = len(r["boxes"])
            lg = mask_logits[start : start + n]
            start += n
            rows = torch.arange(n, device=lg.device)
            small = torch.sigmoid(lg[rows, r["labels"]]) if n else lg.new_zeros((0, side, side))
            r["mask_probs"] = paste_masks(small, r["boxes"], image_size)
            r["masks"] = r["mask_probs"] >= 0.5
        return results


__all__ = ["CANONICAL_SIZE", "BoxHead", "MaskHead", "RoIHeads", "assign_levels", "paste_masks"]
