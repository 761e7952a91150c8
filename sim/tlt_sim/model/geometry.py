"""MJCF-specific geometry for the generator: camera axes and number text.

Rotations, poses and quaternions live in :mod:`tlt_common.geometry.transforms`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def look_at_xyaxes(forward: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """MJCF ``xyaxes`` of a camera looking along ``forward`` (MuJoCo cameras look along -z)."""
    f = np.asarray(forward, dtype=float)
    f = f / np.linalg.norm(f)
    right = np.cross(f, np.asarray(up, dtype=float))
    if np.linalg.norm(right) < 1e-6:  # looking along up: any right angle will do
        right = np.cross(f, np.array([0.0, 1.0, 0.0]))
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, f)
    return np.concatenate([right, cam_up])


def fmt(values: Sequence[float] | float) -> str:
    """MJCF number list text, compact and exact enough (1e-9 m)."""
    if isinstance(values, int | float):
        values = [values]
    return " ".join(f"{float(v):.9g}" for v in values)
