"""Chamfer distances between point clouds: per point, one-sided and symmetric.

``nearest_distances(a, b)`` gives, for each point of ``a``, the Euclidean distance to its nearest
point of ``b``; the certificate takes percentiles of these. The one-sided Chamfer distance is their
mean (or the mean of their squares); the symmetric one adds the other direction. Clouds may be
batched ``(B, N, 3)`` or single ``(N, 3)``; a ``mask`` (B, N) marks the valid points of ``a`` when a
batch is padded to a common size.
"""

from __future__ import annotations

import torch


def nearest_sq_distances(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Squared distance from each point of ``a`` (..., N, 3) to its nearest point of ``b`` (..., M, 3).

    Squared distances have a finite gradient where a point coincides with its neighbour, so the
    corrector optimises these.
    """
    if b.shape[-2] == 0:
        raise ValueError("the reference cloud is empty: no nearest point exists")
    # torch.cdist's matrix-multiply path loses precision for nearby points; the difference path is exact.
    diff = a[..., :, None, :] - b[..., None, :, :]
    return diff.pow(2).sum(-1).min(dim=-1).values


def nearest_distances(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Distance from each point of ``a`` (..., N, 3) to its nearest point of ``b`` (..., M, 3)."""
    return nearest_sq_distances(a, b).sqrt()


def _masked_mean(values: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    if mask is None:
        return values.mean(dim=-1)
    m = mask.to(values.dtype)
    return (values * m).sum(-1) / m.sum(-1).clamp(min=1.0)


def chamfer_one_sided(
    a: torch.Tensor, b: torch.Tensor, squared: bool = False, mask: torch.Tensor | None = None
) -> torch.Tensor:
    """Mean over the points of ``a`` of the (squared) distance to ``b``; shape ``(...)``."""
    d = nearest_sq_distances(a, b) if squared else nearest_distances(a, b)
    return _masked_mean(d, mask)


def chamfer_symmetric(a: torch.Tensor, b: torch.Tensor, squared: bool = False) -> torch.Tensor:
    """One-sided Chamfer from ``a`` to ``b`` plus from ``b`` to ``a``."""
    return chamfer_one_sided(a, b, squared) + chamfer_one_sided(b, a, squared)


__all__ = ["chamfer_one_sided", "chamfer_symmetric", "nearest_distances", "nearest_sq_distances"]
