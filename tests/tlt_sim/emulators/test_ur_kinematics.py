"""UR10e forward/inverse kinematics from the published DH parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tlt_sim.emulators import ur_kinematics as kin


def test_zero_configuration_matches_the_dh_geometry() -> None:
    # All joints at zero: the arm lies along -x (a2 + a3), offsets d4 + d6 along -y, d1 - d5 up.
    pose = kin.forward([0.0] * 6)
    assert pose[:3] == pytest.approx([-0.6127 - 0.57155, -(0.17415 + 0.11655), 0.1807 - 0.11985], abs=1e-9)


def test_tcp_offset_moves_along_the_flange_z_axis() -> None:
    q = [0.3, -1.2, 1.1, -1.4, -1.5, 0.2]
    flange = kin.pose_to_matrix(kin.forward(q))
    tcp = kin.pose_to_matrix(kin.forward(q, tcp=[0, 0, 0.2, 0, 0, 0]))
    assert np.allclose(tcp[:3, 3], flange[:3, 3] + 0.2 * flange[:3, 2])


joint = st.floats(min_value=-math.pi + 0.05, max_value=math.pi - 0.05)


@settings(max_examples=60, deadline=None)
@given(st.lists(joint, min_size=6, max_size=6))
def test_inverse_of_forward_recovers_the_configuration(q: list[float]) -> None:
    # Away from the wrist (q5 = 0 or pi) and elbow (q3 = 0, arm stretched) singularities the
    # solution nearest q is q itself; at them the angles are ill-conditioned, the pose is not.
    if abs(math.sin(q[4])) < 0.05:
        q[4] = 1.0
    if abs(math.sin(q[2])) < 0.05:
        q[2] = 1.0
    pose = kin.forward(q)
    solutions = kin.inverse_all(pose)
    assert 1 <= len(solutions) <= 8
    for s in solutions:
        assert np.allclose(kin.forward_matrix(s), kin.pose_to_matrix(pose), atol=1e-6)
    assert kin.inverse_nearest(pose, q) == pytest.approx(q, abs=1e-6)


def test_nearest_solution_keeps_whole_turns_of_the_reference() -> None:
    q = [-0.2, -1.0, 1.2, -1.5, -1.4, 0.3]
    ref = [v + 2 * math.pi for v in q[:1]] + q[1:]
    assert kin.inverse_nearest(kin.forward(q), ref)[0] == pytest.approx(q[0] + 2 * math.pi, abs=1e-6)


def test_unreachable_pose_raises() -> None:
    with pytest.raises(kin.IKError):
        kin.inverse_nearest([3.0, 0.0, 0.5, 0.0, math.pi, 0.0], [0.0] * 6)
