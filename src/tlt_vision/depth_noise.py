"""A depth camera's noise: filtered out of a part's cloud, allowed for in its certificate.

The twin's depth is exact; a real camera's is not. A stereo camera's (the lifter's ZEDs) is about
1 % of the depth at a few metres, and moves each point along its ray by more than a certificate
threshold: the 90th percentile of the Chamfer distances of a right pose is then the noise's, not
the fit's. With such noise added to each pixel's depth (``bench/vision.py --depth-noise 0.01``)
few of the certifiable views are certified, and many of those few are wrong.

Two things answer it, both given the camera's noise (node.yaml ``depth_noise``): 1 sigma of
``fraction`` times the depth plus ``per_m2`` times its square. A stereo camera's is the square's:
a disparity error of ``s`` pixels moves a point at depth z by ``z^2 s / (b f)`` (baseline ``b``,
focal length ``f`` in pixels), so ``per_m2`` is ``s / (b f)``, per metre:

* Each point of a part's cloud takes the median depth of the part's own valid pixels in a
  ``window`` x ``window`` square about it (:func:`window_median`). Only the mask's pixels enter,
  so the part's silhouette does not blur into what lies behind it; a median, so a stray pixel of
  the background inside the mask does not move the points beside it.
* The certificate's threshold grows by what is left of the noise (:meth:`DepthNoise.allowance`):
  the 90th percentile of the noise's own distances, added in quadrature, at the cloud's depth.
  Where that allowance is over ``max_allowance`` of the part's size (2 %, the accuracy the issue
  holds certified poses to), the depth cannot place the part that well, and no pose is certified,
  with that reason (:meth:`DepthNoise.too_noisy`). Without that bound, a generous allowance
  certifies wrong poses (a small part far away, a fitting turned by degrees), and more of them at
  lower noise: the same allowance then comes at a greater depth, where a part is a few pixels
  across and the window a large share of it.

A stereo camera's noise is shared by neighbouring pixels (the matcher's window makes them err
together), which the median takes down less than independent noise: ``shared`` is how much more
of it the window leaves (:func:`median_share`, from the noise's correlation length in the frame's
pixels; 1 for independent noise). The correlation is a property of the camera at its native
resolution, so the share depends on the frame's focal length: :meth:`DepthNoise.for_frame`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from tlt_common.pixel_noise import correlated_field

# The 90th percentile of |N(0, 1)|: the certificate's percentile of a Gaussian's distances.
P90_OF_NORMAL = 1.6449
# The sample median's standard error over the mean's, for Gaussian noise (sqrt(pi / 2)).
MEDIAN_EFFICIENCY = math.sqrt(math.pi / 2)


@dataclass(frozen=True)
class DepthNoise:
    """The camera's depth noise (1 sigma: ``fraction`` of the depth plus ``per_m2`` times its
    square), the filter's window, and the largest allowance for it, a fraction of the part's size."""

    fraction: float = 0.0
    window: int = 5  # pixels, odd
    max_allowance: float = 0.02
    per_m2: float = 0.0  # 1/m: a stereo camera's disparity error over baseline times focal length
    # The noise neighbouring pixels share: over ``correlation_px`` pixels of the camera at its
    # native resolution, whose focal length is ``focal_px``; and the share of it the window's
    # median leaves over an independent noise's, for the frame at hand (:meth:`for_frame`).
    correlation_px: float = 0.0
    focal_px: float = 0.0
    shared: float = 1.0

    @property
    def exact(self) -> bool:
        return self.fraction <= 0.0 and self.per_m2 <= 0.0

    def for_frame(self, fx: float) -> DepthNoise:
        """This noise in a frame of focal length ``fx`` (pixels): the median's share of the noise
        correlated over ``correlation_px * fx / focal_px`` of its pixels."""
        if self.correlation_px <= 0.0 or self.focal_px <= 0.0:
            return self
        return replace(self, shared=median_share(self.correlation_px * fx / self.focal_px, self.window))

    def sigma(self, depth: float | np.ndarray) -> float | np.ndarray:
        """1 sigma (m) of a raw pixel's depth at ``depth`` (m; one or an array)."""
        return self.fraction * depth + self.per_m2 * depth * depth

    def residual(self, depth: float) -> float:
        """1 sigma (m) of a filtered point's depth at ``depth`` (m)."""
        if self.exact:
            return 0.0
        return self.sigma(depth) * MEDIAN_EFFICIENCY / self.window * self.shared

    def allowance(self, depth: float) -> float:
        """What the certificate allows for the residual noise at ``depth`` (m), added to a
        threshold in quadrature."""
        return P90_OF_NORMAL * self.residual(depth)

    def too_noisy(self, depth: float, size: float) -> bool:
        """Whether the allowance at ``depth`` (m) is over ``max_allowance`` of ``size`` (m), the
        part's."""
        return self.allowance(depth) > self.max_allowance * size


EXACT = DepthNoise()


@functools.lru_cache(maxsize=64)
def median_share(correlation_px: float, window: int) -> float:
    """How much more of a noise correlated over ``correlation_px`` pixels (a Gaussian kernel's
    sigma) a ``window`` x ``window`` median leaves than of independent noise: measured once on a
    drawn field of it (the same draw every time), since no closed form gives it."""
    correlation_px = round(correlation_px, 2)
    if correlation_px < 0.3:
        return 1.0
    rng = np.random.default_rng(0)
    white = rng.standard_normal((192, 192))
    shared = correlated_field(white, correlation_px)
    filtered = ndimage.median_filter(shared, window)[window:-window, window:-window]
    independent = ndimage.median_filter(white, window)[window:-window, window:-window]
    return float(np.std(filtered) / np.std(independent))


def window_median(
    depth: np.ndarray, valid: np.ndarray, v: np.ndarray, u: np.ndarray, window: int
) -> np.ndarray:
    """Per pixel ``(v[i], u[i])`` (rows, columns of ``depth``), the median of the ``valid`` depths in
    the ``window`` x ``window`` square about it. Each of those pixels must itself be valid."""
    half = window // 2
    offsets = np.arange(-half, half + 1)
    rows = v[:, None, None] + offsets[None, :, None]
    cols = u[:, None, None] + offsets[None, None, :]
    h, w = depth.shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rows, cols = np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)
    values = np.where(inside & valid[rows, cols], depth[rows, cols], np.nan).reshape(len(v), -1)
    return np.nanmedian(values.astype(np.float64), axis=1)


def with_noise(depth: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """``depth`` with Gaussian noise of ``fraction`` times each pixel's depth, independent from pixel
    to pixel (the noise :class:`DepthNoise` describes, as the benchmarks draw it); "no depth" (0,
    NaN, inf) stays so."""
    d = np.asarray(depth)
    return (d * (1 + fraction * rng.standard_normal(d.shape))).astype(d.dtype)


__all__ = ["EXACT", "DepthNoise", "median_share", "window_median", "with_noise"]
