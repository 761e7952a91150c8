import numpy as np
import pytest
import torch

from tlt_vision.cad.models import build_models
from tlt_vision.pose.detector import KeypointDetector
from tlt_vision.pose.estimator import MIN_POINTS, PoseEstimator


def test_bad_clouds_are_uncertified_with_a_reason_never_raised():
    m = build_models(0.75, {"vertical": 0.75})["rivet"]
    est = PoseEstimator(m, KeypointDetector(len(m.keypoint_names), 0.02, width=8), threshold=0.003)
    nan_cloud = np.full((100, 3), np.nan)
    out = est.estimate_batch([np.zeros((0, 3)), np.zeros((MIN_POINTS - 1, 3)), nan_cloud])
    assert len(out) == 3
    for e in out:
        assert not e.certified
        assert e.certificate.reason.startswith("too few points")
    fields = out[0].certified_pose_fields("x")
    assert fields["certified"] is False and fields["keypoint_groups_required"] == 1
    assert fields["reason"].startswith("too few points")


def test_untrained_detector_is_never_passed_off_as_good():
    torch.manual_seed(0)
    m = build_models(0.75, {"vertical": 0.75})["strut_tube/vertical"]
    est = PoseEstimator(m, KeypointDetector(len(m.keypoint_names), 0.3, width=8), threshold=0.01)
    # A flat random patch is not a tube at all.
    cloud = np.random.default_rng(0).uniform(-0.2, 0.2, size=(200, 3)) * [1, 1, 0] + [0, 0, 1]
    e = est.estimate(cloud)
    assert not e.certified and e.certificate.reason
    assert e.certified_pose_fields()["certified"] is False


def test_detector_must_match_the_model():
    m = build_models(0.75, {"vertical": 0.75})["rivet"]
    with pytest.raises(ValueError, match="keypoints"):
        PoseEstimator(m, KeypointDetector(5, 0.02, width=8), 0.003)
