"""The coarse-pose search (tlt_tools.coarse_pose_search): the pinhole view of a tag, the
camera views it tries, and the configurations it returns, checked against the project's own
kinematics and collision scene (the twin's rendering of the chosen poses is
tests/tlt_ars/test_coarse_poses.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from tlt_tools import coarse_pose_search as cps

from tlt_ars.planning.world import build_scene
from tlt_common.config_schema import load_yaml
from tlt_common.geometry.transforms import pose_matrix, rot_x

SMALL = cps.ViewSpec(distances=(0.32, 0.36), rolls=12, azimuths=4)


@pytest.fixture(scope="module")
def setup():
    return cps.Setup.load(cps.DEFAULT_MISSION)


def test_the_camera_model_is_the_twins_d405():
    edu = load_yaml("config/twin/edu.yaml")["cameras"]
    frame = load_yaml("config/twin/run.yaml")["cameras"]["d405"]
    assert pytest.approx(edu["d405_fovy_deg"]) == cps.D405_FOVY_DEG
    assert pytest.approx(frame["width"] / frame["height"]) == cps.D405_ASPECT


def test_a_centred_head_on_tag_keeps_the_margin_the_pinhole_model_gives():
    spec = cps.ViewSpec()
    tag = np.eye(4)
    d, side = 0.4, 0.16
    camera = pose_matrix((0.0, 0.0, d), rot_x(math.pi))  # looking down -z at the tag
    half_v = side / 2 / d / (2 * math.tan(math.radians(spec.fovy_deg) / 2))
    assert cps.image_margin(camera, tag, side, spec) == pytest.approx(0.5 - half_v)
    off = pose_matrix((0.5, 0.0, d), rot_x(math.pi))  # tag far to one side: outside the image
    assert cps.image_margin(off, tag, side, spec) < 0
    behind = pose_matrix((0.0, 0.0, -d), rot_x(math.pi))
    assert cps.image_margin(behind, tag, side, spec) == -math.inf


def test_every_view_looks_at_the_tag_centre_from_its_distance_within_the_tilt():
    spec = cps.ViewSpec(distances=(0.3, 0.4), rolls=6)
    tag = pose_matrix((1.0, -2.0, 0.5), rot_x(0.3))
    views = list(cps.camera_views(tag, spec))
    assert len(views) == 2 * 6 * (1 + 2 * spec.azimuths)
    for cam, d, tilt in views:
        r = cam[:3, :3]
        assert np.allclose(r.T @ r, np.eye(3), atol=1e-9) and np.linalg.det(r) == pytest.approx(1.0)
        to_tag = tag[:3, 3] - cam[:3, 3]
        assert np.linalg.norm(to_tag) == pytest.approx(d)
        assert np.allclose(to_tag / d, r[:, 2], atol=1e-9)  # optical axis through the centre
        off_normal = math.degrees(math.acos(np.clip(-r[:, 2] @ tag[:3, 2], -1, 1)))
        assert off_normal == pytest.approx(tilt, abs=1e-6) and tilt <= spec.max_tilt_deg + 1e-9


def test_search_returns_free_configurations_whose_camera_sees_the_tag_as_asked(setup):
    arm, dispenser = "ars_x", "rivet_dispenser_x"
    found = cps.search(setup, arm, dispenser, spec=SMALL, count=3)
    assert found
    kin = setup.scene.kinematics(arm)
    lower, upper = setup.scene.joint_limits(arm)
    collision = build_scene(setup.scene, arm, setup.mission)
    tag = setup.tag_pose(dispenser)
    assert [c.cost for c in found] == sorted(c.cost for c in found)
    for c in found:
        assert np.all(c.q >= lower) and np.all(c.q <= upper)
        assert not collision.in_collision(c.q)
        cam = kin.base @ kin.flange(c.q) @ setup.optical(arm)
        assert cps.image_margin(cam, tag, setup.printed_size, SMALL) >= SMALL.margin
        assert np.linalg.norm(cam[:3, 3] - tag[:3, 3]) == pytest.approx(c.distance, abs=1e-6)
        assert math.degrees(math.acos(-cam[:3, 2] @ tag[:3, 2])) <= SMALL.max_tilt_deg + 1e-6


def test_search_refuses_an_unknown_dispenser_and_a_view_no_camera_can_have(setup):
    with pytest.raises(cps.NoCoarsePose, match="no dispenser 'nowhere'"):
        cps.search(setup, "ars_x", "nowhere")
    # A tag 0.16 m wide cannot keep 45% of the image clear on both sides from 0.3 m.
    tight = cps.ViewSpec(distances=(0.3,), margin=0.45, rolls=4)
    with pytest.raises(cps.NoCoarsePose, match="rivet_dispenser_x"):
        cps.search(setup, "ars_x", "rivet_dispenser_x", spec=tight)


def test_main_prints_the_poses_as_the_ars_files_yaml(capsys):
    assert cps.main(["--ars", "ars_y", "--dispenser", "rivet_dispenser_y"]) == 0
    out = yaml.safe_load(capsys.readouterr().out)
    q = out["dispensers"]["rivet_dispenser_y"]["joints"]
    assert len(q) == 6 and all(isinstance(v, float) for v in q)
    assert cps.main(["--ars", "ars_y", "--dispenser", "rivet_dispenser_y", "--margin", "0.49"]) == 1
