"""Small rigid-body helpers shared by the generator and the scene (rotations, quaternions, poses)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np


def rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """Fixed-axis roll, pitch, yaw (as ROS): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def mat_to_quat(mat: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat, dtype=float).reshape(9))
    return quat


def quat_to_mat(quat: Sequence[float]) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=float))
    return mat.reshape(3, 3)


def look_at_xyaxes(forward: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """MJCF ``xyaxes`` of a camera looking along ``forward`` (MuJoCo cameras look along -z)."""
    f = np.asarray(forward, dtype=float)
    f = f / np.linalg.norm(f)
    right = np.cross(f, np.asarray(up, dtype=float))
    if np.linalg.norm(right) < 1e-6:  # looking along up: any right angle will do
        right = np.cross(f, np.array([0.0, 1.0, 0.0]))
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, f)
    return np.concatenate([right, cam_up])


def frame_from_axes(x: Sequence[float], z: Sequence[float]) -> np.ndarray:
    """Rotation whose z axis is along ``z`` and x axis along ``x`` made orthogonal to it."""
    zv = np.asarray(z, dtype=float)
    zv = zv / np.linalg.norm(zv)
    xv = np.asarray(x, dtype=float)
    xv = xv - (xv @ zv) * zv
    xv = xv / np.linalg.norm(xv)
    return np.column_stack([xv, np.cross(zv, xv), zv])


def fmt(values: Sequence[float] | float) -> str:
    """MJCF number list text, compact and exact enough (1e-9 m)."""
    if isinstance(values, int | float):
        values = [values]
    return " ".join(f"{float(v):.9g}" for v in values)
