"""Weighted rigid registration of corresponding points (Kabsch / Umeyama without scale).

``register(a, b, w)`` returns the rotation ``R`` and translation ``t`` minimising
``sum_i w_i |R a_i + t - b_i|^2``. ``R`` is always a proper rotation (det +1): when the best
orthogonal fit is a reflection (coplanar or noisy points), the smallest singular direction is flipped,
which is the constrained optimum (Umeyama 1991).

The rotation is differentiable through a custom backward of the polar factor whose denominators
``s_i + s_j`` are bounded below: collinear keypoints (axially symmetric parts) leave the rotation
about their axis undetermined, and the plain SVD backward then returns inf/NaN; here that direction
just gets a damped, finite gradient.
"""

from __future__ import annotations

import torch


def _polar_parts(h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``U' , s', V`` with ``H = U' diag(s') V^T`` and ``U' V^T`` the nearest rotation to ``H``."""
    u, s, vh = torch.linalg.svd(h)
    v = vh.transpose(-1, -2)
    d = torch.sign(torch.det(u @ vh))
    d = torch.where(d == 0, torch.ones_like(d), d)
    flip = torch.ones_like(s)
    flip[..., 2] = d
    return u * flip[..., None, :], s * flip, v


class _NearestRotation(torch.autograd.Function):
    """Nearest rotation ``Q = U D V^T`` to a 3x3 matrix ``H`` (batched), with a bounded backward."""

    @staticmethod
    def forward(ctx, h: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        u, s, v = _polar_parts(h)
        ctx.save_for_backward(u, s, v)
        return u @ v.transpose(-1, -2)

    @staticmethod
    def backward(ctx, grad_q: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        u, s, v = ctx.saved_tensors
        # dQ = U' A V^T with A_ij = (U'^T dH V)_ij - (.)_ji over (s'_i + s'_j); the adjoint follows.
        gamma = u.transpose(-1, -2) @ grad_q @ v
        denom = s[..., :, None] + s[..., None, :]
        floor = 1e-6 * s[..., :1, None].abs().clamp(min=1e-12)
        denom = torch.maximum(denom, floor)
        k = (gamma - gamma.transpose(-1, -2)) / denom
        return u @ k @ v.transpose(-1, -2)


def nearest_rotation(h: torch.Tensor) -> torch.Tensor:
    """The proper rotation nearest (Frobenius) to each 3x3 matrix ``h`` (..., 3, 3)."""
    return _NearestRotation.apply(h)


def register(
    a: torch.Tensor, b: torch.Tensor, weights: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """``R`` (..., 3, 3), ``t`` (..., 3) with ``R a_i + t ~ b_i``; ``a``, ``b`` are (..., K, 3).

    ``weights`` (..., K) are non-negative; they need not sum to one but must not all be zero.
    With fewer than three non-collinear points the rotation about the points' line is arbitrary
    (but still a proper rotation); with one point it is arbitrary and ``t`` moves the point.
    """
    if a.shape != b.shape:
        raise ValueError(f"point sets differ in shape: {tuple(a.shape)} and {tuple(b.shape)}")
    if weights is None:
        weights = torch.ones(a.shape[:-1], dtype=a.dtype, device=a.device)
    wsum = weights.sum(-1, keepdim=True)
    if bool((wsum <= 0).any()):
        raise ValueError("registration weights sum to zero")
    w = (weights / wsum)[..., None]
    ca = (w * a).sum(-2)
    cb = (w * b).sum(-2)
    h = (w * (a - ca[..., None, :])).transpose(-1, -2) @ (b - cb[..., None, :])
    rot = nearest_rotation(h).transpose(-1, -2)
    t = cb - (rot @ ca[..., None])[..., 0]
    return rot, t


def transform(points: torch.Tensor, rot: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """``R p + t`` for points (..., N, 3), ``R`` (..., 3, 3), ``t`` (..., 3)."""
    return points @ rot.transpose(-1, -2) + t[..., None, :]


def rotation_angle(r1: torch.Tensor, r2: torch.Tensor) -> torch.Tensor:
    """Angle (rad) of the relative rotation ``r1^T r2``."""
    rel = r1.transpose(-1, -2) @ r2
    cos = ((rel.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0).clamp(-1.0, 1.0)
    return torch.arccos(cos)


__all__ = ["nearest_rotation", "register", "rotation_angle", "transform"]
