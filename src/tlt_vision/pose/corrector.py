"""The C-3PO corrector: refine detected keypoints so the posed CAD model fits the observed cloud.

For keypoints ``y + d``, registration of the CAD keypoints onto them gives ``R(d), t(d)``; the
corrector minimises the one-sided Chamfer objective ``mean_i dist(x_i, R S + t)^2`` of the observed
points ``x`` against the posed CAD surface ``S`` (exact point-to-surface distances, the limit of a
dense CAD sample) over the corrections ``d``, by gradient descent (Adam) through the registration.
It is batched, stops after ``max_iterations`` or when no element improved by more than
``tolerance`` (relative) for ``patience`` iterations, and keeps each element's best iterate, so
the objective it returns is never above the one it started from.

:func:`refine_pose` then polishes the registered pose itself (L-BFGS over a rotation about the
cloud's centre and a translation) on the same objective plus a free-space term (the camera saw
each point, so the ray just in front of it is outside the part). Moving keypoints through a
registration is slow to settle a large part's rotation: a cross frame's was left a fraction of a
degree off, 5-8 mm at its corners, more than the corner-joint tolerance. And a thin tube fits
almost as well from behind (the observed front surface on the model's back one, one diameter too
near), which the free-space term rules out; a second start one tube diameter further away lets
the refinement reach the right side. An element keeps its corrected pose unless a refined one has
a lower objective, and the model is unchanged, so a bent tube still does not fit a straight one.
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
    refine_iterations: int = 0  # L-BFGS iterations of refine_pose after the correction (0: none)


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


def _rotation(w: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (B, 3, 3) of axis-angle vectors (B, 3), differentiable at zero."""
    z = torch.zeros_like(w[:, 0])
    k = torch.stack(
        [
            torch.stack([z, -w[:, 2], w[:, 1]], -1),
            torch.stack([w[:, 2], z, -w[:, 0]], -1),
            torch.stack([-w[:, 1], w[:, 0], z], -1),
        ],
        -2,
    )
    return torch.linalg.matrix_exp(k)


# Units of the refinement's unknowns and objective: millimetres keep L-BFGS's tolerances and the
# float32 objective well scaled for parts fitted to tenths of a millimetre.
_MM = 1e-3
FREE_SPACE_STEP = 0.005  # m in front of an observed point, along its ray, that must be free
PROXIMAL = 0.01  # mm^2 of objective per mm^2 of translation from the start


def refine_pose(
    observed: torch.Tensor,
    mask: torch.Tensor,
    rot: torch.Tensor,
    t: torch.Tensor,
    surface: SurfaceDistance,
    iterations: int,
    depth_offsets: tuple[float, ...] = (0.0,),
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rotation (B, 3, 3), translation (B, 3) and Chamfer objective (B,) (that of
    :func:`chamfer_objective`) after refining ``rot, t`` (see the module docstring).

    The refinement minimises the Chamfer objective plus a free-space term, from each start in
    ``depth_offsets`` (the pose pushed that far (m) away from the camera along the cloud's mean
    ray: a tube fitted from behind is one diameter too near), and keeps per element the pose with
    the lowest total, the input pose unless a refined one is lower.
    """
    observed, rot, t = observed.detach(), rot.detach().to(observed.dtype), t.detach().to(observed.dtype)
    m = mask.to(observed.dtype)
    count = m.sum(-1).clamp(min=1.0)
    centre = (observed * m[..., None]).sum(1) / count[:, None]
    # Free space: the camera saw each point, so the ray just in front of it is outside the part.
    # Without it a thin tube seen along a strip fits as well from behind (the points on the far
    # side of a tube moved one diameter towards the camera), 2.4 cm off with a sub-millimetre fit.
    ray = observed / torch.linalg.vector_norm(observed, dim=-1, keepdim=True).clamp(min=1e-9)
    front = observed - FREE_SPACE_STEP * ray
    view = centre / torch.linalg.vector_norm(centre, dim=-1, keepdim=True).clamp(min=1e-9)

    def chamfer(r: torch.Tensor, tt: torch.Tensor) -> torch.Tensor:
        return (surface(model_frame(observed, r, tt)).pow(2) * m).sum(-1) / count

    def total(r: torch.Tensor, tt: torch.Tensor) -> torch.Tensor:
        inside = torch.relu(-surface.signed(model_frame(front, r, tt))).pow(2)
        return chamfer(r, tt) + (inside * m).sum(-1) / count

    with torch.no_grad():
        best = total(rot, t)
    best_r, best_t = rot.clone(), t.clone()
    if iterations <= 0:
        return rot, t, chamfer(rot, t)
    for offset in depth_offsets:
        r0, t0 = rot, t + offset * view
        w = torch.zeros_like(t, requires_grad=True)
        d = torch.zeros_like(t, requires_grad=True)

        def pose(w: torch.Tensor, d: torch.Tensor, r0=r0, t0=t0) -> tuple[torch.Tensor, torch.Tensor]:
            turn = _rotation(w)
            return turn @ r0, centre + (turn @ (t0 - centre)[..., None])[..., 0] + d * _MM

        opt = torch.optim.LBFGS(
            [w, d], lr=1.0, max_iter=iterations, line_search_fn="strong_wolfe", tolerance_change=1e-9
        )

        def closure(opt=opt, w=w, d=d, pose=pose) -> torch.Tensor:
            opt.zero_grad()
            # Elements are independent: the sum's minimiser is every element's own.
            # A slight pull to the start: along a direction the cloud leaves open (a tube along
            # its axis, its ends hidden in the fittings) the pose stays as corrected, not drifted.
            value = total(*pose(w, d)).sum() / _MM**2 + PROXIMAL * d.pow(2).sum()
            value.backward()
            return value

        opt.step(closure)
        with torch.no_grad():
            r, tt = pose(w, d)
            value = total(r, tt)
            better = value < best
            best = torch.where(better, value, best)
            best_r[better], best_t[better] = r[better], tt[better]
    with torch.no_grad():
        return best_r, best_t, chamfer(best_r, best_t)


__all__ = ["Correction", "CorrectorConfig", "chamfer_objective", "correct", "refine_pose"]
