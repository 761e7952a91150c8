import pytest
import torch

from tlt_vision.segmentation.evaluate import average_precision, mask_ap50, mask_iou


def _mask(*cells):
    m = torch.zeros(4, 4, dtype=torch.bool)
    for r, c in cells:
        m[r, c] = True
    return m


def test_mask_iou_hand_computed():
    a = torch.stack([_mask((0, 0), (0, 1))])
    b = torch.stack([_mask((0, 1), (0, 2)), _mask((3, 3))])
    assert mask_iou(a, b).tolist() == [[pytest.approx(1 / 3), 0.0]]


def test_average_precision_hand_computed():
    # Ranked: TP, FP, TP with 3 objects: recall steps 1/3 at p=1, 2/3 at p=2/3.
    assert average_precision([True, False, True], [0.9, 0.8, 0.7], 3) == pytest.approx(1 / 3 + 1 / 3 * 2 / 3)
    assert average_precision([], [], 2) == 0.0
    with pytest.raises(ValueError):
        average_precision([True], [1.0], 0)


def test_mask_ap50_tiny_case():
    full = _mask(*[(r, c) for r in range(2) for c in range(2)])  # 4 cells top-left
    other = _mask(*[(r, c) for r in range(2, 4) for c in range(2, 4)])  # 4 cells bottom-right
    half = _mask((0, 0), (0, 1))  # IoU 0.5 with `full`: counts as a hit
    gt = [{"masks": torch.stack([full, other]), "labels": torch.tensor([1, 2])}]
    pred = [
        {
            "masks": torch.stack([half, full, other, other]),
            "labels": torch.tensor([1, 1, 2, 1]),
            "scores": torch.tensor([0.9, 0.8, 0.7, 0.95]),
        }
    ]
    res = mask_ap50(pred, gt, num_classes=5)
    # Class 1 ranked: other (0.95, miss), half (0.9, hit), full (0.8, duplicate -> miss):
    # precision 1/2 at recall 1 -> AP 0.5. Class 2: one hit -> AP 1. Classes 3-5 have no ground truth.
    assert res["per_class"] == {1: pytest.approx(0.5), 2: pytest.approx(1.0)}
    assert res["map"] == pytest.approx(0.75)
