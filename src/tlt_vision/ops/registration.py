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

from collections.abc import Callable
from dataclasses import dataclass

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


def _polar_backward(u: torch.Tensor, s: torch.Tensor, v: torch.Tensor, grad_q: torch.Tensor) -> torch.Tensor:
    """The gradient with respect to ``H`` from that with respect to its nearest rotation ``Q``,
    given :func:`_polar_parts` of ``H``."""
    # dQ = U' A V^T with A_ij = (U'^T dH V)_ij - (.)_ji over (s'_i + s'_j); the adjoint follows.
    gamma = u.transpose(-1, -2) @ grad_q @ v
    denom = s[..., :, None] + s[..., None, :]
    floor = 1e-6 * s[..., :1, None].abs().clamp(min=1e-12)
    denom = torch.maximum(denom, floor)
    k = (gamma - gamma.transpose(-1, -2)) / denom
    return u @ k @ v.transpose(-1, -2)


class _NearestRotation(torch.autograd.Function):
    """Nearest rotation ``Q = U D V^T`` to a 3x3 matrix ``H`` (batched), with a bounded backward."""

    @staticmethod
    def forward(ctx, h: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        u, s, v = _polar_parts(h)
        ctx.save_for_backward(u, s, v)
        return u @ v.transpose(-1, -2)

    @staticmethod
    def backward(ctx, grad_q: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        return _polar_backward(*ctx.saved_tensors, grad_q)


def nearest_rotation(h: torch.Tensor) -> torch.Tensor:
    """The proper rotation nearest (Frobenius) to each 3x3 matrix ``h`` (..., 3, 3)."""
    return _NearestRotation.apply(h)


@dataclass(frozen=True)
class _Moments:
    """What registration reads of two corresponding point sets."""

    w: torch.Tensor  # (..., K, 1) weights summing to one
    ca: torch.Tensor  # (..., 3) weighted centroids
    cb: torch.Tensor
    arms: torch.Tensor  # (..., K, 3) w_k (a_k - ca)
    h: torch.Tensor  # (..., 3, 3) sum_k w_k (a_k - ca)(b_k - cb)^T

    @classmethod
    def of(cls, a: torch.Tensor, b: torch.Tensor, weights: torch.Tensor | None) -> _Moments:
        if a.shape != b.shape:
            raise ValueError(f"point sets differ in shape: {tuple(a.shape)} and {tuple(b.shape)}")
        if weights is None:
            weights = torch.ones(a.shape[:-1], dtype=a.dtype, device=a.device)
        wsum = weights.sum(-1, keepdim=True)
        if bool((wsum <= 0).any()):
            raise ValueError("registration weights sum to zero")
        w = (weights / wsum)[..., None]
        ca, cb = (w * a).sum(-2), (w * b).sum(-2)
        arms = w * (a - ca[..., None, :])
        return cls(w, ca, cb, arms, arms.transpose(-1, -2) @ (b - cb[..., None, :]))


def register(
    a: torch.Tensor, b: torch.Tensor, weights: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """``R`` (..., 3, 3), ``t`` (..., 3) with ``R a_i + t ~ b_i``; ``a``, ``b`` are (..., K, 3).

    ``weights`` (..., K) are non-negative; they need not sum to one but must not all be zero.
    With fewer than three non-collinear points the rotation about the points' line is arbitrary
    (but still a proper rotation); with one point it is arbitrary and ``t`` moves the point.
    """
    m = _Moments.of(a, b, weights)
    rot = nearest_rotation(m.h).transpose(-1, -2)
    return rot, m.cb - (rot @ m.ca[..., None])[..., 0]


def register_with_vjp(
    a: torch.Tensor, b: torch.Tensor, weights: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor, Callable[[torch.Tensor, torch.Tensor], torch.Tensor]]:
    """:func:`register`'s ``R, t``, and a function from the gradients of a scalar with respect to
    them to its gradient with respect to ``b``, written out, not recorded by autograd: the
    corrector asks for it at every step, where autograd's bookkeeping cost more than the sums."""
    with torch.no_grad():
        m = _Moments.of(a, b, weights)
        u, s, v = _polar_parts(m.h)
        rot = (u @ v.transpose(-1, -2)).transpose(-1, -2)
        t = m.cb - (rot @ m.ca[..., None])[..., 0]

    def vjp(grad_rot: torch.Tensor, grad_t: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            # t = cb - R ca: its gradient reaches R, and b through the centroid cb.
            grad_q = (grad_rot - grad_t[..., :, None] * m.ca[..., None, :]).transpose(-1, -2)
            # H = sum_k arms_k (b_k - cb)^T, and the arms sum to zero: cb's share in H vanishes.
            return m.arms @ _polar_backward(u, s, v, grad_q) + m.w * grad_t[..., None, :]

    return rot, t, vjp


def transform(points: torch.Tensor, rot: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """``R p + t`` for points (..., N, 3), ``R`` (..., 3, 3), ``t`` (..., 3)."""
    return points @ rot.transpose(-1, -2) + t[..., None, :]


def rotation_angle(r1: torch.Tensor, r2: torch.Tensor) -> torch.Tensor:
    """Angle (rad) of the relative rotation ``r1^T r2``."""
    rel = r1.transpose(-1, -2) @ r2
    cos = ((rel.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0).clamp(-1.0, 1.0)
    return torch.arccos(cos)


__all__ = ["nearest_rotation", "register", "rotation_angle", "transform"]
