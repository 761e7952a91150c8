"""Rigid transforms shared by the agents and the twin: rotations, poses and their conversions.

Conventions, the same everywhere in the project:

- A pose is a 4x4 homogeneous matrix in metres; a rotation is a 3x3 matrix.
- Roll, pitch, yaw are fixed-axis angles as in URDF and ROS: R = Rz(yaw) Ry(pitch) Rx(roll).
- A quaternion is a unit quaternion with w >= 0, in ROS's order ``(x, y, z, w)`` (geometry_msgs)
  unless a name says otherwise. MuJoCo's order ``(w, x, y, z)`` appears only through
  :func:`rotation_to_mujoco_quat`, at the twin's boundary.
- A rotation vector (axis times angle, rad) is the form UR controllers use in their poses.

Quaternion and rotation-vector conversions go through :class:`scipy.spatial.transform.Rotation`.
A matrix handed to them is taken as a rotation (orthonormal to rounding, as the matrices the
code builds are) and not projected onto the nearest one first: that projection costs several
times the conversion, and the twin converts every body's pose on each ground-truth message.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

# Rotations within this angle (rad) of a half turn get the one canonical rotation vector.
_HALF_TURN = 1e-6


def rot_x(a: float) -> np.ndarray:
    """Rotation by ``a`` rad about x."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation by ``a`` rad about y."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation by ``a`` rad about z."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """Rotation of fixed-axis roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)), as in URDF."""
    return rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def rpy_from_matrix(r: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`rpy_matrix` (pitch in [-pi/2, pi/2])."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    roll = math.atan2(r[2, 1], r[2, 2])
    yaw = math.atan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


def frame_from_axes(x: Sequence[float], z: Sequence[float]) -> np.ndarray:
    """Rotation whose z axis is along ``z`` and x axis along ``x`` made orthogonal to it."""
    zv = np.asarray(z, dtype=float)
    zv = zv / np.linalg.norm(zv)
    xv = np.asarray(x, dtype=float)
    xv = xv - (xv @ zv) * zv
    xv = xv / np.linalg.norm(xv)
    return np.column_stack([xv, np.cross(zv, xv), zv])


def pose_matrix(position: Sequence[float], rotation: np.ndarray | None = None) -> np.ndarray:
    """4x4 pose from a position and a 3x3 rotation (identity when omitted)."""
    t = np.eye(4)
    t[:3, 3] = position
    if rotation is not None:
        t[:3, :3] = rotation
    return t


def invert(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def pose_error(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Position (m) and rotation angle (rad) between two poses."""
    dp = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    r = a[:3, :3].T @ b[:3, :3]
    # atan2 of sine and cosine keeps precision near zero, where acos of the trace does not.
    s = math.hypot(r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]) / 2.0
    c = (np.trace(r) - 1.0) / 2.0
    return dp, math.atan2(s, c)


def describe_pose(pose: np.ndarray) -> str:
    """Short human-readable form of a 4x4 pose: position in m and roll/pitch/yaw in degrees."""
    p = pose[:3, 3]
    r, pi_, y = rpy_from_matrix(pose[:3, :3])
    return (
        f"xyz=({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
        f" rpy=({math.degrees(r):.1f}, {math.degrees(pi_):.1f}, {math.degrees(y):.1f}) deg"
    )


def _from_matrix(rot: np.ndarray) -> Rotation:
    return Rotation.from_matrix(np.asarray(rot, dtype=float), assume_valid=True)


def rotation_to_quaternion(rot: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` (geometry_msgs order) of a rotation matrix, ``w >= 0``."""
    q = _from_matrix(rot).as_quat(canonical=True)
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def quaternion_to_rotation(q: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a quaternion ``(x, y, z, w)`` (geometry_msgs order), normalised first.

    Raises ``ValueError`` for a zero quaternion, which names no rotation.
    """
    v = np.asarray(q, dtype=float)
    if float(v @ v) < 1e-12:
        raise ValueError("zero quaternion")
    return Rotation.from_quat(v).as_matrix()


def rotation_to_mujoco_quat(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion in MuJoCo's order ``(w, x, y, z)``, ``w >= 0``: the twin's boundary."""
    return _from_matrix(rot).as_quat(canonical=True, scalar_first=True)


def rotvec_to_matrix(rv: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis times angle, rad)."""
    return Rotation.from_rotvec(np.asarray(rv, dtype=float)).as_matrix()


def matrix_to_rotvec(r: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix, angle in [0, pi].

    A half turn has two rotation vectors, ``v`` and ``-v``; within 1e-6 rad of it the one whose
    largest component (the first of equal ones) is positive is returned, so the same rotation
    always gives the same vector.
    """
    rv = _from_matrix(r).as_rotvec()
    if math.pi - float(np.linalg.norm(rv)) < _HALF_TURN and rv[int(np.argmax(np.abs(rv)))] < 0.0:
        rv = -rv
    return rv


__all__ = [
    "describe_pose",
    "frame_from_axes",
    "invert",
    "matrix_to_rotvec",
    "pose_error",
    "pose_matrix",
    "quaternion_to_rotation",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_to_mujoco_quat",
    "rotation_to_quaternion",
    "rotvec_to_matrix",
    "rpy_from_matrix",
    "rpy_matrix",
]
