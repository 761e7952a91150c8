"""The contact sheet of an image set: a grid of its first images with every mask outlined in its
class's colour and the larger ones named, to see at a glance what a render wrote."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tlt_tools.vision_training.dataset import Sample
from tlt_vision.segmentation.config import CLASSES

CLASS_BGR = {  # outline colours (BGR), one per class
    "strut_tube": (255, 255, 255),
    "end_fitting": (0, 165, 255),
    "cross_frame": (255, 200, 80),
    "corner_joint": (255, 60, 60),
    "rivet": (60, 60, 255),
}


def write_preview(path: str | Path, samples: list[Sample], columns: int = 3, tile_width: int = 400) -> None:
    """A grid of ``samples`` (each at most ``tile_width`` wide) with every mask outlined in its
    class's colour and the larger ones named."""
    import cv2

    tiles = []
    for sample in samples:
        h, w = sample.depth.shape
        scale = min(1.0, tile_width / w)
        size = (round(w * scale), round(h * scale))
        image = np.ascontiguousarray(cv2.resize(sample.rgb[..., ::-1], size, interpolation=cv2.INTER_AREA))
        for mask, label in zip(sample.masks, sample.labels, strict=True):
            cls = CLASSES[int(label) - 1]
            small = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
            contours, _ = cv2.findContours(small, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            cv2.drawContours(image, contours, -1, CLASS_BGR[cls], 1)
            ys, xs = np.nonzero(small)
            if len(xs) >= 0.003 * size[0] * size[1]:  # naming every rack part would hide the image
                cv2.putText(
                    image,
                    cls,
                    (int(xs.mean()), int(ys.mean())),
                    cv2.FONT_HERSHEY_SIMPLEX,
                    0.35,
                    CLASS_BGR[cls],
                    1,
                    cv2.LINE_AA,
                )
        tiles.append(image)
    while len(tiles) % columns:
        tiles.append(np.zeros_like(tiles[0]))
    rows = [np.hstack(tiles[r : r + columns]) for r in range(0, len(tiles), columns)]
    if not cv2.imwrite(str(path), np.vstack(rows)):
        raise OSError(f"{path}: could not write the preview")
