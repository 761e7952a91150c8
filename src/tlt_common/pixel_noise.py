"""Noise neighbouring pixels share, as a stereo camera's depth has it: the twin's camera models
draw it (``tlt_sim.model.camera_sensor``), the vision pipeline allows for it
(``tlt_vision.depth_noise``)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def correlated_field(white: np.ndarray, correlation_px: float) -> np.ndarray:
    """``white`` (independent unit normal noise) smoothed by a Gaussian of ``correlation_px`` pixels
    and scaled back to unit variance. Under a third of a pixel it is returned as it is."""
    if correlation_px < 0.3:
        return white
    smooth = ndimage.gaussian_filter(white, correlation_px, mode="reflect")
    impulse = np.zeros(int(8 * correlation_px) * 2 + 1)
    impulse[len(impulse) // 2] = 1.0
    kernel = ndimage.gaussian_filter1d(impulse, correlation_px, mode="constant")
    return smooth / (float(np.sum(kernel**2)) ** (white.ndim / 2))


__all__ = ["correlated_field"]
