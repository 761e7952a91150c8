"""RoIAlign (Mask R-CNN): average of bilinear samples on a regular grid in each output bin.

Semantics follow the reference RoIAlign: a box ``(x1, y1, x2, y2)`` in image pixels is scaled by
``spatial_scale``; with ``aligned=True`` the box is shifted by half a pixel so that a pixel's value
sits at its centre (a box ``[0, 4]`` on a 4-pixel row covers the samples ``0..3`` exactly), and its
size is not clamped; with ``aligned=False`` the shift is not applied and sizes below one pixel are
raised to one. Each of the ``PH x PW`` bins averages ``sampling_ratio**2`` samples at the centres of
a regular sub-grid. A sample more than one pixel outside the map reads 0; one within a pixel of the
border reads the border value (coordinates clamped to 0, the last row/column held constant).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def _bilinear(feat: torch.Tensor, y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Bilinear samples of one image ``feat`` (C, H, W) at pixel coordinates ``(y, x)`` (R, S) -> (C, R, S).

    Coordinates are clamped to ``[0, H - 1]`` (the reference's border rule) and sampled with
    ``grid_sample`` (``align_corners=True`` maps -1 and +1 to the first and last pixel centres),
    whose backward is a fast native scatter; samples more than a pixel outside read 0. Channels
    stay first, as ``grid_sample`` gives them: moving them last copied every sample.
    """
    _, h, w = feat.shape
    outside = (y < -1.0) | (y > h) | (x < -1.0) | (x > w)
    yc = y.clamp(0.0, h - 1.0)
    xc = x.clamp(0.0, w - 1.0)
    gy = yc / max(h - 1, 1) * 2.0 - 1.0
    gx = xc / max(w - 1, 1) * 2.0 - 1.0
    grid = torch.stack([gx, gy], dim=-1)[None]  # (1, R, S, 2)
    v = F.grid_sample(feat[None], grid, mode="bilinear", padding_mode="border", align_corners=True)
    return v[0].masked_fill(outside, 0.0)


def roi_align(
    features: torch.Tensor,
    rois: torch.Tensor,
    output_size: tuple[int, int],
    spatial_scale: float = 1.0,
    sampling_ratio: int = 2,
    aligned: bool = True,
) -> torch.Tensor:
    """Pool ``features`` (B, C, H, W) over ``rois`` (R, 5) = ``(batch_index, x1, y1, x2, y2)``.

    Returns ``(R, C, PH, PW)``. Differentiable with respect to ``features``. ``sampling_ratio``
    must be positive (a fixed sub-grid keeps the computation one batched gather).
    """
    if sampling_ratio <= 0:
        raise ValueError("sampling_ratio must be a positive number of samples per bin side")
    ph, pw = output_size
    r = rois.shape[0]
    c = features.shape[1]
    if r == 0:
        return features.new_zeros((0, c, ph, pw))
    rois = rois.to(features.dtype)
    offset = 0.5 if aligned else 0.0
    x1 = rois[:, 1] * spatial_scale - offset
    y1 = rois[:, 2] * spatial_scale - offset
    rw = rois[:, 3] * spatial_scale - offset - x1
    rh = rois[:, 4] * spatial_scale - offset - y1
    if not aligned:
        rw = rw.clamp(min=1.0)
        rh = rh.clamp(min=1.0)
    bin_w, bin_h = rw / pw, rh / ph
    s = sampling_ratio
    # Sample positions along each axis, in units of bins: (p + (i + 0.5) / s) for p bins, i samples.
    gy = (torch.arange(ph * s, dtype=features.dtype, device=features.device) + 0.5) / s
    gx = (torch.arange(pw * s, dtype=features.dtype, device=features.device) + 0.5) / s
    ys = y1[:, None] + gy[None, :] * bin_h[:, None]  # (R, PH*s)
    xs = x1[:, None] + gx[None, :] * bin_w[:, None]  # (R, PW*s)
    yy = ys[:, :, None].expand(r, ph * s, pw * s).reshape(r, -1)
    xx = xs[:, None, :].expand(r, ph * s, pw * s).reshape(r, -1)
    batch = rois[:, 0].long()
    images = torch.unique(batch).tolist()
    if len(images) == 1:  # inference: one image, its samples need no gathering
        vals = _bilinear(features[images[0]], yy, xx)  # (C, R, PH*s*PW*s)
    else:
        vals = features.new_zeros((c, r, yy.shape[1]))
        for b in images:
            sel = torch.nonzero(batch == b).flatten()
            vals = vals.index_copy(1, sel, _bilinear(features[b], yy[sel], xx[sel]))
    # One axis at a time, the contiguous one first: torch's mean over the two strided sample axes
    # at once is about ten times slower on the CPU.
    vals = vals.reshape(c, r, ph, s, pw, s).sum(dim=5).sum(dim=3) / (s * s)
    return vals.permute(1, 0, 2, 3).contiguous()


__all__ = ["roi_align"]
