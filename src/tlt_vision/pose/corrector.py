"""The C-3PO corrector: refine detected keypoints so the posed CAD model fits the observed cloud.

For keypoints ``y + d``, registration of the CAD keypoints onto them gives ``R(d), t(d)``; the
corrector minimises the one-sided Chamfer objective ``mean_i dist(x_i, R S + t)^2`` of the observed
points ``x`` against the posed CAD surface ``S`` (exact point-to-surface distances, the limit of a
dense CAD sample) over the corrections ``d``, by gradient descent (Adam) through the registration.
The gradient is written out, not recorded by autograd: the objective's with respect to the pose
from the surface's own, then the registration's back to the keypoints (autograd's bookkeeping on
a frame's few thousand points made its poses take a third longer).
It is batched, each element on its own: an element stops after ``max_iterations`` or when it has
not improved by more than ``tolerance`` (relative) for ``patience`` iterations, and keeps its best
iterate, so the objective it returns is never above the one it started from.

:func:`refine_pose` then polishes the registered pose itself (Levenberg-Marquardt over a rotation
about the cloud's centre and a translation, each element on its own) on the same objective plus a
free-space term (the camera saw each point, so the ray just in front of it is outside the part).
Moving keypoints through a registration is slow to settle a large part's rotation: a cross
frame's can be left a fraction of a degree off, millimetres at its corners, more than the
corner-joint tolerance. And a thin tube fits almost as well from behind (the observed front surface on the
model's back one, one diameter too near), which the free-space term rules out; a second start one
tube diameter further away lets the refinement reach the right side; an end fitting, about as
long as it is wide, fitted with its axis a quarter turn off, reaches its fit from a start turned
that much. Every start of every element runs in one batch of steps. An element keeps its
corrected pose unless a refined one has a lower objective, and the model is unchanged, so a bent
tube still does not fit a straight one. The objective is a sum of squared residuals (each
point's distance to the surface, and its ray's depth inside the part), so Gauss-Newton steps
converge in a few iterations where a quasi-Newton method on the sum of the whole batch takes
several times as many, and each element stops when its step no longer gains.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from tlt_vision.cad.surface import SurfaceDistance
from tlt_vision.ops.registration import register, register_with_vjp


@dataclass(frozen=True)
class CorrectorConfig:
    max_iterations: int = 100
    step: float = 0.01  # initial Adam step, as a fraction of the part's scale
    decay: float = 0.97  # step multiplier per iteration: large moves first, then settle
    tolerance: float = 1e-4
    patience: int = 10
    refine_iterations: int = 0  # at most this many refine_pose steps per start (0: no refinement)
    points: int = 0  # the corrector fits at most this many of each cloud's points (0: all of them)


_ADAM_BETAS = (0.9, 0.999)  # torch.optim.Adam's defaults
_ADAM_EPS = 1e-8


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
    keypoint_weights: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Objective (B,), rotation and translation of the model registered onto ``keypoints``.

    ``model_keypoints`` are (K, 3), or (B, K, 3) for a batch of several models; ``keypoint_weights``
    (B, K), when given, leave out (0) keypoints that pad a model with fewer."""
    rot, t = register(model_keypoints.expand_as(keypoints), keypoints, keypoint_weights)
    d2 = surface(model_frame(observed, rot, t)).pow(2)
    m = mask.to(d2.dtype)
    return (d2 * m).sum(-1) / m.sum(-1).clamp(min=1.0), rot, t


