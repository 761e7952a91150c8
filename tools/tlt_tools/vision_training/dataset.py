"""Rendered training images on disk: one directory, an ``index.json`` and one ``.npz`` per image.

The image renderer (:mod:`tlt_tools.vision_training.render_dataset`) writes it and the Mask R-CNN trainer,
the self-supervised C-3PO and the vision benchmarks read it, so the format lives here once.

``index.json``::

    {"format": "tlt-vision-images", "version": 1, "classes": [...], "width": 640, "height": 480,
     "images": ["00000.npz", ...], "settings": {...how it was rendered...}}

Each ``NNNNN.npz`` holds (``N`` instances, ``H`` x ``W`` pixels):

===============  ================  =====================================================
``rgb``          (H, W, 3) uint8   the colour image
``depth``        (H, W) float32    metres along the optical axis, 0 where nothing was hit
``masks``        (N, H, W) bool    one mask per visible part instance (stored bit-packed
                                   along W as ``masks_packed``: the bool array is eight
                                   times larger and compressing it takes as long as rendering)
``labels``       (N,) int64        1-based into ``classes`` (0 is the background)
``names``        (N,) str          the twin's instance name (``bay1/vertical_x0_y0/tube``)
``poses``        (N, 4, 4) float64 model-to-camera transform of each part (optical frame)
``defects``      (N,) str          ``""`` for a good part, else the defect kind
``intrinsics``   (3, 3) float64    the pinhole matrix K
===============  ================  =====================================================

:func:`read_index` and :class:`ImageSet` refuse a directory that is not such a set with an error
naming the path and what is wrong.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "tlt-vision-images"
VERSION = 1
INDEX = "index.json"
ARRAYS = ("rgb", "depth", "masks", "labels", "names", "poses", "defects", "intrinsics")


class DatasetError(ValueError):
    """A directory that is not a readable image set; the message names the path."""


@dataclass
class Sample:
    rgb: np.ndarray
    depth: np.ndarray
    masks: np.ndarray
    labels: np.ndarray
    names: np.ndarray
    poses: np.ndarray
    defects: np.ndarray
    intrinsics: np.ndarray


def write_sample(path: str | Path, sample: Sample) -> None:
    """Write one image's arrays (compressed: masks and depth compress tenfold)."""
    n = len(sample.labels)
    shapes = {"masks": (n, *sample.depth.shape), "names": (n,), "poses": (n, 4, 4), "defects": (n,)}
    for key, shape in shapes.items():
        if getattr(sample, key).shape != shape:
            raise ValueError(f"{key} has shape {getattr(sample, key).shape}, expected {shape}")
    arrays = {key: getattr(sample, key) for key in ARRAYS if key != "masks"}
    arrays["masks_packed"] = np.packbits(sample.masks.astype(bool), axis=-1)
    np.savez_compressed(path, **arrays)


def write_index(
    root: str | Path, classes: list[str], width: int, height: int, images: list[str], settings: dict[str, Any]
) -> None:
    index = {
        "format": FORMAT,
        "version": VERSION,
        "classes": list(classes),
        "width": width,
        "height": height,
        "images": list(images),
        "settings": settings,
    }
    tmp = Path(root) / (INDEX + ".tmp")
    tmp.write_text(json.dumps(index, indent=1))
    tmp.replace(Path(root) / INDEX)  # a set interrupted mid-write keeps its last whole index


def read_index(root: str | Path) -> dict[str, Any]:
    path = Path(root) / INDEX
    try:
        index = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise DatasetError(f"{path}: no such file: not a rendered image set") from exc
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path}: not JSON: {exc}") from exc
    if not isinstance(index, dict) or index.get("format") != FORMAT:
        raise DatasetError(f"{path}: format is not {FORMAT!r}")
    if index.get("version") != VERSION:
        raise DatasetError(f"{path}: version {index.get('version')!r}, this code reads {VERSION}")
    for key in ("classes", "width", "height", "images"):
        if key not in index:
            raise DatasetError(f"{path}: {key} is missing")
    return index


