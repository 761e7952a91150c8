import numpy as np
import pytest
from PIL import Image

from tlt_vision.cad.models import build_models
from tlt_vision.detections import Detection
from tlt_vision.inspection import Observation
from tlt_vision.pose.certificate import Certificate
from tlt_vision.pose.estimator import PoseEstimate
from tlt_vision.pose_picture import CERTIFIED, REFUSED, PosedFrame, projected, write_pose_picture

MODELS = build_models(0.75, {"vertical": 0.75})
K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


def _estimate(cls: str, translation, certified: bool) -> PoseEstimate:
    cert = Certificate(certified, 0.001, 0.002, 1, 1, ("body",), "" if certified else "degenerate view")
    return PoseEstimate(cls, cls, np.eye(3), np.asarray(translation, float), np.zeros((2, 3)), cert, 100, 0.0)


def test_a_posed_model_projects_onto_its_place_in_the_image():
    """A rivet (radius 6 mm, 24 mm long along z, its axis the camera's) 1 m ahead and 0.1 m right
    of the camera: its points at x 0.094-0.106 m, depths 0.988-1.012 m, project between those
    bounds' pixels."""
    uv = projected(MODELS["rivet"], np.eye(3), np.array([0.1, 0.0, 1.0]), K)
    assert len(uv) > 100
    assert uv[:, 0].min() >= 320 + 500 * 0.094 / 1.012 - 1e-6
    assert uv[:, 0].max() <= 320 + 500 * 0.106 / 0.988 + 1e-6
    assert np.all(np.abs(uv[:, 1] - 240.0) <= 500 * 0.006 / 0.988 + 1e-6)
    assert uv[:, 0].max() - uv[:, 0].min() > 5  # the whole rivet, not one point
    behind = projected(MODELS["rivet"], np.eye(3), np.array([0.0, 0.0, -1.0]), K)
    assert len(behind) == 0  # nothing behind the camera is drawn


def test_the_picture_shows_masks_and_certified_and_refused_poses(tmp_path):
    rgb = np.full((480, 640, 3), 40, dtype=np.uint8)
    mask = np.zeros((480, 640), dtype=bool)
    mask[230:250, 360:380] = True
    detections = [Detection("rivet", mask), Detection("rivet", np.zeros_like(mask))]
    observations = [
        Observation("rivet", _estimate("rivet", [0.1, 0.0, 1.0], True)),
        Observation("rivet", _estimate("rivet", [-0.2, 0.1, 1.0], False)),
        Observation("rivet", None, "empty mask: part not in view"),
    ]
    frame = PosedFrame("frame 0", rgb, K, detections, observations)
    classes = ["strut_tube", "end_fitting", "cross_frame", "corner_joint", "rivet"]
    path = write_pose_picture(tmp_path / "poses.png", [frame], MODELS, classes)
    picture = np.asarray(Image.open(path).convert("RGB")).astype(int)
    colours = picture.reshape(-1, 3)

    def near(colour) -> int:
        return int((np.abs(colours - np.array(colour) * 255).max(axis=1) < 30).sum())

    assert near(CERTIFIED) > 20 and near(REFUSED) > 20
    with pytest.raises(ValueError, match="no frame"):
        write_pose_picture(tmp_path / "none.png", [], MODELS, classes)
