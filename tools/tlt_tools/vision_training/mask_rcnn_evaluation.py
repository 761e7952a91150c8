"""Mask AP50 of a Mask R-CNN on an image set, of the model alone or of the masks as the vision
node makes them (:meth:`tlt_vision.segmentation_source.MaskRcnnSegmenter.refine`), and its one-line
summary."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from tlt_tools.vision_training.dataset import ImageSet
from tlt_tools.vision_training.mask_rcnn_data import InputError
from tlt_vision.segmentation.evaluate import MaskAP
from tlt_vision.segmentation.inference import detect_rgb
from tlt_vision.segmentation.model import MaskRCNN

if TYPE_CHECKING:
    from tlt_vision.segmentation_source import MaskRcnnSegmenter


def node_segmenter(path: str | Path, model: MaskRCNN, max_size: int | None) -> MaskRcnnSegmenter:
    """The vision node's segmentation (configured by the node.yaml at ``path``) around ``model``,
    whose own inference settings stay in force but while :func:`evaluate` uses the node's."""
    from tlt_vision.node_config import load_config
    from tlt_vision.segmentation_source import MaskRcnnSegmenter

    own = model.inference_settings()
    try:
        segmenter = MaskRcnnSegmenter.from_config(load_config(path), model=model, max_size=max_size)
    except (OSError, ValueError) as exc:
        raise InputError(f"--node-config {path}: {exc}") from exc
    model.set_inference(**own)
    return segmenter


def evaluate(
    model: MaskRCNN,
    images: ImageSet,
    max_size: int | None,
    limit: int | None = None,
    node: MaskRcnnSegmenter | None = None,
) -> dict[str, Any]:
    """Mask AP50 of ``model`` on the set at full resolution: ``map``, ``per_class`` {name: AP}
    (classes with ground truth), ``seconds_per_image`` (segmentation, not scoring), ``images``; with
    ``node`` (:func:`node_segmenter` around ``model``), of the masks as the node makes them."""
    n = len(images) if limit is None else min(limit, len(images))
    acc = MaskAP(len(images.classes))
    seconds = 0.0
    own = model.inference_settings()
    if node is not None:
        model.set_inference(**node.inference)
    try:
        for i in range(n):
            s = images[i]
            t0 = time.perf_counter()
            pred = detect_rgb(model, s.rgb, max_size)
            if node is not None:
                pred = node.refine(pred, s.depth, s.intrinsics)
            seconds += time.perf_counter() - t0
            gt = {
                "masks": torch.as_tensor(s.masks, dtype=torch.bool),
                "labels": torch.as_tensor(s.labels, dtype=torch.long),
            }
            acc.add(pred, gt)
    finally:
        model.set_inference(**own)
    result = acc.result()
    per_class = {images.classes[label - 1]: ap for label, ap in result["per_class"].items()}
    return {
        "map": result["map"],
        "per_class": per_class,
        "seconds_per_image": seconds / max(n, 1),
        "images": n,
    }


def format_ap(result: dict[str, Any], classes: Sequence[str]) -> str:
    parts = [f"{c} {result['per_class'][c]:.3f}" if c in result["per_class"] else f"{c} -" for c in classes]
    return f"mask AP50 {result['map']:.3f} ({', '.join(parts)})"
