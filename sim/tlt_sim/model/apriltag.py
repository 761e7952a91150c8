"""AprilTag 36h11 images for the dispensers, drawn by OpenCV and written as PNG textures.

Each dispenser carries one tag; its id is the dispenser's index in the mission. The image has the
tag's black border plus a white quiet zone one cell wide, which detectors need to find the edge.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

CELLS = 8  # 6x6 data bits plus the one-cell black border of a 36h11 tag
PIXELS_PER_CELL = 16


def tag_image(tag_id: int, pixels_per_cell: int = PIXELS_PER_CELL) -> np.ndarray:
    """Grey image (uint8) of tag ``tag_id`` of the 36h11 family with a white quiet zone."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    if not 0 <= tag_id < dictionary.bytesList.shape[0]:
        raise ValueError(f"tag id {tag_id} is outside the 36h11 family")
    marker = cv2.aruco.generateImageMarker(dictionary, tag_id, CELLS * pixels_per_cell, borderBits=1)
    return cv2.copyMakeBorder(marker, *(pixels_per_cell,) * 4, borderType=cv2.BORDER_CONSTANT, value=255)


def write_tag_png(tag_id: int, path: str | Path) -> Path:
    """Write the tag image as an RGB PNG (MuJoCo textures want colour) and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    image = cv2.cvtColor(tag_image(tag_id), cv2.COLOR_GRAY2BGR)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"cannot write {path}")
    return path


def tag_side(tag_size: float) -> float:
    """Side of the black square of a tag printed ``tag_size`` wide including its quiet zone."""
    return tag_size * CELLS / (CELLS + 2)
