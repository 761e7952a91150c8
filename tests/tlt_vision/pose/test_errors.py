"""Pose errors as the vision benchmark counts them, against hand-computed cases."""

from pathlib import Path

import numpy as np
import pytest

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import models_for_mission
from tlt_vision.pose.errors import add_s, rotation_error_deg

ONE_BAY = Path(__file__).resolve().parents[3] / "missions" / "one_bay.yaml"


@pytest.fixture(scope="module")
def models():
    return models_for_mission(load_mission(ONE_BAY))


def rot_x(deg):
    a = np.radians(deg)
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def rot_z(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_a_corner_joint_turned_by_a_symmetry_has_no_rotation_error(models):
    cube = models["corner_joint"]
    truth = rot_x(20) @ rot_z(35)
    assert rotation_error_deg(cube, truth @ rot_z(90), truth) == pytest.approx(0.0, abs=1e-4)
    assert rotation_error_deg(cube, truth @ rot_x(10), truth) == pytest.approx(10.0, abs=1e-4)
    # 60 degrees about z is 30 from the nearest quarter turn.
    assert rotation_error_deg(cube, truth @ rot_z(60), truth) == pytest.approx(30.0, abs=1e-4)


def test_a_tube_counts_its_axis_only_and_either_end(models):
    tube = models["strut_tube/vertical"]
    truth = rot_x(30)
    assert rotation_error_deg(tube, truth @ rot_z(77), truth) == pytest.approx(0.0, abs=1e-4)
    assert rotation_error_deg(tube, truth @ rot_x(180), truth) == pytest.approx(0.0, abs=1e-4)
    assert rotation_error_deg(tube, truth @ rot_x(4), truth) == pytest.approx(4.0, abs=1e-4)


def test_add_s_is_zero_at_the_truth_and_the_offset_of_a_cube_moved_along_a_face_normal(models):
    cube = models["corner_joint"]
    r, t = rot_z(15), np.array([0.1, -0.2, 1.0])
    assert add_s(cube, r, t, r, t) == pytest.approx(0.0, abs=1e-6)
    # Moved 1 mm along a face normal, the points of the two faces across that normal are 1 mm off
    # the true surface and those of the four side faces about 0 (they stay on the true faces'
    # planes): the mean is about a third of a millimetre.
    moved = add_s(cube, r, t + r @ np.array([0.0, 0.0, 0.001]), r, t)
    assert 0.00025 < moved < 0.0005
    # Symmetric: a quarter turn about a face normal moves nothing.
    assert add_s(cube, r @ rot_z(90), t, r, t) == pytest.approx(0.0, abs=1e-5)
