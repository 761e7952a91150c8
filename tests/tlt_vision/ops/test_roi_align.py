import pytest
import torch

from tlt_vision.ops.roi_align import roi_align


def _ramp(h: int = 4, w: int = 4) -> torch.Tensor:
    """A feature map f(x, y) = x + 10 y: bilinear sampling of a linear map is exact."""
    y, x = torch.meshgrid(
        torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij"
    )
    return (x + 10 * y)[None, None]


def test_aligned_whole_map_hand_computed():
    # aligned=True: box [0, 4] starts at -0.5, bins of 2 px, samples at 0, 1 (bin 0) and 2, 3 (bin 1).
    out = roi_align(_ramp(), torch.tensor([[0.0, 0.0, 0.0, 4.0, 4.0]]), (2, 2), 1.0, 2, aligned=True)
    torch.testing.assert_close(out[0, 0], torch.tensor([[5.5, 7.5], [25.5, 27.5]]))


def test_unaligned_is_shifted_half_a_pixel():
    # aligned=False: box starts at 0, samples at 0.5, 1.5 and 2.5, 3.5; x = 3.5 reads the last column (3).
    out = roi_align(_ramp(), torch.tensor([[0.0, 0.0, 0.0, 4.0, 4.0]]), (2, 2), 1.0, 2, aligned=False)
    assert out[0, 0, 0].tolist() == pytest.approx([1.0 + 10.0, (2.5 + 3.0) / 2 + 10.0])


def test_spatial_scale_and_single_sample():
    # Box [2, 6] in image px at scale 0.5 -> [1, 3] on the map, aligned -> starts at 0.5, one bin of
    # 2 px, one sample at its centre 1.5.
    out = roi_align(_ramp(), torch.tensor([[0.0, 2.0, 2.0, 6.0, 6.0]]), (1, 1), 0.5, 1, aligned=True)
    assert out.item() == pytest.approx(1.5 + 15.0)


def test_impulse_bilinear_weights():
    f = torch.zeros(1, 1, 4, 4)
    f[0, 0, 1, 2] = 1.0
    # One sample at (x, y) = (1.75, 1.25): weights (1 - 0.25) * 0.75 on pixel (y=1, x=2).
    roi = torch.tensor([[0.0, 1.75, 1.25, 1.75, 1.25]])  # zero-size box, aligned: sample at (1.25, 0.75)
    out = roi_align(f, roi, (1, 1), 1.0, 1, aligned=False)  # unaligned: size raised to 1 -> (2.25, 1.75)
    # Sample at x = 1.75 + 0.5 = 2.25, y = 1.25 + 0.5 = 1.75: weight on (1, 2) = (1 - 0.75) * (1 - 0.25).
    assert out.item() == pytest.approx(0.25 * 0.75)


def test_outside_reads_zero_and_border_clamps():
    f = torch.ones(1, 1, 4, 4)
    far = roi_align(f, torch.tensor([[0.0, -10.0, -10.0, -8.0, -8.0]]), (1, 1), 1.0, 1)
    assert far.item() == 0.0
    # Sample at x = -0.75 (within a pixel of the border) reads the border value.
    near = roi_align(f, torch.tensor([[0.0, -0.25, 1.0, -0.25, 1.0]]), (1, 1), 1.0, 1)
    assert near.item() == 1.0


def test_batch_index_channels_and_gradient():
    f = torch.stack([_ramp()[0], 2 * _ramp()[0]]).repeat(1, 3, 1, 1).requires_grad_(True)
    rois = torch.tensor([[1.0, 0.0, 0.0, 4.0, 4.0], [0.0, 0.0, 0.0, 4.0, 4.0]])
    out = roi_align(f, rois, (2, 2), 1.0, 2)
    assert out.shape == (2, 3, 2, 2)
    torch.testing.assert_close(out[0, 2], torch.tensor([[11.0, 15.0], [51.0, 55.0]]))
    out.sum().backward()
    # Every pixel of image 0 is sampled once with weight 1/4 per output cell: 4 cells * 3 channels.
    assert f.grad[0].sum().item() == pytest.approx(4 * 3)


def test_no_rois_and_bad_sampling_ratio():
    assert roi_align(_ramp(), torch.zeros(0, 5), (7, 7)).shape == (0, 1, 7, 7)
    with pytest.raises(ValueError):
        roi_align(_ramp(), torch.zeros(1, 5), (7, 7), sampling_ratio=0)
