import numpy as np
import pytest
import torch

from tlt_vision.cad.models import build_models
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
