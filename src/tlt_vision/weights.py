"""Trained weights with a manifest: saved together, checked together, refused when they disagree.

``save_weights`` writes ``<stem>.pt`` (the state dict) and ``<stem>.json`` (the manifest: format,
kind, version, classes, the model's settings, every tensor's shape, the SHA-256 of the .pt file and
any figures the trainer adds). ``load_weights`` checks all of that against the model the caller
built from its own configuration before loading a single tensor: a missing file, a manifest of
another kind, other classes, a changed file or a tensor of another shape raises
:class:`WeightsError` naming the path and, for shapes, the tensor, its shape and the expected one.
A node calls it at start-up, so a bad file stops it there rather than producing wrong poses.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import nn

FORMAT = 1


class WeightsError(RuntimeError):
    """Weights that cannot be used; the message names the file and what is wrong."""

    def __init__(self, path: str | Path, reason: str) -> None:
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{path}: {reason}")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def manifest_path(weights: str | Path) -> Path:
    return Path(weights).with_suffix(".json")


def save_weights(
    model: nn.Module,
    path: str | Path,
    kind: str,
    version: str,
    classes: Sequence[str],
    settings: Mapping[str, Any],
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write the state dict to ``path`` (.pt) and its manifest beside it; returns the manifest path."""
    path = Path(path)
    if path.suffix != ".pt":
        raise ValueError(f"{path}: weights files end in .pt")
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    torch.save(state, path)
    manifest = {
        "format": FORMAT,
        "kind": kind,
        "version": version,
        "classes": list(classes),
        "settings": dict(settings),
        "shapes": {k: list(v.shape) for k, v in state.items()},
        "sha256": _sha256(path),
        **({"extra": dict(extra)} if extra else {}),
    }
    out = manifest_path(path)
    out.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return out


def read_manifest(path: str | Path) -> dict[str, Any]:
    """The manifest of weights file ``path``; WeightsError when it is missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        raise WeightsError(path, "weights file not found")
    mpath = manifest_path(path)
    if not mpath.is_file():
        raise WeightsError(mpath, "manifest not found (weights are only used with their manifest)")
    try:
        manifest = json.loads(mpath.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise WeightsError(mpath, f"unreadable manifest: {exc}") from exc
    for key in ("format", "kind", "version", "classes", "settings", "shapes", "sha256"):
        if key not in manifest:
            raise WeightsError(mpath, f"manifest lacks {key!r}")
    if manifest["format"] != FORMAT:
        raise WeightsError(mpath, f"manifest format {manifest['format']!r}, expected {FORMAT}")
    return manifest


def load_weights(
    model: nn.Module, path: str | Path, kind: str, classes: Sequence[str] | None = None
) -> dict[str, Any]:
    """Check weights ``path`` against ``model`` and load them into it; returns the manifest."""
    path = Path(path)
    manifest = read_manifest(path)
    if manifest["kind"] != kind:
        raise WeightsError(path, f"weights are for {manifest['kind']!r}, expected {kind!r}")
    if classes is not None and list(classes) != manifest["classes"]:
        raise WeightsError(path, f"weights are for classes {manifest['classes']}, expected {list(classes)}")
    if _sha256(path) != manifest["sha256"]:
        raise WeightsError(path, "file does not match its manifest's SHA-256 (changed or truncated)")
    expected = {k: list(v.shape) for k, v in model.state_dict().items()}
    for key, shape in expected.items():
        if key not in manifest["shapes"]:
            raise WeightsError(path, f"tensor {key} missing; expected shape {tuple(shape)}")
        if manifest["shapes"][key] != shape:
            raise WeightsError(
                path, f"tensor {key} has shape {tuple(manifest['shapes'][key])}, expected {tuple(shape)}"
            )
    extra = sorted(set(manifest["shapes"]) - set(expected))
    if extra:
        raise WeightsError(path, f"unexpected tensor {extra[0]} (the model has no such parameter)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for a corrupt file
        raise WeightsError(path, f"unreadable weights: {exc}") from exc
    for key, shape in expected.items():
        if key not in state or list(state[key].shape) != shape:
            raise WeightsError(
                path, f"tensor {key} in the file differs from its manifest; expected {tuple(shape)}"
            )
    model.load_state_dict(state)
    return manifest


__all__ = ["FORMAT", "WeightsError", "load_weights", "manifest_path", "read_manifest", "save_weights"]
