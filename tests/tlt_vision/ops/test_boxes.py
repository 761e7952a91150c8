import math

import pytest
import torch

from tlt_vision.ops.boxes import BoxCoder, box_area, box_iou, clip_boxes


def test_iou_hand_computed():
    a = torch.tensor([[0.0, 0.0, 2.0, 2.0]])
    b = torch.tensor([[1.0, 1.0, 3.0, 3.0], [2.0, 2.0, 4.0, 4.0], [0.0, 0.0, 2.0, 2.0], [0.0, 0.0, 1.0, 2.0]])
    iou = box_iou(a, b)
    # overlap 1 of union 4 + 4 - 1; touching corners; identical; half contained.
    assert iou[0].tolist() == pytest.approx([1 / 7, 0.0, 1.0, 0.5])


def test_iou_of_empty_boxes_is_zero_not_nan():
    z = torch.tensor([[1.0, 1.0, 1.0, 1.0]])
    assert box_iou(z, z).item() == 0.0
    assert box_area(torch.tensor([[2.0, 0.0, 1.0, 3.0]])).item() == 0.0


def test_clip():
    out = clip_boxes(torch.tensor([[-5.0, -1.0, 30.0, 8.0]]), height=10, width=20)
    assert out.tolist() == [[0.0, 0.0, 20.0, 8.0]]


def test_encode_hand_computed():
    coder = BoxCoder(weights=(10.0, 10.0, 5.0, 5.0))
    ref = torch.tensor([[0.0, 0.0, 10.0, 20.0]])  # centre (5, 10), w 10, h 20
    tgt = torch.tensor([[2.0, 4.0, 22.0, 24.0]])  # centre (12, 14), w 20, h 20
    d = coder.encode(tgt, ref)
    assert d[0].tolist() == pytest.approx([10 * 7 / 10, 10 * 4 / 20, 5 * math.log(2.0), 0.0])


def test_decode_inverts_encode():
    torch.manual_seed(0)
    ref = torch.rand(50, 2) * 100
    ref = torch.cat([ref, ref + 1 + torch.rand(50, 2) * 50], dim=1)
    tgt = torch.rand(50, 2) * 100
    tgt = torch.cat([tgt, tgt + 1 + torch.rand(50, 2) * 50], dim=1)
    coder = BoxCoder(weights=(10.0, 10.0, 5.0, 5.0))
    assert torch.allclose(coder.decode(coder.encode(tgt, ref), ref), tgt, atol=1e-3)


def test_decode_clamps_huge_scale():
    coder = BoxCoder()
    out = coder.decode(torch.tensor([[0.0, 0.0, 1e6, 1e6]]), torch.tensor([[0.0, 0.0, 16.0, 16.0]]))
    assert torch.isfinite(out).all()
    assert out[0, 2] - out[0, 0] == pytest.approx(1000.0, rel=1e-4)
