"""UR10e kinematics: the DH product against pinocchio, and the analytic inverse."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from tlt_common.geometry.transforms import pose_error, pose_matrix, rot_z, rpy_matrix
from tlt_common.geometry.ur10e import IkFailed, Ur10eKinematics, pinocchio_model

BASE = pose_matrix([-0.35, -0.35, 0.55], rot_z(math.pi / 4))
TOOL = pose_matrix([0.0, 0.0, 0.16])


@pytest.fixture
def kin() -> Ur10eKinematics:
    return Ur10eKinematics(base=BASE, tool=TOOL)


def test_forward_matches_pinocchio_model_on_random_configurations(kin):
    model = pinocchio_model(BASE, TOOL)
    data = model.createData()
    tool = model.getFrameId("tool")
    rng = np.random.default_rng(7)
    for q in rng.uniform(-2 * math.pi, 2 * math.pi, (200, 6)):
        pin.framesForwardKinematics(model, data, q)
        dp, dr = pose_error(kin.forward(q), data.oMf[tool].homogeneous)
        assert dp < 1e-9 and dr < 1e-9


def test_home_pose_matches_published_geometry():
    # At the zero configuration the UR10e lies stretched along -x of its base: x = a2 + a3,
    # y = -(d4 + d6), z = d1 - d5 (UR's published zero pose).
    t = Ur10eKinematics().flange(np.zeros(6))
    assert t[:3, 3] == pytest.approx([-0.6127 - 0.57155, -0.17415 - 0.11655, 0.1807 - 0.11985], abs=1e-9)


def test_ik_round_trip_returns_all_solutions_within_limits_nearest_first(kin):
    rng = np.random.default_rng(11)
    counts = []
    for q in rng.uniform(-math.pi, math.pi, (150, 6)):
        pose = kin.forward(q)
        solutions = kin.inverse(pose, q)
        counts.append(len(solutions))
        assert 1 <= len(solutions) <= 8
        for s in solutions:
            dp, dr = pose_error(kin.forward(s), pose)
            assert dp < 1e-6 and dr < 1e-6
            assert np.all(s >= kin.lower) and np.all(s <= kin.upper)
        # The configuration the pose came from is a solution, so the nearest one is it.
        assert np.max(np.abs(solutions[0] - q)) < 1e-6
        gaps = [np.max(np.abs(s - q)) for s in solutions]
        assert gaps == sorted(gaps)
    assert max(counts) == 8  # a generic pose has all eight branches


def test_ik_wraps_each_joint_near_the_current_configuration(kin):
    q = np.array([-0.3, -1.2, 1.1, -1.4, -1.6, 0.2])
    current = q + np.array([2 * math.pi, 0, 0, 0, 0, -2 * math.pi]) + 0.05
    best = kin.nearest(kin.forward(q), current)
    assert best[0] == pytest.approx(q[0] + 2 * math.pi)
    assert best[5] == pytest.approx(q[5] - 2 * math.pi)


def test_elbow_limit_excludes_solutions():
    limited = Ur10eKinematics(base=BASE, tool=TOOL, lower=[-6.3, -6.3, 0.0, -6.3, -6.3, -6.3])
    q = np.array([0.3, -1.2, 1.1, -1.4, -1.6, 0.2])
    for s in limited.inverse(limited.forward(q), q):
        assert s[2] >= 0.0


def test_unreachable_pose_fails_naming_the_pose(kin):
    far = pose_matrix([3.0, 2.0, 1.0], rpy_matrix((0.0, math.pi, 0.0)))
    with pytest.raises(IkFailed) as err:
        kin.inverse(far)
    assert "xyz=(3.000, 2.000, 1.000)" in str(err.value)
    assert "outside the workspace" in err.value.reason
    assert np.allclose(err.value.pose, far)


def test_non_finite_pose_is_refused(kin):
    bad = np.eye(4)
    bad[0, 3] = math.nan
    with pytest.raises(IkFailed, match="not a finite 4x4 pose"):
        kin.inverse(bad)


def test_wrist_singularity_keeps_wrist_3(kin):
    q = np.array([0.4, -1.3, 1.5, -1.2, 0.0, 0.7])  # wrist 2 at zero: joints 4 and 6 aligned
    solutions = kin.inverse(kin.forward(q), q)
    for s in solutions:
        assert pose_error(kin.forward(s), kin.forward(q))[0] < 1e-6


def test_turn_variants_stay_within_limits(kin):
    q = np.array([-4.0, -1.0, 1.0, -1.0, -1.0, 0.0])
    variants = kin.turn_variants(q)
    assert len(variants) == 1 and variants[0][0] == pytest.approx(-4.0 + 2 * math.pi)
    assert pose_error(kin.forward(variants[0]), kin.forward(q))[0] < 1e-9
