"""The file of a C-3PO keypoint detector's weights: written by the training commands
(:mod:`tlt_tools.vision_training.c3po_supervised`, :mod:`tlt_tools.vision_training.c3po_self_supervised`)
and read by the vision node, which checks that the weights fit the CAD model it poses."""

from __future__ import annotations

from pathlib import Path

from tlt_vision.cad.models import CadModel
from tlt_vision.pose.detector import KeypointDetector
from tlt_vision.weights import WeightsError, load_weights, save_weights

KIND = "c3po_detector"
VERSION = "1"


def save_detector(
    det: KeypointDetector, model: CadModel, path: str | Path, training: dict, history: list[dict]
) -> Path:
    """Write ``det`` and its manifest (``training``: how it was trained; ``history``: per epoch)."""
    settings = {
        "model": model.name,
        "num_keypoints": det.num_keypoints,
        "scale": float(det.scale),
        "width": det.width,
    }
    extra = {"training": training, "history": history}
    return save_weights(det, path, KIND, VERSION, [model.object_class], settings, extra)


def load_detector(path: str | Path, model: CadModel, width: int) -> KeypointDetector:
    """A detector for ``model`` with the weights at ``path``; WeightsError if they do not fit it."""
    det = KeypointDetector(len(model.keypoint_names), model.diameter / 2, width)
    manifest = load_weights(det, path, KIND, [model.object_class])
    if manifest["settings"].get("model") != model.name:
        raise WeightsError(
            path, f"weights are for model {manifest['settings'].get('model')!r}, expected {model.name!r}"
        )
    return det


__all__ = ["KIND", "VERSION", "load_detector", "save_detector"]
