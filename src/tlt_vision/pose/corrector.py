"""The C-3PO corrector: refine detected keypoints so the posed CAD model fits the observed cloud.

For keypoints ``y + d``, registration of the CAD keypoints onto them gives ``R(d), t(d)``; the
corrector minimises the one-sided Chamfer objective ``mean_i dist(x_i, R S + t)^2`` of the observed
points ``x`` against the posed CAD surface ``S`` (exact point-to-surface distances, the limit of a
dense CAD sample) over the corrections ``d``, by gradient descent (Adam) through the registration.
It is batched, stops after ``max_iterations`` or when no element improved by more than
``tolerance`` (relative) for ``patience`` iterations, and keeps each element's best iterate, so
the objective it returns is never above the one it started from.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from tlt_vision.cad.surface import SurfaceDistance
from tlt_vision.ops.registration import register


@dataclass(frozen=True)
class CorrectorConfig:
    max_iterations: int = 100
    step: float = 0.01  # initial Adam step, as a fraction of the part's scale
    decay: float = 0.97  # step multiplier per iteration: large moves first, then settle
    tolerance: float = 1e-4
    patience: int = 10


@dataclass(frozen=True)
class Correction:
    keypoints: torch.Tensor  # (B, K, 3) corrected
    rotation: torch.Tensor  # (B, 3, 3)
    translation: torch.Tensor  # (B, 3)
    objective_before: torch.Tensor  # (B,) mean squared nearest distance, m^2
    objective_after: torch.Tensor  # (B,)
    iterations: int


def model_frame(points: torch.Tensor, rot: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Camera-frame points (B, N, 3) expressed in the frame of a model posed at ``R, t``."""
    return (points - t[..., None, :]) @ rot


def chamfer_objective(
    observed: torch.Tensor,
    mask: torch.Tensor,
    keypoints: torch.Tensor,
    surface: SurfaceDistance,
    model_keypoints: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Objective (B,), rotation and translation of the model registered onto ``keypoints``."""
    rot, t = register(model_keypoints.expand_as(keypoints), keypoints)
    d2 = surface(model_frame(observed, rot, t)).pow(2)
    m = mask.to(d2.dtype)
    return (d2 * m).sum(-1) / m.sum(-1).clamp(min=1.0), rot, t


def correct(
    observed: torch.Tensor,
    keypoints: torch.Tensor,
    surface: SurfaceDistance,
    model_keypoints: torch.Tensor,
    scale: float,
    mask: torch.Tensor | None = None,
    config: CorrectorConfig | None = None,
) -> Correction:
    """Correct ``keypoints`` (B, K, 3) against ``observed`` (B, N, 3); see the module docstring."""
    cfg = config or CorrectorConfig()
    if mask is None:
        mask = torch.ones(observed.shape[:2], dtype=torch.bool, device=observed.device)
    observed, keypoints = observed.detach(), keypoints.detach()
    model_keypoints = model_keypoints.to(observed.dtype)
    delta = torch.zeros_like(keypoints, requires_grad=True)
    opt = torch.optim.Adam([delta], lr=cfg.step * scale)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, gamma=cfg.decay)
    with torch.no_grad():
        start, _, _ = chamfer_objective(observed, mask, keypoints, surface, model_keypoints)
    best = start.clone()
    best_delta = torch.zeros_like(keypoints)
    stale = 0
    iterations = 0
    for iterations in range(1, cfg.max_iterations + 1):  # noqa: B007 (the count is reported)
        opt.zero_grad()
        obj, _, _ = chamfer_objective(observed, mask, keypoints + delta, surface, model_keypoints)
        obj.sum().backward()
        with torch.no_grad():
            improved = obj < best * (1.0 - cfg.tolerance)
            better = obj < best
            best_delta[better] = delta.detach()[better]
            best = torch.where(better, obj.detach(), best)
            stale = 0 if bool(improved.any()) else stale + 1
        if stale >= cfg.patience:
            break
        opt.step()
        sched.step()
    with torch.no_grad():
        final_kp = keypoints + best_delta
        final, rot, t = chamfer_objective(observed, mask, final_kp, surface, model_keypoints)
    return Correction(final_kp, rot, t, start, final, iterations)


__all__ = ["Correction", "CorrectorConfig", "chamfer_objective", "correct"]