def _chamfer_pose_gradient(
    observed: torch.Tensor, m: torch.Tensor, rot: torch.Tensor, t: torch.Tensor, surface: SurfaceDistance
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The Chamfer objective (B,) of :func:`chamfer_objective` at the pose ``rot, t`` and its
    gradients with respect to ``rot`` (B, 3, 3) and ``t`` (B, 3); ``m`` (B, N) 1 for a point."""
    arm = observed - t[..., None, :]
    sdf, grad = surface.signed_with_gradient(arm @ rot)
    count = m.sum(-1).clamp(min=1.0)
    objective = (sdf.pow(2) * m).sum(-1) / count
    # d objective / d q_i for the model-frame points q_i = (x_i - t) R.
    dq = grad * (2.0 * sdf * m / count[:, None])[..., None]
    return objective, arm.transpose(-1, -2) @ dq, -(rot @ dq.sum(1)[..., None])[..., 0]


def correct(
    observed: torch.Tensor,
    keypoints: torch.Tensor,
    surface: SurfaceDistance,
    model_keypoints: torch.Tensor,
    scale: float | torch.Tensor,
    mask: torch.Tensor | None = None,
    config: CorrectorConfig | None = None,
    keypoint_weights: torch.Tensor | None = None,
) -> Correction:
    """Correct ``keypoints`` (B, K, 3) against ``observed`` (B, N, 3); see the module docstring.

    ``scale`` (m) sizes the steps: one for the batch, or (B,) for parts of several sizes;
    ``model_keypoints`` and ``keypoint_weights`` as in :func:`chamfer_objective`."""
    cfg = config or CorrectorConfig()
    if mask is None:
        mask = torch.ones(observed.shape[:2], dtype=torch.bool, device=observed.device)
    observed, keypoints = observed.detach(), keypoints.detach()
    batch = keypoints.shape[0]
    model_keypoints = model_keypoints.to(observed.dtype).expand_as(keypoints)
    # The unknowns are in units of each element's scale, so one Adam step size fits every part.
    unit = torch.as_tensor(scale, dtype=observed.dtype).reshape(-1, 1, 1).expand(batch, 1, 1)

    points = mask.to(observed.dtype)  # 1 for a point, 0 for padding

    def objective_and_gradient(
        kp: torch.Tensor, d: torch.Tensor, rows: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The objective of the elements ``rows`` at keypoints ``kp + d * unit`` and its gradient
        with respect to ``d``, in closed form: the Chamfer term's with respect to the pose, then
        the registration's back to the keypoints."""
        weights = None if keypoint_weights is None else keypoint_weights[rows]
        rot, t, back = register_with_vjp(model_keypoints[rows], kp + d * unit[rows], weights)
        obj, d_rot, d_t = _chamfer_pose_gradient(observed[rows], points[rows], rot, t, surface.select(rows))
        return obj, back(d_rot, d_t) * unit[rows]

    with torch.no_grad():
        start, _, _ = chamfer_objective(observed, mask, keypoints, surface, model_keypoints, keypoint_weights)
    best = start.clone()
    delta = torch.zeros_like(keypoints)
    best_delta = torch.zeros_like(keypoints)
    # Adam by hand, so that each element steps, and stops, on its own: an element no longer
    # improving leaves the batch, and what a part's pose comes to does not depend on the others
    # posed with it (a frame's thirty parts no longer all run while one still improves).
    first, second = torch.zeros_like(keypoints), torch.zeros_like(keypoints)
    stale = torch.zeros(batch, dtype=torch.long)
    active = torch.arange(batch)
    iterations = 0
    for iterations in range(1, cfg.max_iterations + 1):
        d = delta[active]
        obj, grad = objective_and_gradient(keypoints[active], d, active)
        with torch.no_grad():
            improved = obj < best[active] * (1.0 - cfg.tolerance)
            better = obj < best[active]
            best_delta[active] = torch.where(better[:, None, None], d * unit[active], best_delta[active])
            best[active] = torch.where(better, obj, best[active])
            stale[active] = torch.where(improved, 0, stale[active] + 1)
            m = first[active] = _ADAM_BETAS[0] * first[active] + (1 - _ADAM_BETAS[0]) * grad
            v = second[active] = _ADAM_BETAS[1] * second[active] + (1 - _ADAM_BETAS[1]) * grad * grad
            lr = cfg.step * cfg.decay ** (iterations - 1)
            m_hat = m / (1 - _ADAM_BETAS[0] ** iterations)
            v_hat = v / (1 - _ADAM_BETAS[1] ** iterations)
            delta[active] = delta[active] - lr * m_hat / (v_hat.sqrt() + _ADAM_EPS)
            active = active[stale[active] < cfg.patience]
        if not len(active):
            break
    with torch.no_grad():
        final_kp = keypoints + best_delta
        final, rot, t = chamfer_objective(
            observed, mask, final_kp, surface, model_keypoints, keypoint_weights
        )
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


# Units of the refinement's unknowns and objective: millimetres keep the normal equations well
# scaled in float32 for parts fitted to tenths of a millimetre.
_MM = 1e-3
FREE_SPACE_STEP = 0.005  # m in front of an observed point, along its ray, that must be free
PROXIMAL = 0.01  # mm^2 of objective per mm^2 of translation from the start
LM_DAMPING = 1e-3  # Levenberg-Marquardt's first damping, relative to the normal equations' diagonal
LM_MAX_DAMPING = 1e8  # an element whose step this damped still fails has converged
LM_TOLERANCE = 1e-3  # relative decrease of a step below which an element has converged


@dataclass
class _Fit:
    """One refinement state per element: pose, the objective and its Gauss-Newton system there."""

    rot: torch.Tensor  # (B, 3, 3)
    t: torch.Tensor  # (B, 3)
    moved: torch.Tensor  # (B, 3) translation from the start, mm (the proximal term's)
    value: torch.Tensor  # (B,) objective, mm^2
    hessian: torch.Tensor  # (B, 6, 6) J^T J, unknowns (rotation about the centre rad, translation mm)
    gradient: torch.Tensor  # (B, 6) J^T r


def _residuals(
    surface: SurfaceDistance, points: torch.Tensor, rot: torch.Tensor, t: torch.Tensor, free_from: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Residuals (B, N), m, and their gradients (B, N, 3) with respect to the points' camera-frame
    position: the distance to the surface, and for the points from ``free_from`` on (the free-space
    term's) the depth inside the part. Both terms' points are measured in one call: a call's cost
    is mostly per operation, not per point."""
    sdf, grad = surface.signed_with_gradient(model_frame(points, rot, t))
    free = torch.arange(points.shape[-2]) >= free_from
    inside = sdf < 0
    sign = torch.where(free, torch.where(inside, -1.0, 0.0), torch.sign(sdf))
    res, dres = sdf * sign, grad * sign[..., None]
    return res, dres @ rot.transpose(-1, -2)  # model frame -> camera frame


def refine_pose(
    observed: torch.Tensor,
    mask: torch.Tensor,
    rot: torch.Tensor,
    t: torch.Tensor,
    surface: SurfaceDistance,
    iterations: int,
    depth_offsets: tuple[float, ...] | torch.Tensor = (0.0,),
    turns: torch.Tensor | None = None,
    use: torch.Tensor | None = None,
    trim: float | torch.Tensor = 0.0,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rotation (B, 3, 3), translation (B, 3) and Chamfer objective (B,) (that of
    :func:`chamfer_objective`) after refining ``rot, t`` (see the module docstring).

    The refinement minimises the Chamfer objective plus a free-space term by Levenberg-Marquardt
    (at most ``iterations`` steps, each element on its own), from each start in ``depth_offsets``
    (the pose pushed that far (m) away from the camera along the cloud's mean ray: a tube fitted
    from behind is one diameter too near; a tuple for every element, or a tensor (B, S) of each
    element's own), and keeps per element the pose with the lowest total, the input pose unless a
    refined one is lower. ``turns`` (B, S, 3, 3), when given, also turns each start in the model's
    own frame (``rot @ turn``, about the model's origin: an end fitting fitted with its axis a
    quarter turn off); ``use`` (B, S) leaves out the starts an element does not have.

    ``trim`` (one for the batch, or (B,)) leaves that fraction of each cloud's points, those
    farthest from the posed surface, out of the Chamfer term, in the steps and in the choice
    between starts (a trimmed least squares; the certificate's 90th percentile leaves out as many):
    a mask that takes in part of a neighbouring fitting would pull the whole fit towards it, off a
    pose its cloud certifies at. The objective returned is then the trimmed one too.
    """
    observed, rot, t = observed.detach(), rot.detach().to(observed.dtype), t.detach().to(observed.dtype)
    cloud = _Observed.of(observed, mask, trim)
    with torch.no_grad():
        best = cloud.total(surface, rot, t)
    if iterations <= 0:
        return rot, t, cloud.chamfer(surface, rot, t)
    offsets = torch.as_tensor(depth_offsets, dtype=observed.dtype)
    offsets = offsets.expand(len(rot), offsets.shape[-1]) if offsets.dim() == 1 else offsets
    if use is None:
        use = torch.ones(offsets.shape, dtype=torch.bool)
    # Every element's every start in one batch: a step costs about the same for a few rows as
    # for many (per-operation overhead), so the starts run side by side, not one after another.
    element, k = use.nonzero(as_tuple=True)
    start_rot = rot[element] if turns is None else rot[element] @ turns[element, k].to(rot.dtype)
    view = cloud.centre / torch.linalg.vector_norm(cloud.centre, dim=-1, keepdim=True).clamp(min=1e-9)
    start_t = t[element] + offsets[element, k, None] * view[element]
    r, tt, value = _levenberg_marquardt(
        cloud.rows(element), surface.select(element), start_rot, start_t, iterations
    )
    # Per element the lowest total of its starts, the input pose unless a refined one is lower.
    lowest = torch.full_like(best, float("inf")).scatter_reduce(0, element, value, "amin")
    taken = (value == lowest[element]) & (value < best[element])
    best_r, best_t = rot.clone(), t.clone()
    best_r[element[taken]], best_t[element[taken]] = r[taken], tt[taken]
    with torch.no_grad():
        return best_r, best_t, cloud.chamfer(surface, best_r, best_t)


@dataclass(frozen=True)
class _Observed:
    """The observed points of a batch and what the refinement derives from them once."""

    observed: torch.Tensor  # (B, N, 3)
    m: torch.Tensor  # (B, N) 1 for a point, 0 for padding
    count: torch.Tensor  # (B,)
    front: torch.Tensor  # (B, N, 3) FREE_SPACE_STEP in front of each point along its ray
    centre: torch.Tensor  # (B, 3)
    kept: torch.Tensor  # (B,) how many of the nearest points the Chamfer term counts (the trim)

    @classmethod
    def of(cls, observed: torch.Tensor, mask: torch.Tensor, trim: float | torch.Tensor = 0.0) -> _Observed:
        m = mask.to(observed.dtype)
        count = m.sum(-1).clamp(min=1.0)
        kept = torch.ceil(count * (1.0 - torch.as_tensor(trim, dtype=m.dtype))).clamp(min=1.0)
        # Free space: the camera saw each point, so the ray just in front of it is outside the
        # part. Without it a thin tube seen along a strip fits as well from behind (the points on
        # the far side of a tube moved one diameter towards the camera): centimetres off with a
        # sub-millimetre fit.
        ray = observed / torch.linalg.vector_norm(observed, dim=-1, keepdim=True).clamp(min=1e-9)
        centre = (observed * m[..., None]).sum(1) / count[:, None]
        return cls(observed, m, count, observed - FREE_SPACE_STEP * ray, centre, kept)

    def rows(self, rows: torch.Tensor) -> _Observed:
        fields = ("observed", "m", "count", "front", "centre", "kept")
        return _Observed(*(getattr(self, f)[rows] for f in fields))

    def chamfer(self, surface: SurfaceDistance, r: torch.Tensor, tt: torch.Tensor) -> torch.Tensor:
        d2 = surface(model_frame(self.observed, r, tt)).pow(2)
        return (d2 * _nearest(d2, self.m, self.count, self.kept)).sum(-1) / self.kept

    def total(self, surface: SurfaceDistance, r: torch.Tensor, tt: torch.Tensor) -> torch.Tensor:
        """The refinement's objective: the Chamfer one plus the free-space term."""
        inside = torch.relu(-surface.signed(model_frame(self.front, r, tt))).pow(2)
        return self.chamfer(surface, r, tt) + (inside * self.m).sum(-1) / self.count


def _nearest(d2: torch.Tensor, m: torch.Tensor, count: torch.Tensor, kept: torch.Tensor) -> torch.Tensor:
    """(B, N) 1 for each element's ``kept`` points (``m`` 1) of least ``d2``, 0 for the rest."""
    trimmed = (kept < count).nonzero()[:, 0]
    if not len(trimmed):
        return m
    # Only the trimmed elements' distances are ranked: a batch's tubes and rivets keep all.
    out = m.clone()
    valid = m[trimmed] > 0
    ranked = torch.where(valid, d2[trimmed], torch.inf).sort(-1).values
    cut = ranked.gather(-1, (kept[trimmed].long() - 1)[:, None])
    out[trimmed] = ((d2[trimmed] <= cut) & valid).to(d2.dtype)
    return out


def _levenberg_marquardt(
    cloud: _Observed, surface: SurfaceDistance, rot: torch.Tensor, t: torch.Tensor, iterations: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rotation, translation and total objective of each element after at most ``iterations``
    steps from ``rot, t`` (see :func:`refine_pose`)."""
    observed, front, centre = cloud.observed, cloud.front, cloud.centre
    # residual (m) -> its share of the objective, mm: the Chamfer term's of the points kept
    scales = ((1.0 / cloud.kept).sqrt() / _MM, (1.0 / cloud.count).sqrt() / _MM)
    # The Chamfer term's points, then the free-space term's, side by side (_residuals).
    points, free_from = torch.cat([observed, front], 1), observed.shape[1]
    arms = points - centre[:, None]
    proximal = torch.diag(torch.tensor([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], dtype=observed.dtype)) * PROXIMAL

    def fit(r: torch.Tensor, tt: torch.Tensor, moved: torch.Tensor, rows: torch.Tensor | None = None) -> _Fit:
        """The state at ``r, tt`` of every element, or of the elements ``rows`` (r, tt, moved theirs)."""

        def own(x: torch.Tensor) -> torch.Tensor:
            return x if rows is None else x[rows]

        on = surface if rows is None else surface.select(rows)
        # A slight pull to the start: along a direction the cloud leaves open (a tube along its
        # axis, its ends hidden in the fittings) the pose stays as corrected, not drifted.
        value = PROXIMAL * moved.pow(2).sum(-1)
        hessian = proximal.expand(len(r), 6, 6).clone()
        gradient = torch.cat([torch.zeros_like(moved), PROXIMAL * moved], -1)
        res, dres = _residuals(on, own(points), r, tt, free_from)
        m = own(cloud.m)
        counted = _nearest(res[:, :free_from].pow(2), m, own(cloud.count), own(cloud.kept))
        weight = torch.cat([counted.sqrt() * own(scales[0])[:, None], m.sqrt() * own(scales[1])[:, None]], -1)
        # d(residual)/d(rotation w about the centre) = -(arm x dres); d/d(translation mm) = -dres mm.
        jac = torch.cat([-torch.linalg.cross(own(arms), dres), -_MM * dres], -1) * weight[..., None]
        res = res * weight
        value = value + res.pow(2).sum(-1)
        hessian = hessian + jac.transpose(-1, -2) @ jac
        gradient = gradient + (jac * res[..., None]).sum(1)
        return _Fit(r, tt, moved, value, hessian, gradient)

    eye = torch.eye(6, dtype=torch.float64)
    state = fit(rot.clone(), t.clone(), torch.zeros_like(t))  # updated in place
    damping = torch.full_like(state.value, LM_DAMPING, dtype=torch.float64)
    done = torch.zeros_like(state.value, dtype=torch.bool)
    for _ in range(iterations):
        if bool(done.all()):
            break
        # Only the elements still converging take a step: a frame's parts settle in 3-6
        # steps, a few take all of them.
        rows = (~done).nonzero()[:, 0]
        h, g = state.hessian[rows].double(), state.gradient[rows].double()
        diag = torch.diagonal(h, dim1=-2, dim2=-1)
        # Marquardt's scaling, with a floor for a direction the cloud leaves open (a tube's
        # turn about its axis), whose diagonal is zero.
        scaled = diag + 1e-9 * diag.mean(-1, keepdim=True) + 1e-30
        step = torch.linalg.solve(h + damping[rows, None, None] * eye * scaled[..., None], -g)
        # What the step is expected to gain: the Gauss-Newton model's decrease.
        expected = -(g * step).sum(-1) - 0.5 * (step[:, None, :] @ h @ step[..., None])[:, 0, 0]
        step = step.to(observed.dtype)
        turn = _rotation(step[:, :3])
        r = turn @ state.rot[rows]
        tt = centre[rows] + (turn @ (state.t[rows] - centre[rows])[..., None])[..., 0] + step[:, 3:] * _MM
        trial = fit(r, tt, state.moved[rows] + step[:, 3:], rows)
        before = state.value[rows]
        accept = trial.value < before
        gain = (before - trial.value) / before.clamp(min=1e-30)
        taken = rows[accept]
        state.rot[taken], state.t[taken] = trial.rot[accept], trial.t[accept]
        state.moved[taken], state.value[taken] = trial.moved[accept], trial.value[accept]
        state.hessian[taken], state.gradient[taken] = trial.hessian[accept], trial.gradient[accept]
        damping[rows] = torch.where(accept, damping[rows] / 3.0, damping[rows] * 4.0)
        # Converged: a step that gained (or would gain) less than LM_TOLERANCE of the
        # objective, or one that fails however short it is made.
        small = expected < LM_TOLERANCE * state.value[rows].double()
        done[rows] = (accept & (gain < LM_TOLERANCE)) | small
        done |= damping > LM_MAX_DAMPING
    with torch.no_grad():
        return state.rot, state.t, cloud.total(surface, state.rot, state.t)


__all__ = ["Correction", "CorrectorConfig", "chamfer_objective", "correct", "refine_pose"]
