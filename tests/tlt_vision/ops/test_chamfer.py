import pytest
import torch

from tlt_vision.ops.chamfer import chamfer_one_sided, chamfer_symmetric, nearest_distances


def test_hand_computed():
    a = torch.tensor([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    b = torch.tensor([[0.0, 3.0, 0.0], [3.0, 0.0, 1.0], [10.0, 0.0, 0.0]])
    # a0: min(3, sqrt 10, 10) = 3; a1: min(sqrt 18, 1, 7) = 1.
    assert nearest_distances(a, b).tolist() == pytest.approx([3.0, 1.0])
    assert chamfer_one_sided(a, b).item() == pytest.approx(2.0)
    assert chamfer_one_sided(a, b, squared=True).item() == pytest.approx(5.0)
    # b -> a: 3, 1, 7.
    assert chamfer_symmetric(a, b).item() == pytest.approx(2.0 + 11.0 / 3.0)


def test_batched_and_masked():
    a = torch.tensor([[[0.0, 0, 0], [1.0, 0, 0]], [[0.0, 0, 0], [5.0, 0, 0]]])
    b = torch.zeros(2, 1, 3)
    mask = torch.tensor([[True, True], [True, False]])
    assert chamfer_one_sided(a, b).tolist() == pytest.approx([0.5, 2.5])
    assert chamfer_one_sided(a, b, mask=mask).tolist() == pytest.approx([0.5, 0.0])


def test_empty_reference_is_an_error():
    with pytest.raises(ValueError):
        nearest_distances(torch.zeros(3, 3), torch.zeros(0, 3))


def test_gradient_finite_at_coincident_points():
    a = torch.zeros(1, 3, requires_grad=True)
    chamfer_one_sided(a, torch.zeros(1, 3), squared=True).backward()
    assert torch.isfinite(a.grad).all()
