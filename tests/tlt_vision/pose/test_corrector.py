import numpy as np
import pytest
import torch

from tlt_vision.cad.models import build_models
from tlt_vision.cad.surface import SurfaceDistance
from tlt_vision.cad.views import random_rotation, synthetic_view
from tlt_vision.ops.registration import rotation_angle, transform
from tlt_vision.pose.corrector import CorrectorConfig, chamfer_objective, correct


@pytest.mark.parametrize("name", ["end_fitting", "corner_joint", "strut_tube/vertical"])
def test_corrector_reduces_the_objective_batched(name):
    torch.manual_seed(0)
    m = build_models(0.75, {"vertical": 0.75})[name]
    rng = np.random.default_rng(5)
    obs, kps, rots = [], [], []
    for _ in range(2):
        rot = random_rotation(rng)
        t = np.array([0.0, 0.0, 0.8])
        obs.append(torch.tensor(synthetic_view(m, rot, t, 200, rng, noise=0.0005)[:150], dtype=torch.float32))
        gt = transform(
            torch.tensor(m.keypoints, dtype=torch.float32), torch.tensor(rot).float(), torch.tensor(t).float()
        )
        kps.append(gt + torch.randn_like(gt) * 0.05 * m.diameter)
        rots.append(torch.tensor(rot, dtype=torch.float32))
    obs_b, kp_b = torch.stack(obs), torch.stack(kps)
    cfg = CorrectorConfig(max_iterations=40, step=0.02, decay=0.95)
    res = correct(
        obs_b, kp_b, m.surface, torch.tensor(m.keypoints, dtype=torch.float32), m.diameter / 2, config=cfg
    )
    assert res.iterations <= cfg.max_iterations
    assert (res.objective_after <= res.objective_before).all()
    assert (res.objective_after < 0.5 * res.objective_before).all()
    # The reported objective is the one of the returned keypoints.
    mask = torch.ones(obs_b.shape[:2], dtype=torch.bool)
    again, _, _ = chamfer_objective(obs_b, mask, res.keypoints, m.surface, torch.tensor(m.keypoints).float())
    assert torch.allclose(again, res.objective_after)
    assert torch.allclose(
        res.rotation @ res.rotation.transpose(1, 2), torch.eye(3).expand(2, 3, 3), atol=1e-5
    )
    if name == "corner_joint":  # a cube's pose is defined up to its symmetries only
        return
    # Axial parts: the axis comes back (rotation about it is not observable).
    for k in range(2):
        axis = res.rotation[k, :, 2]
        assert abs(float(axis @ rots[k][:, 2])) > np.cos(np.radians(5))
    assert rotation_angle(res.rotation[0], res.rotation[0]).item() == pytest.approx(0.0, abs=1e-3)


def test_zero_iterations_returns_the_input():
    m = build_models(0.75, {"vertical": 0.75})["rivet"]
    obs = torch.tensor(synthetic_view(m, np.eye(3), np.array([0, 0, 0.5]), 64, np.random.default_rng(0)))[
        None
    ].float()
    kp = transform(torch.tensor(m.keypoints).float(), torch.eye(3), torch.tensor([0.0, 0.0, 0.5]))[None]
    res = correct(
        obs, kp, m.surface, torch.tensor(m.keypoints).float(), 0.01, config=CorrectorConfig(max_iterations=0)
    )
    assert torch.equal(res.keypoints, kp)
    assert res.iterations == 0


def _two_parts():
    """A corner joint whose detected keypoints are close and a tube's that are far off: the
    first settles in a few iterations, the second takes many."""
    models = build_models(0.75, {"vertical": 0.75})
    names = ("corner_joint", "strut_tube/vertical")
    k = max(len(models[n].keypoints) for n in names)
    rng = np.random.default_rng(3)
    obs, kps, model_kps, surfaces, scales = [], [], [], [], []
    for name, off in zip(names, (0.02, 0.3), strict=True):
        m = models[name]
        rot, t = random_rotation(rng), np.array([0.05, -0.02, 0.9])
        obs.append(torch.tensor(synthetic_view(m, rot, t, 300, rng, noise=0.0003)[:200], dtype=torch.float32))
        model_kp = torch.zeros(k, 3)
        model_kp[: len(m.keypoints)] = torch.tensor(m.keypoints, dtype=torch.float32)
        gt = transform(model_kp, torch.tensor(rot).float(), torch.tensor(t).float())
        kps.append(gt + torch.randn(gt.shape, generator=torch.Generator().manual_seed(1)) * off * m.diameter)
        model_kps.append(model_kp)
        surfaces.append(m.surface)
        scales.append(m.diameter / 2)
    weights = torch.tensor([[1.0] * len(models[n].keypoints) + [0.0] * (k - len(models[n].keypoints))
                            for n in names])  # fmt: skip
    return torch.stack(obs), torch.stack(kps), surfaces, torch.stack(model_kps), torch.tensor(scales), weights


def test_each_element_is_corrected_as_if_alone():
    """A part's correction does not depend on what else is in the batch: it stops when it stops
    improving, not when the slowest part does."""
    obs, kps, surfaces, model_kps, scales, weights = _two_parts()
    cfg = CorrectorConfig(max_iterations=150, step=0.02, decay=0.98, patience=10)
    both = correct(obs, kps, SurfaceDistance.stacked(surfaces), model_kps, scales, config=cfg,
                   keypoint_weights=weights)  # fmt: skip
    for b in range(2):
        alone = correct(obs[b : b + 1], kps[b : b + 1], surfaces[b], model_kps[b], scales[b : b + 1],
                        config=cfg, keypoint_weights=weights[b : b + 1])  # fmt: skip
        assert torch.allclose(both.keypoints[b], alone.keypoints[0], atol=1e-6)
        assert torch.allclose(both.objective_after[b], alone.objective_after[0], rtol=1e-5)
    assert (both.objective_after < both.objective_before).all()
