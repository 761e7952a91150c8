"""Rigid transforms: roll/pitch/yaw, poses, and the one quaternion convention at the boundaries."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tlt_common.geometry.transforms import (
    frame_from_axes,
    invert,
    matrix_to_rotvec,
    pose_error,
    pose_matrix,
    quaternion_to_rotation,
    rot_x,
    rot_y,
    rot_z,
    rotation_to_mujoco_quat,
    rotation_to_quaternion,
    rotvec_to_matrix,
    rpy_from_matrix,
    rpy_matrix,
)

ROTATIONS = Rotation.random(50, rng=3).as_matrix()


def test_rpy_round_trip():
    rpy = (0.3, -0.7, 2.1)
    assert rpy_from_matrix(rpy_matrix(rpy)) == pytest.approx(rpy)


def test_rpy_is_fixed_axis_roll_then_pitch_then_yaw():
    roll, pitch, yaw = 0.2, -0.4, 1.1
    assert np.allclose(rpy_matrix((roll, pitch, yaw)), rot_z(yaw) @ rot_y(pitch) @ rot_x(roll))
    extrinsic_xyz = Rotation.from_euler("xyz", (roll, pitch, yaw)).as_matrix()
    assert np.allclose(rpy_matrix((roll, pitch, yaw)), extrinsic_xyz)


def test_invert_undoes_a_pose_and_pose_error_measures_the_difference():
    t = pose_matrix([0.4, -1.2, 0.7], rpy_matrix((0.1, 0.5, -2.0)))
    assert np.allclose(invert(t) @ t, np.eye(4))
    moved = t @ pose_matrix([0.0, 0.0, 0.03], rot_z(0.2))
    dp, dr = pose_error(t, moved)
    assert dp == pytest.approx(0.03) and dr == pytest.approx(0.2)


def test_quaternion_is_in_ros_order_with_non_negative_w():
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    assert rotation_to_quaternion(rot_z(math.pi / 3)) == pytest.approx((0.0, 0.0, s, c))
    for r in ROTATIONS:
        q = rotation_to_quaternion(r)
        assert q[3] >= 0.0 and math.hypot(*q) == pytest.approx(1.0)
        assert np.allclose(quaternion_to_rotation(q), r)


def test_quaternion_to_rotation_normalises_and_refuses_zero():
    assert np.allclose(quaternion_to_rotation((0.0, 0.0, 2.0, 0.0)), rot_z(math.pi))
    with pytest.raises(ValueError, match="zero quaternion"):
        quaternion_to_rotation((0.0, 0.0, 0.0, 0.0))


def test_mujoco_quaternion_is_the_same_quaternion_scalar_first():
    for r in ROTATIONS:
        x, y, z, w = rotation_to_quaternion(r)
        assert rotation_to_mujoco_quat(r) == pytest.approx([w, x, y, z])


def test_frame_from_axes_keeps_z_and_orthogonalises_x():
    r = frame_from_axes([1.0, 0.0, 0.3], [0.0, 0.0, 2.0])
    assert np.allclose(r, np.eye(3))
    r = frame_from_axes([1.0, 1.0, 0.0], [0.0, 1.0, 1.0])
    assert np.allclose(r.T @ r, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(r[:, 2], np.array([0.0, 1.0, 1.0]) / math.sqrt(2.0))


def test_rotation_vector_round_trip_near_pi() -> None:
    for rv in ([0.0, 0.0, math.pi - 1e-7], [1.0, 2.0, -0.5], [0.0, 0.0, 0.0]):
        out = matrix_to_rotvec(rotvec_to_matrix(rv))
        assert np.allclose(rotvec_to_matrix(out), rotvec_to_matrix(rv), atol=1e-6)


def test_a_half_turn_has_one_rotation_vector():
    for axis in ([1.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.3, -0.9, 0.1], [-1.0, 0.0, 0.0]):
        k = np.asarray(axis) / np.linalg.norm(axis)
        rv = matrix_to_rotvec(rotvec_to_matrix(math.pi * k))
        assert rv == pytest.approx(matrix_to_rotvec(rotvec_to_matrix(-math.pi * k)))
        assert rv[int(np.argmax(np.abs(rv)))] > 0.0 and np.linalg.norm(rv) == pytest.approx(math.pi)


def test_quaternion_of_known_rotations():
    assert rotation_to_quaternion(np.eye(3)) == pytest.approx((0, 0, 0, 1))
    c, s = math.cos(math.pi / 3), math.sin(math.pi / 3)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert rotation_to_quaternion(rz) == pytest.approx((0, 0, math.sin(math.pi / 6), math.cos(math.pi / 6)))
    rx180 = np.diag([1.0, -1.0, -1.0])
    assert rotation_to_quaternion(rx180) == pytest.approx((1, 0, 0, 0))
