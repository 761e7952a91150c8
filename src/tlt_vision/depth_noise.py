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
  A generous allowance alone would certify wrong poses (a small part far away, a fitting turned by
  degrees), so a pose is certified only where the fit to so noisy a cloud places the part to
  ``max_allowance`` of its size (2 %, the accuracy the issue holds certified poses to) at
  ``precision_sigmas`` standard errors: :mod:`tlt_vision.pose.precision` predicts that error
  from the cloud's geometry and this noise, since hundreds of points place a part far better than
  any one of them.

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
    frame_fx: float = 0.0  # pixels: the focal length of the frame at hand, 0 when not known
    # How many predicted standard errors of a fitted pose (:mod:`tlt_vision.pose.precision`) must
    # lie within ``max_allowance`` of the part's size for the pose to be certified.
    precision_sigmas: float = 2.0

    @property
    def exact(self) -> bool:
        return self.fraction <= 0.0 and self.per_m2 <= 0.0

    def for_frame(self, fx: float) -> DepthNoise:
        """This noise in a frame of focal length ``fx`` (pixels): the median's share of the noise
        correlated over ``correlation_px * fx / focal_px`` of its pixels."""
        if self.correlation_px <= 0.0 or self.focal_px <= 0.0:
            return replace(self, frame_fx=fx)
        shared = median_share(self.correlation_px * fx / self.focal_px, self.window)
        return replace(self, shared=shared, frame_fx=fx)

    @property
    def pixels_per_draw(self) -> float:
        """Frame pixels per independent draw of the filtered noise (:func:`draw_area`): the
        window's and, in a frame of known focal length, the camera's own correlation's."""
        correlation = 0.0
        if self.correlation_px > 0.0 and self.focal_px > 0.0 and self.frame_fx > 0.0:
            correlation = self.correlation_px * self.frame_fx / self.focal_px
        return draw_area(correlation, self.window)

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


@functools.lru_cache(maxsize=64)
def draw_area(correlation_px: float, window: int) -> float:
    """Pixels per independent draw of a noise correlated over ``correlation_px`` pixels once a
    ``window`` x ``window`` median has filtered it: the variance of a 30 x 30 block's mean times
    its pixels over one pixel's variance, measured once on drawn fields (the same draws every
    time). A fit's precision counts its points by it (:mod:`tlt_vision.pose.precision`)."""
    correlation_px = round(correlation_px, 2)
    rng = np.random.default_rng(0)
    means, variances = [], []
    for _ in range(200):
        field = rng.standard_normal((60, 60))
        if correlation_px >= 0.3:
            field = correlated_field(field, correlation_px)
        filtered = ndimage.median_filter(field, window)[10:-10, 10:-10]
        means.append(float(filtered[5:35, 5:35].mean()))
        variances.append(float(filtered.var()))
    return max(1.0, float(np.var(means)) * 900.0 / float(np.mean(variances)))


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


__all__ = ["EXACT", "DepthNoise", "draw_area", "median_share", "window_median", "with_noise"]
