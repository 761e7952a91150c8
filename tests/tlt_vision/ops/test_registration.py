import math

import pytest
import torch

from tlt_vision.ops.registration import (
    nearest_rotation,
    register,
    register_with_vjp,
    rotation_angle,
    transform,
)


def _rz(angle: float) -> torch.Tensor:
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


def test_hand_computed_quarter_turn():
    a = torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, 0]], dtype=torch.float64)
    b = torch.tensor([[0.0, 1, 0], [-1.0, 0, 0], [0, 0, 1.0], [0, 0, 0]], dtype=torch.float64) + torch.tensor(
        [1.0, 2.0, 3.0], dtype=torch.float64
    )
    rot, t = register(a, b)
    assert torch.allclose(rot, _rz(math.pi / 2), atol=1e-9)
    assert t.tolist() == pytest.approx([1.0, 2.0, 3.0])


def test_random_batch_recovers_pose():
    torch.manual_seed(1)
    q = torch.linalg.qr(torch.randn(5, 3, 3, dtype=torch.float64)).Q
    q = q * torch.det(q)[:, None, None]  # proper rotations
    t = torch.randn(5, 3, dtype=torch.float64)
    a = torch.randn(5, 7, 3, dtype=torch.float64)
    b = transform(a, q, t)
    rot, tt = register(a, b)
    assert torch.allclose(rot, q, atol=1e-9) and torch.allclose(tt, t, atol=1e-9)


def test_weights_ignore_an_outlier():
    a = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5]], dtype=torch.float64)
    b = a.clone()
    b[4] = torch.tensor([-50.0, 3.0, 9.0])
    w = torch.tensor([1.0, 1.0, 1.0, 1.0, 0.0], dtype=torch.float64)
    rot, t = register(a, b, w)
    assert torch.allclose(rot, torch.eye(3, dtype=torch.float64), atol=1e-9)
    assert torch.allclose(t, torch.zeros(3, dtype=torch.float64), atol=1e-9)


def test_reflection_is_never_returned():
    # b is a mirror image of a: the best orthogonal map is a reflection; a proper rotation comes back.
    a = torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [-1.0, -1.0, -1.0]], dtype=torch.float64)
    b = a * torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    rot, _ = register(a, b)
    assert torch.det(rot).item() == pytest.approx(1.0)
    assert torch.allclose(rot @ rot.T, torch.eye(3, dtype=torch.float64), atol=1e-9)


def test_nearest_rotation_gradient_matches_numeric_and_is_finite_when_degenerate():
    torch.manual_seed(2)
    h = torch.randn(3, 3, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(nearest_rotation, (h,))
    line = torch.tensor([[0.0, 0, -1], [0, 0, 0], [0, 0, 1]], dtype=torch.float64)
    moved = (line @ _rz(0.3).T + 1.0).requires_grad_(True)
    rot, t = register(line, moved)
    (rot.sum() + t.sum()).backward()
    assert torch.isfinite(moved.grad).all()
    assert torch.det(rot).item() == pytest.approx(1.0)


def test_the_written_out_gradient_is_the_registrations():
    # The corrector's gradient back through the registration, against autograd's,
    # weighted and batched; finite for collinear points (an axial part's keypoints).
    torch.manual_seed(3)
    a = torch.randn(4, 6, 3, dtype=torch.float64)
    b = (a @ _rz(0.4).T + 0.3 + 0.05 * torch.randn(4, 6, 3, dtype=torch.float64)).requires_grad_(True)
    weights = torch.rand(4, 6, dtype=torch.float64)
    weights[1, -2:] = 0.0  # padding keypoints of a model with fewer
    grad_rot, grad_t = torch.randn(4, 3, 3, dtype=torch.float64), torch.randn(4, 3, dtype=torch.float64)
    rot, t = register(a, b, weights)
    (expected,) = torch.autograd.grad((rot * grad_rot).sum() + (t * grad_t).sum(), b)
    rot2, t2, back = register_with_vjp(a, b.detach(), weights)
    assert torch.allclose(rot2, rot) and torch.allclose(t2, t)
    assert torch.allclose(back(grad_rot, grad_t), expected, atol=1e-10)
    assert torch.allclose(back(grad_rot, grad_t)[1, -2:], torch.zeros(2, 3, dtype=torch.float64))
    line = torch.tensor([[0.0, 0, -1], [0, 0, 0], [0, 0, 1]], dtype=torch.float64)
    _, _, back = register_with_vjp(line, line @ _rz(0.3).T + 1.0)
    ones = torch.ones(3, 3, dtype=torch.float64)
    assert torch.isfinite(back(ones, ones[0])).all()


def test_rotation_angle():
    assert rotation_angle(_rz(0.1), _rz(0.4)).item() == pytest.approx(0.3)


def test_mismatched_or_zero_weights_rejected():
    with pytest.raises(ValueError):
        register(torch.zeros(3, 3), torch.zeros(4, 3))
    with pytest.raises(ValueError):
        register(torch.ones(3, 3), torch.ones(3, 3), torch.zeros(3))