class ImageSet:
    """A rendered image set, read lazily: ``len(s)``, ``s[i] -> Sample``."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.index = read_index(self.root)
        self.classes: list[str] = list(self.index["classes"])
        self.files: list[str] = list(self.index["images"])

    def __len__(self) -> int:
        return len(self.files)

    @property
    def recipe(self) -> dict[str, Any]:
        """How the set was rendered (its index's settings: seed, size, scene mix, defects), without
        the per-image lists, and its image count: what a weights manifest records of its data,
        since the set's own directory is usually scratch space."""
        settings = self.index.get("settings", {})
        kept = {k: v for k, v in settings.items() if k not in ("scene_kinds", "defective_parts")}
        return {**kept, "images": len(self)}

    def path(self, i: int) -> Path:
        """The file of image ``i``."""
        return self.root / self.files[i]

    def __getitem__(self, i: int) -> Sample:
        path = self.path(i)
        try:
            with np.load(path, allow_pickle=False) as data:
                stored = [key for key in ARRAYS if key != "masks"] + ["masks_packed"]
                missing = [key for key in stored if key not in data.files]
                if missing:
                    raise DatasetError(f"{path}: missing arrays {', '.join(missing)}")
                arrays = {key: data[key] for key in stored if key != "masks_packed"}
                width = arrays["depth"].shape[1]
                arrays["masks"] = np.unpackbits(data["masks_packed"], axis=-1, count=width).astype(bool)
                return Sample(**arrays)
        except (OSError, ValueError) as exc:
            if isinstance(exc, DatasetError):
                raise
            raise DatasetError(f"{path}: cannot read: {exc}") from exc


class ImageSets:
    """Several image sets of one class list read as one (sets rendered in parallel with their own
    seeds): ``len(s)``, ``s[i] -> Sample``, ``s.path(i)``, ``s.classes``, ``s.roots``."""

    def __init__(self, sets: list[ImageSet]) -> None:
        if not sets:
            raise DatasetError("no image sets given")
        for other in sets[1:]:
            if other.classes != sets[0].classes:
                raise DatasetError(
                    f"{other.root / 'index.json'}: classes {other.classes} differ from "
                    f"{sets[0].root / 'index.json'}'s {sets[0].classes}"
                )
        self.sets = sets
        self.classes = sets[0].classes
        self.roots = [s.root for s in sets]
        self._starts = np.cumsum([0] + [len(s) for s in sets])

    def _locate(self, i: int) -> tuple[ImageSet, int]:
        if not 0 <= i < len(self):
            raise IndexError(f"image {i} of {len(self)}")
        k = int(np.searchsorted(self._starts, i, side="right")) - 1
        return self.sets[k], i - int(self._starts[k])

    def __len__(self) -> int:
        return int(self._starts[-1])

    def path(self, i: int) -> Path:
        images, j = self._locate(i)
        return images.path(j)

    def __getitem__(self, i: int) -> Sample:
        images, j = self._locate(i)
        return images[j]


def instance_model(object_class: str, name: str) -> str:
    """The CAD model of a rendered instance of ``object_class``: a strut tube's kind (vertical or
    diagonal) is read from the twin's instance name (``.../diagonal_dispenser_x/0/tube``)."""
    if object_class == "strut_tube":
        return "strut_tube/diagonal" if "/diagonal" in name else "strut_tube/vertical"
    return object_class


def instance_part(object_class: str, name: str) -> str:
    """The part a rendered instance belongs to: the twin draws each side of a cross frame as an
    instance of its own (``payload/side_2``), every other part as one."""
    return name.rsplit("/", 1)[0] if object_class == "cross_frame" else name


__all__ = [
    "DatasetError",
    "ImageSet",
    "ImageSets",
    "Sample",
    "instance_model",
    "instance_part",
    "read_index",
    "write_index",
    "write_sample",
]
