"""The depth camera's noise: the window median, what noise it leaves, and where a part is out of
the certificate's reach."""

import math

import numpy as np
import pytest

from tlt_vision.depth_noise import EXACT, DepthNoise, window_median, with_noise


def test_window_median_takes_only_the_valid_pixels_in_its_square_hand_computed():
    depth = np.arange(25, dtype=np.float32).reshape(5, 5)
    valid = np.ones((5, 5), dtype=bool)
    valid[1, 1] = False  # the 6 is not the part's
    # Centre (2, 2), 3x3: 7 8 11 12 13 16 17 18 -> median 12.5.
    # Corner (0, 0), 3x3: only 0 1 5 lie in the image and 6 is not valid -> median 1.
    got = window_median(depth, valid, np.array([2, 0]), np.array([2, 0]), 3)
    assert got.tolist() == [12.5, 1.0]
    # A window of 1 is the pixel itself.
    assert window_median(depth, valid, np.array([3]), np.array([4]), 1).tolist() == [19.0]


def test_what_noise_is_left_and_the_certificates_allowance_hand_computed():
    noise = DepthNoise(fraction=0.01, window=5)
    # 1 % of 1 m, over 25 pixels' median: 10 mm * sqrt(pi / 2) / 5 = 2.507 mm; its 90th
    # percentile distance 1.645 times that.
    assert noise.residual(1.0) == pytest.approx(0.01 * math.sqrt(math.pi / 2) / 5)
    assert noise.allowance(1.0) == pytest.approx(1.6449 * 0.0025066, rel=1e-4)
    assert noise.allowance(0.5) == pytest.approx(noise.allowance(1.0) / 2)
    assert EXACT.exact and EXACT.allowance(3.0) == 0.0


def test_added_noise_is_the_fraction_of_each_pixels_depth_and_no_depth_stays_none():
    depth = np.full((200, 200), 2.0, dtype=np.float32)
    depth[:10] = 0.0
    noisy = with_noise(depth, 0.01, np.random.default_rng(0))
    assert noisy.dtype == np.float32 and (noisy[:10] == 0).all()
    assert np.std(noisy[10:]) == pytest.approx(0.02, rel=0.05)
    assert np.mean(noisy[10:]) == pytest.approx(2.0, abs=0.001)


def test_the_median_leaves_more_of_a_noise_neighbouring_pixels_share():
    """Measured against independent noise's; none shared, the same."""
    from scipy import ndimage

    from tlt_common.pixel_noise import correlated_field
    from tlt_vision.depth_noise import median_share

    assert median_share(0.0, 5) == 1.0
    assert 1.0 < median_share(0.7, 5) < median_share(2.0, 5) < 5 / 1.2533
    # A fresh field: the median of 5 x 5 leaves the measured share over independent noise's.
    rng = np.random.default_rng(11)
    white = rng.standard_normal((300, 300))
    shared = ndimage.median_filter(correlated_field(white, 2.0), 5).std()
    independent = ndimage.median_filter(white, 5).std()
    assert shared / independent == pytest.approx(median_share(2.0, 5), rel=0.1)


def test_the_configured_noise_reaches_the_clouds_the_certificates_and_the_bend_cut_camera_by_camera():
    from tlt_common.config_schema import ConfigError, load_yaml
    from tlt_vision.node_config import DEFAULT_CONFIG, config_from_dict

    raw = load_yaml(DEFAULT_CONFIG)
    shipped = config_from_dict(raw)
    assert shipped.depth_noise.exact  # a camera named nowhere
    # Each shipped camera's is a stereo camera's, growing with the depth's square.
    zed = shipped.depth_noise_of("zed_1")
    assert zed.fraction == 0 and zed.sigma(2.0) == pytest.approx(4 * zed.sigma(1.0))
    # Its noise is shared by neighbouring pixels: the median leaves more of it, the more so the
    # more pixels of the frame the sharing spans.
    coarse, fine = shipped.depth_noise_of("zed_1", 171.0), shipped.depth_noise_of("zed_1", 514.0)
    assert zed.shared == 1.0 < coarse.shared < fine.shared
    assert fine.residual(1.0) > coarse.residual(1.0) > zed.residual(1.0)
    assert shipped.with_exact_depth().depth_noise_of("zed_1").exact
    raw["depth_noise"] = {"fraction": 0.005, "cameras": {"ars_x/d405_a": 0.001}}
    config = config_from_dict(raw)
    assert config.depth_noise == DepthNoise(fraction=0.005, window=5, max_allowance=0.02)
    assert config.pipeline_options["depth_noise"] == config.depth_noise
    assert config.depth_split.depth_noise == config.depth_noise
    assert config.depth_noise_of("zed_1") == config.depth_noise
    assert config.depth_noise_of("ars_x/d405_a") == DepthNoise(fraction=0.001, window=5, max_allowance=0.02)
    raw["depth_noise"]["cameras"] = {"zed_1": {"per_m2": 0.008}}
    assert config_from_dict(raw).depth_noise_of("zed_1").sigma(2.0) == pytest.approx(0.032)
    raw["depth_noise"]["cameras"] = {"zed_1": {"per_m2": 0.008, "focal": 500}}
    with pytest.raises(ConfigError, match=r"depth_noise\.cameras\.zed_1.*unknown keys"):
        config_from_dict(raw)
    raw["depth_noise"]["cameras"] = {"zed_1": {"per_m2": -1}}
    with pytest.raises(ConfigError, match=r"depth_noise\.cameras\.zed_1.*per_m2"):
        config_from_dict(raw)
    raw["depth_noise"]["cameras"] = {"d405": 0.001}  # an alias is not a camera's name
    with pytest.raises(ConfigError, match=r"depth_noise\.cameras\.d405.*unknown camera"):
        config_from_dict(raw)
