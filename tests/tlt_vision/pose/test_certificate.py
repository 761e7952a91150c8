import math

import numpy as np
import pytest
import torch

from tlt_vision.cad.models import build_models
from tlt_vision.cad.views import synthetic_view
from tlt_vision.ops.registration import transform
from tlt_vision.pose.certificate import certify
from tlt_vision.pose.corrector import model_frame

LENGTHS = {"cross_frame_side": 0.75, "vertical": 0.75, "diagonal": 1.06066}


@pytest.fixture(scope="module")
def models():
    return build_models(0.75, LENGTHS)


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _cert(model, obs, rot, t, threshold):
    o = torch.tensor(obs, dtype=torch.float32)
    r = torch.tensor(rot, dtype=torch.float32)
    tt = torch.tensor(t, dtype=torch.float32)
    dist = model.surface(model_frame(o[None], r[None], tt[None]))[0]
    kp = transform(torch.tensor(model.keypoints, dtype=torch.float32), r, tt)
    return certify(o, dist, kp, model.visibility, threshold)


def test_p90_hand_computed(models):
    m = models["rivet"]
    kp = torch.tensor(m.keypoints, dtype=torch.float32)
    obs = kp[:1].repeat(10, 1)  # every point on keypoint end_a: its group is visible
    dist = torch.arange(10, dtype=torch.float32) / 1000.0  # 0..9 mm
    c = certify(obs, dist, kp, m.visibility, 0.0085)
    # 90th percentile, linear interpolation: position 0.9 * 9 = 8.1 -> 8.1 mm <= 8.5 mm.
    assert c.chamfer_p90 == pytest.approx(0.0081)
    assert c.certified and c.reason == ""
    c2 = certify(obs, dist, kp, m.visibility, 0.008)
    assert not c2.certified and "8.1 mm > threshold 8.0 mm" in c2.reason


def test_an_allowance_for_the_depths_noise_grows_the_threshold_in_quadrature(models):
    m = models["rivet"]
    kp = torch.tensor(m.keypoints, dtype=torch.float32)
    obs = kp[:1].repeat(10, 1)
    dist = torch.arange(10, dtype=torch.float32) / 1000.0  # p90 8.1 mm, as above
    assert not certify(obs, dist, kp, m.visibility, 0.006).certified
    # hypot(6, 6) = 8.49 mm: what the certificate was judged against is what it reports.
    c = certify(obs, dist, kp, m.visibility, 0.006, allowance=0.006)
    assert c.certified and c.chamfer_threshold == pytest.approx(math.hypot(0.006, 0.006))
    c2 = certify(obs, dist, kp, m.visibility, 0.006, allowance=0.005)  # hypot: 7.8 mm
    assert not c2.certified and "8.1 mm > threshold 7.8 mm" in c2.reason


def test_true_pose_certified_wrong_pose_rejected(models):
    m = models["strut_tube/vertical"]
    rot, t = _rx(1.2), np.array([0.02, -0.05, 1.0])
    obs = synthetic_view(m, rot, t, 500, np.random.default_rng(0), noise=0.001)
    good = _cert(m, obs, rot, t, 0.01)
    assert good.certified, good.reason
    assert good.keypoint_groups_visible == 2
    wrong = _cert(m, obs, _rx(1.2 + math.radians(10)), t, 0.01)
    assert not wrong.certified
    assert "not observably correct" in wrong.reason
    assert wrong.chamfer_p90 > 0.01


def test_degenerate_partial_view_rejected(models):
    m = models["strut_tube/vertical"]
    rot, t = _rx(1.2), np.array([0.02, -0.05, 1.0])
    obs = synthetic_view(m, rot, t, 500, np.random.default_rng(0), noise=0.001)
    axis = rot[:, 2]
    half = obs[(obs - t) @ axis < 0.0]  # only the half of the tube towards end a
    c = _cert(m, half, rot, t, 0.01)
    assert c.chamfer_p90 < 0.01  # the points fit ...
    assert not c.certified  # ... but half a tube does not fix its position along the axis
    assert c.keypoint_groups_visible == 1 and "degenerate view" in c.reason


def test_empty_cloud_not_certified(models):
    m = models["rivet"]
    c = certify(torch.zeros(0, 3), torch.zeros(0), torch.zeros(2, 3), m.visibility, 0.003)
    assert not c.certified and c.reason == "no observed points"
