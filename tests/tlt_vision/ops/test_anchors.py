import pytest
import torch

from tlt_vision.ops.anchors import base_anchors, grid_anchors, pyramid_anchors


def test_base_anchors_area_and_ratio():
    a = base_anchors(32.0, [0.5, 1.0, 2.0])
    w = a[:, 2] - a[:, 0]
    h = a[:, 3] - a[:, 1]
    assert (w * h).tolist() == pytest.approx([1024.0] * 3)
    assert (h / w).tolist() == pytest.approx([0.5, 1.0, 2.0])
    assert a[1].tolist() == pytest.approx([-16.0, -16.0, 16.0, 16.0])


def test_grid_anchors_hand_computed():
    a = grid_anchors((2, 3), stride=8, size=16.0, ratios=[1.0])
    assert a.shape == (6, 4)
    # Row 0, column 2: centre (2.5 * 8, 0.5 * 8) = (20, 4).
    assert a[2].tolist() == pytest.approx([12.0, -4.0, 28.0, 12.0])
    # Row 1, column 0: centre (4, 12).
    assert a[3].tolist() == pytest.approx([-4.0, 4.0, 12.0, 20.0])


def test_pyramid_levels():
    levels = pyramid_anchors([(8, 8), (4, 4)], [4, 8], [16.0, 32.0], [0.5, 1.0, 2.0])
    assert [lv.shape[0] for lv in levels] == [8 * 8 * 3, 4 * 4 * 3]
    with pytest.raises(ValueError):
        pyramid_anchors([(8, 8)], [4, 8], [16.0], [1.0])
    assert torch.isfinite(levels[0]).all()
