"""UR10e forward and inverse kinematics from the published DH parameters.

Poses are UR poses: ``[x, y, z, rx, ry, rz]`` in the controller's base frame, metres and an
axis-angle rotation vector, exactly as RTDE reports ``actual_TCP_pose``. ``tcp`` is the tool
offset from the flange (``set_tcp``), also a UR pose.

The inverse is the closed-form solution for a UR arm (three parallel shoulder/elbow/wrist-1 axes,
intersecting wrist axes), giving up to eight joint solutions; :func:`inverse_nearest` picks the
one closest to a reference configuration, each joint moved by whole turns to the equivalent
angle nearest the reference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tlt_common.geometry import ur10e


@dataclass(frozen=True)
class DH:
    """Standard DH parameters of a six-joint UR arm (metres, radians)."""

    d: tuple[float, ...]
    a: tuple[float, ...]
    alpha: tuple[float, ...]


# The data sheet's, kept in one place with the twin's model of the arm.
UR10E = DH(d=ur10e.D, a=ur10e.A, alpha=ur10e.ALPHA)


class IKError(ValueError):
    """The pose has no joint solution (out of reach or at a singular configuration)."""


def rotvec_to_matrix(rv: Sequence[float]) -> np.ndarray:
    """Rotation matrix of an axis-angle vector (Rodrigues)."""
    v = np.asarray(rv, dtype=float)
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * (kx @ kx)


def matrix_to_rotvec(r: np.ndarray) -> np.ndarray:
    """Axis-angle vector of a rotation matrix, angle in [0, pi]."""
    cos_angle = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(cos_angle)
    if angle < 1e-9:
        return np.zeros(3)
    if math.pi - angle < 1e-6:
        # Near pi the antisymmetric part vanishes; take the axis from the symmetric part.
        m = (r + np.eye(3)) / 2.0
        axis = m[:, int(np.argmax(np.diag(m)))]
        axis = axis / np.linalg.norm(axis)
        return axis * angle
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2.0 * math.sin(angle))
    return axis * angle


def pose_to_matrix(pose: Sequence[float]) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rotvec_to_matrix(pose[3:6])
    t[:3, 3] = pose[0:3]
    return t


def matrix_to_pose(t: np.ndarray) -> list[float]:
    return [*map(float, t[:3, 3]), *map(float, matrix_to_rotvec(t[:3, :3]))]


def forward_matrix(q: Sequence[float], dh: DH = UR10E) -> np.ndarray:
    """Base-to-flange transform at joint angles ``q``."""
    t = np.eye(4)
    for i in range(6):
        t = t @ ur10e.dh(q[i], dh.d[i], dh.a[i], dh.alpha[i])
    return t


def forward(q: Sequence[float], tcp: Sequence[float] | None = None, dh: DH = UR10E) -> list[float]:
    """TCP pose at joint angles ``q`` (flange pose when ``tcp`` is None)."""
    t = forward_matrix(q, dh)
    if tcp is not None:
        t = t @ pose_to_matrix(tcp)
    return matrix_to_pose(t)


def inverse_all(
    pose: Sequence[float], tcp: Sequence[float] | None = None, dh: DH = UR10E
) -> list[list[float]]:
    """Every joint solution (angles in (-pi, pi]) reaching ``pose``; empty when none exists."""
    t06 = pose_to_matrix(pose)
    if tcp is not None:
        t06 = t06 @ np.linalg.inv(pose_to_matrix(tcp))
    d1, _, _, d4, d5, d6 = dh.d
    a2, a3 = dh.a[1], dh.a[2]
    p05 = t06 @ np.array([0.0, 0.0, -d6, 1.0])
    r05 = math.hypot(p05[0], p05[1])
    if r05 < abs(d4):
        return []
    solutions: list[list[float]] = []
    phi = math.atan2(p05[1], p05[0])
    psi = math.acos(max(-1.0, min(1.0, d4 / r05)))
    for s1 in (1, -1):
        th1 = phi + s1 * psi + math.pi / 2
        c1, sn1 = math.cos(th1), math.sin(th1)
        c5 = (t06[0, 3] * sn1 - t06[1, 3] * c1 - d4) / d6
        if abs(c5) > 1.0 + 1e-9:
            continue
        for s5 in (1, -1):
            th5 = s5 * math.acos(max(-1.0, min(1.0, c5)))
            sn5 = math.sin(th5)
            t60 = np.linalg.inv(t06)
            if abs(sn5) < 1e-9:
                th6 = 0.0  # wrist singularity: joint 6 is free, any value reaches the pose
            else:
                th6 = math.atan2(
                    (-t60[1, 0] * sn1 + t60[1, 1] * c1) / sn5,
                    (t60[0, 0] * sn1 - t60[0, 1] * c1) / sn5,
                )
            t01 = ur10e.dh(th1, d1, 0.0, dh.alpha[0])
            t45 = ur10e.dh(th5, d5, 0.0, dh.alpha[4])
            t56 = ur10e.dh(th6, d6, 0.0, dh.alpha[5])
            t14 = np.linalg.inv(t01) @ t06 @ np.linalg.inv(t45 @ t56)
            p13 = t14 @ np.array([0.0, -d4, 0.0, 1.0]) - np.array([0.0, 0.0, 0.0, 1.0])
            n13 = float(np.linalg.norm(p13[:3]))
            c3 = (n13**2 - a2**2 - a3**2) / (2 * a2 * a3)
            if abs(c3) > 1.0 + 1e-9:
                continue
            for s3 in (1, -1):
                th3 = s3 * math.acos(max(-1.0, min(1.0, c3)))
                th2 = -math.atan2(p13[1], -p13[0]) + math.asin(max(-1.0, min(1.0, a3 * math.sin(th3) / n13)))
                t12 = ur10e.dh(th2, 0.0, a2, 0.0)
                t23 = ur10e.dh(th3, 0.0, a3, 0.0)
                t34 = np.linalg.inv(t12 @ t23) @ t14
                th4 = math.atan2(t34[1, 0], t34[0, 0])
                q = [th1, th2, th3, th4, th5, th6]
                solutions.append([math.atan2(math.sin(x), math.cos(x)) for x in q])
    # Keep only solutions that really reach the pose (guards the clamped acos/asin branches).
    target = t06
    good = []
    for q in solutions:
        err = forward_matrix(q, dh) - target
        if float(np.max(np.abs(err))) < 1e-6:
            good.append(q)
    return good


def _nearest_equivalent(angle: float, reference: float, low: float, high: float) -> float:
    best = angle + 2 * math.pi * round((reference - angle) / (2 * math.pi))
    if best < low:
        best += 2 * math.pi
    if best > high:
        best -= 2 * math.pi
    return best


def inverse_nearest(
    pose: Sequence[float],
    reference: Sequence[float],
    tcp: Sequence[float] | None = None,
    limits: Sequence[tuple[float, float]] | None = None,
    dh: DH = UR10E,
) -> list[float]:
    """The joint solution for ``pose`` closest to ``reference``; raises :class:`IKError` if none."""
    limits = limits or [(-2 * math.pi, 2 * math.pi)] * 6
    best: list[float] | None = None
    best_cost = math.inf
    for q in inverse_all(pose, tcp, dh):
        shifted = [_nearest_equivalent(q[i], reference[i], *limits[i]) for i in range(6)]
        if any(not (limits[i][0] <= shifted[i] <= limits[i][1]) for i in range(6)):
            continue
        cost = sum((shifted[i] - reference[i]) ** 2 for i in range(6))
        if cost < best_cost:
            best, best_cost = shifted, cost
    if best is None:
        raise IKError(f"no joint solution for pose {[round(v, 4) for v in pose]}")
    return best
