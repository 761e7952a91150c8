"""Trained Mask R-CNN weights -> a model, and one RGB image -> detections at the image's own size.

The trainer may work on downscaled images (``max_size``: the longest side in pixels, for CPU
speed); the weights' manifest records it under ``settings["max_size"]`` together with the model's
configuration (``settings["model"]``), and :func:`detect_rgb` applies the same downscale before the
model and brings the boxes and masks back to the full image. The trainer's evaluation and the
vision node (``segmentation_source.MaskRcnnSegmenter``) both go through here, so an image is
prepared the same way in training, evaluation and on the robot.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from tlt_vision.segmentation.config import CLASSES, MaskRCNNConfig
from tlt_vision.segmentation.model import MaskRCNN
from tlt_vision.weights import WeightsError, load_weights, read_manifest

KIND = "mask_rcnn"


def scaled_size(height: int, width: int, max_size: int | None) -> tuple[int, int]:
    """(h, w) with the longest side at most ``max_size`` (aspect kept); unchanged when it fits."""
    longest = max(height, width)
    if not max_size or longest <= max_size:
        return height, width
    s = max_size / longest
    return max(1, round(height * s)), max(1, round(width * s))


def resize_image(image: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Float images (B, 3, H, W) resized to ``size`` with antialiasing (a plain bilinear
    downscale aliases thin struts into dashes)."""
    if tuple(image.shape[-2:]) == tuple(size):
        return image
    return F.interpolate(image, size=size, mode="bilinear", align_corners=False, antialias=True)


def resize_masks(masks: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Boolean masks (N, H, W) resized to ``size``: a pixel is in when half its area was."""
    if tuple(masks.shape[-2:]) == tuple(size):
        return masks
    if masks.shape[0] == 0:
        return masks.new_zeros((0, *size))
    small = F.interpolate(
        masks[:, None].to(torch.float32), size=size, mode="area" if size[0] <= masks.shape[-2] else "bilinear"
    )
    return small[:, 0] >= 0.5


def rgb_to_tensor(rgb: np.ndarray) -> torch.Tensor:
    """uint8 (H, W, 3) -> float (1, 3, H, W) in [0, 1]."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an RGB image (H, W, 3), got shape {rgb.shape}")
    return torch.from_numpy(np.ascontiguousarray(rgb)).permute(2, 0, 1)[None].to(torch.float32) / 255.0


@torch.no_grad()
def detect_rgb(model: MaskRCNN, rgb: np.ndarray, max_size: int | None) -> dict[str, torch.Tensor]:
    """Detections of one uint8 RGB image (H, W, 3): ``boxes``, ``labels``, ``scores`` and
    ``masks`` (D, H, W) at the image's own size, however small the model saw it, the probabilities
    the box branch's were thresholded from (``mask_probs``, (B, H, W) for the first B detections,
    the box branch's; a semantic head's regions follow them, their mask their probability) and with a
    semantic head its ``semantic_probs`` (C, H, W) at that size too; on the CPU whatever device
    the model is on."""
    model.eval()
    image = rgb_to_tensor(rgb).to(next(model.parameters()).device)
    h, w = image.shape[-2:]
    size = scaled_size(h, w, max_size)
    out = {k: v.cpu() for k, v in model(resize_image(image, size))[0].items()}
    if size != (h, w):
        sy, sx = h / size[0], w / size[1]
        out["boxes"] = out["boxes"] * torch.tensor([sx, sy, sx, sy])
        if len(out["masks"]):
            # Bilinear on the small mask then threshold: smoother edges than repeating pixels.
            big = F.interpolate(
                out["masks"][:, None].to(torch.float32), size=(h, w), mode="bilinear", align_corners=False
            )
            out["masks"] = big[:, 0] >= 0.5
        else:
            out["masks"] = torch.zeros((0, h, w), dtype=torch.bool)
        if len(out.get("mask_probs", ())):
            out["mask_probs"] = F.interpolate(
                out["mask_probs"][:, None], size=(h, w), mode="bilinear", align_corners=False
            )[:, 0]
        if "semantic_probs" in out:
            out["semantic_probs"] = F.interpolate(
                out["semantic_probs"][None], size=(h, w), mode="bilinear", align_corners=False
            )[0]
    return out


def weights_settings(cfg: MaskRCNNConfig, max_size: int | None) -> dict[str, Any]:
    """The manifest's ``settings`` for a model trained with this configuration and image size."""
    return {"model": cfg.to_dict(), "max_size": max_size}


def load_mask_rcnn(path: str | Path, classes: Sequence[str] = CLASSES) -> tuple[MaskRCNN, dict[str, Any]]:
    """The model a weights file was trained as (configuration from its manifest), loaded and in
    eval mode, with its manifest; WeightsError (naming the path) for anything that does not fit."""
    manifest = read_manifest(path)
    settings: Mapping[str, Any] = manifest["settings"]
    if not isinstance(settings, Mapping) or "model" not in settings:
        raise WeightsError(path, "manifest settings lack 'model' (the Mask R-CNN configuration)")
    try:
        cfg = MaskRCNNConfig.from_dict(dict(settings["model"]))
    except (TypeError, ValueError) as exc:
        raise WeightsError(path, f"manifest settings.model: {exc}") from exc
    max_size = settings.get("max_size")
    if max_size is not None and (not isinstance(max_size, int) or max_size < 32):
        raise WeightsError(path, f"manifest settings.max_size {max_size!r} is not an image size >= 32")
    if list(cfg.classes) != list(classes):
        raise WeightsError(path, f"weights are for classes {list(cfg.classes)}, expected {list(classes)}")
    model = MaskRCNN(cfg)
    manifest = load_weights(model, path, KIND, list(classes))
    model.eval()
    return model, manifest


__all__ = [
    "KIND",
    "detect_rgb",
    "load_mask_rcnn",
    "resize_image",
    "resize_masks",
    "rgb_to_tensor",
    "scaled_size",
    "weights_settings",
]
