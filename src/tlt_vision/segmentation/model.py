"""Mask R-CNN: backbone + FPN, RPN, box and mask heads; training losses and detections.

``model(images, targets)`` in training mode returns the loss terms; in eval mode
``model(images)`` returns, per image, ``boxes`` (D, 4), ``labels`` (D,) (1-based class index,
``cfg.classes[label - 1]``), ``scores`` (D,) and ``masks`` (D, H, W) bool. Images are float
(B, 3, H, W) in [0, 1]; targets are dicts of ``boxes`` (G, 4) pixels, ``labels`` (G,) and
``masks`` (G, H, W) bool.

With ``cfg.semantic_classes`` a semantic head also classifies every pixel; in training its loss is
``semantic``, and in eval the instances of those classes are its connected regions
(:mod:`tlt_vision.segmentation.semantic`), not the box branch's detections of them, and each
image's result also carries the head's class probabilities, ``semantic_probs`` (C, H, W), by
which the vision node scores the pieces it cuts those regions into
(:mod:`tlt_vision.segmentation.depth_split`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import torch
from torch import nn

from tlt_vision.segmentation.backbone import FPN, Backbone
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.roi_heads import RoIHeads
from tlt_vision.segmentation.rpn import RPN
from tlt_vision.segmentation.semantic import (
    SemanticHead,
    instances_from_semantic,
    semantic_loss,
    upsample_logits,
)

# MaskRCNNConfig fields a user of trained weights may change (MaskRCNN.set_inference).
INFERENCE_SETTINGS = (
    "rpn_post_nms_top_n_test",
    "score_threshold",
    "detection_nms",
    "detections_per_image",
    "semantic_background_weight",
    "semantic_vote",
)


class MaskRCNN(nn.Module):
    def __init__(self, cfg: MaskRCNNConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or MaskRCNNConfig()
        self.backbone = Backbone(self.cfg.backbone_channels)
        self.fpn = FPN(self.cfg.backbone_channels, self.cfg.fpn_channels)
        self.rpn = RPN(self.cfg)
        self.roi_heads = RoIHeads(self.cfg)
        self.semantic = SemanticHead(self.cfg) if self.cfg.semantic_classes else None
        self.register_buffer("pixel_mean", torch.tensor(self.cfg.pixel_mean).view(1, 3, 1, 1))
        self.register_buffer("pixel_std", torch.tensor(self.cfg.pixel_std).view(1, 3, 1, 1))

    def set_inference(self, **settings: Any) -> None:
        """Change settings that act at inference only (:data:`INFERENCE_SETTINGS`: how many
        proposals are scored, how the semantic head's map is read), never what the weights learned;
        ValueError naming any other."""
        other = sorted(set(settings) - set(INFERENCE_SETTINGS))
        if other:
            raise ValueError(
                f"not inference settings: {', '.join(other)} (these are: {', '.join(INFERENCE_SETTINGS)})"
            )
        cfg = replace(self.cfg, **settings)
        for module in (self, self.rpn, self.roi_heads):
            module.cfg = cfg

    def inference_settings(self) -> dict[str, Any]:
        """The inference settings in force (:data:`INFERENCE_SETTINGS`), to set back later."""
        return {key: getattr(self.cfg, key) for key in INFERENCE_SETTINGS}

    def features(self, images: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        """The stem's stride-2 features and the FPN levels [P2..P5]."""
        stem, feats = self.backbone.pyramid((images - self.pixel_mean) / self.pixel_std)
        return stem, self.fpn(feats)

    def forward(
        self, images: torch.Tensor, targets: list[dict[str, torch.Tensor]] | None = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        if images.dim() != 4 or images.shape[1] != 3:
            raise ValueError(f"expected images (B, 3, H, W), got {tuple(images.shape)}")
        size = (int(images.shape[-2]), int(images.shape[-1]))
        stem, feats = self.features(images)
        logits = self.semantic(stem, feats[0]) if self.semantic is not None else None
        if self.training:
            if targets is None or len(targets) != images.shape[0]:
                raise ValueError("training needs one target dict per image")
            proposals, losses = self.rpn(feats, size, [t["boxes"] for t in targets])
            losses.update(self.roi_heads.losses(feats, proposals, targets))
            if logits is not None:
                losses["semantic"] = semantic_loss(
                    logits, targets, self.cfg.semantic_fg_weight, self.cfg.semantic_gap
                )
            return losses
        proposals, _ = self.rpn(feats, size)
        results = self.roi_heads.detect(feats, proposals, size, skip_labels=self.cfg.semantic_labels)
        if logits is None:
            return results
        probs = torch.softmax(upsample_logits(logits, size), dim=1)
        for r, p in zip(results, probs, strict=True):
            found = instances_from_semantic(
                p,
                self.cfg.semantic_labels,
                self.cfg.semantic_min_area,
                self.cfg.semantic_background_weight,
                self.cfg.semantic_vote,
            )
            # ``mask_probs`` stay the box branch's alone, whose detections come first: a region's
            # probability is its mask, and a frame's regions as full-size floats would cost time.
            for key in r:
                if key != "mask_probs":
                    r[key] = torch.cat([r[key], found[key].to(r[key].dtype)])
            r["semantic_probs"] = p
        return results


def train_step(
    model: MaskRCNN,
    optimizer: torch.optim.Optimizer,
    images: torch.Tensor,
    targets: list[dict[str, torch.Tensor]],
    before_step: Callable[[], None] | None = None,
) -> dict[str, float]:
    """One optimisation step on a batch; returns each loss term and their ``total``.
    ``before_step`` runs between the backward pass and the step (data-parallel training averages
    the gradients there)."""
    model.train()
    losses = model(images, targets)
    total = sum(losses.values())
    optimizer.zero_grad()
    total.backward()
    if before_step is not None:
        before_step()
    optimizer.step()
    out = {k: float(v.detach()) for k, v in losses.items()}
    out["total"] = float(total.detach())
    return out


@torch.no_grad()
def predict(model: MaskRCNN, images: torch.Tensor) -> list[dict[str, torch.Tensor]]:
    """Detections for a batch of images (eval mode)."""
    model.eval()
    return model(images)


__all__ = ["INFERENCE_SETTINGS", "MaskRCNN", "predict", "train_step"]
