"""Tag pose on synthetic images: a 36h11 tag warped into a camera image at a known pose."""

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from tlt_vision.apriltag import CELLS, TagConfig, TagLocator, dispenser_tag_ids, tag_object_points

ROOT = Path(__file__).resolve().parents[2]
W, H = 640, 480
K = np.array([[600.0, 0.0, (W - 1) / 2], [0.0, 600.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
PRINTED = 0.16
SIDE = PRINTED * CELLS / (CELLS + 2)


FACING = np.diag([1.0, -1.0, -1.0])  # tag x right, y up, z towards a camera looking along +z


def _rot(rx: float, ry: float, rz: float) -> np.ndarray:
    """A tag facing the camera, tilted by the rotation vector (rx, ry, rz)."""
    return FACING @ cv2.Rodrigues(np.array([rx, ry, rz], dtype=np.float64))[0]


def render_tag(tag_id: int, rot: np.ndarray, t: np.ndarray, supersample: int = 4) -> np.ndarray:
    """Camera image of the printed tag (quiet zone included) with its centre at ``t``.

    The printed square is mapped by the plane homography K [r1 r2 t] at ``supersample`` times the
    resolution, then area-averaged down: each pixel integrates the light falling on it.
    """
    ppc = 32
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    marker = cv2.aruco.generateImageMarker(d, tag_id, CELLS * ppc, borderBits=1)
    tag = cv2.copyMakeBorder(marker, ppc, ppc, ppc, ppc, cv2.BORDER_CONSTANT, value=255)
    p = tag.shape[0]
    s = PRINTED / p  # metres per tag pixel
    # Tag pixel (u, v) -> tag plane (x right, y up), pixel centres at integers.
    a = np.array([[s, 0.0, 0.5 * s - PRINTED / 2], [0.0, -s, PRINTED / 2 - 0.5 * s], [0.0, 0.0, 1.0]])
    k_hi = K.copy()
    k_hi[:2] *= supersample
    k_hi[0, 2] = (K[0, 2] + 0.5) * supersample - 0.5
    k_hi[1, 2] = (K[1, 2] + 0.5) * supersample - 0.5
    hmat = k_hi @ np.column_stack([rot[:, 0], rot[:, 1], t]) @ a
    big = cv2.warpPerspective(
        tag, hmat, (W * supersample, H * supersample), flags=cv2.INTER_LINEAR, borderValue=110
    )
    return cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize(
    ("tag_id", "angles", "t"),
    [
        (3, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        (0, (0.35, -0.25, 0.2), (0.06, -0.04, 1.0)),
        (5, (-0.3, 0.4, -1.0), (-0.1, 0.05, 1.0)),
    ],
)
def test_pose_at_one_metre_within_the_benchmark_goal(tag_id, angles, t):
    rot, t = _rot(*angles), np.array(t)
    img = render_tag(tag_id, rot, t)
    res = TagLocator(TagConfig(SIDE)).locate(img, tag_id, K)
    assert res.found, res.reason
    err = res.pose.translation - t
    lateral = math.hypot(err[0], err[1])
    assert lateral <= 0.001, f"lateral error {lateral * 1000:.2f} mm"
    assert abs(err[2]) <= 0.0033, f"depth error {err[2] * 1000:.2f} mm"
    assert res.pose.reprojection_error < 0.5
    truth, _ = cv2.projectPoints(tag_object_points(SIDE), cv2.Rodrigues(rot)[0], t, K, np.zeros(5))
    assert np.abs(res.pose.corners - truth.reshape(4, 2)).max() < 0.1  # px
    angle = np.degrees(np.arccos(np.clip((np.trace(res.pose.rotation.T @ rot) - 1) / 2, -1, 1)))
    assert angle < 2.0


@pytest.mark.parametrize(("noise", "blur"), [(6.0, 0.7), (3.0, 1.2)])
def test_a_real_cameras_sensor_noise_and_blur_keep_the_pose_within_the_goal(noise, blur):
    """Gaussian sensor noise (grey levels) and optical blur (1 sigma, px) on the rendered tag, as a
    real camera adds them: the edge-refined corners still hold the goal at 1 m (at 1.2 px of blur
    the depth error grows to about 2.7 mm of the 3.3 allowed)."""
    rng = np.random.default_rng(0)
    cases = [(3, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), (5, (-0.3, 0.4, -1.0), (-0.1, 0.05, 1.0))]
    for tag_id, angles, t in cases:
        rot, t = _rot(*angles), np.array(t)
        img = cv2.GaussianBlur(render_tag(tag_id, rot, t).astype(float), (0, 0), blur)
        img = np.clip(img + rng.normal(0.0, noise, img.shape), 0, 255).round().astype(np.uint8)
        res = TagLocator(TagConfig(SIDE)).locate(img, tag_id, K)
        assert res.found, res.reason
        err = res.pose.translation - t
        assert math.hypot(err[0], err[1]) <= 0.001 and abs(err[2]) <= 0.0033, err


def test_missing_tag_gives_a_reason():
    img = render_tag(2, FACING, np.array([0.0, 0.0, 1.0]))
    res = TagLocator(TagConfig(SIDE)).locate(img, 7, K)
    assert not res.found and res.reason == "tag 7 not in view (tags seen: 2)"
    blank = np.full((H, W, 3), 128, np.uint8)
    res = TagLocator(TagConfig(SIDE)).locate(blank, 0, K)
    assert not res.found and "tags seen: none" in res.reason


def test_edge_refinement_removes_the_detector_bias():
    rot, t = _rot(0.0, 0.0, 0.0), np.array([0.0, 0.0, 1.0])
    img = render_tag(1, rot, t)
    raw = TagLocator(TagConfig(SIDE, edge_refinement=False)).locate(img, 1, K)
    fine = TagLocator(TagConfig(SIDE)).locate(img, 1, K)
    assert abs(fine.pose.translation[2] - 1.0) < abs(raw.pose.translation[2] - 1.0)


def test_config_matches_the_twin_and_dispenser_ids():
    cfg = TagConfig.load()
    assert cfg.tag_side == pytest.approx(SIDE)
    twin = ROOT / "config" / "twin" / "edu.yaml"
    if twin.exists():
        assert yaml.safe_load(twin.read_text())["dispensers"]["tag_size"] == pytest.approx(PRINTED)
    assert dispenser_tag_ids(["a", "b"]) == {"a": 0, "b": 1}
