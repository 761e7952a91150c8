"""The emulated controller's kinematics: the shared UR10e model in UR poses.

Poses are UR poses: ``[x, y, z, rx, ry, rz]`` in the controller's base frame, metres and an
axis-angle rotation vector, exactly as RTDE reports ``actual_TCP_pose``. ``tcp`` is the tool
offset from the flange (``set_tcp``), also a UR pose.

The forward kinematics and the closed-form inverse are :mod:`tlt_common.geometry.ur10e`'s (the
one UR10e model the ARS plans with); :func:`inverse_nearest` picks the solution closest to a
reference configuration, each joint moved by whole turns to the equivalent angle nearest the
reference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tlt_common.geometry import ur10e
from tlt_common.geometry.transforms import invert, matrix_to_rotvec, rotvec_to_matrix
from tlt_common.geometry.ur10e import flange as forward_matrix


class IKError(ValueError):
    """The pose has no joint solution (out of reach or at a singular configuration)."""


def pose_to_matrix(pose: Sequence[float]) -> np.ndarray:
    """4x4 transform of a UR pose."""
    t = np.eye(4)
    t[:3, :3] = rotvec_to_matrix(pose[3:6])
    t[:3, 3] = pose[0:3]
    return t


def matrix_to_pose(t: np.ndarray) -> list[float]:
    """UR pose of a 4x4 transform (rotation vector angle in [0, pi])."""
    return [*map(float, t[:3, 3]), *map(float, matrix_to_rotvec(t[:3, :3]))]


def forward(q: Sequence[float], tcp: Sequence[float] | None = None) -> list[float]:
    """TCP pose at joint angles ``q`` (flange pose when ``tcp`` is None)."""
    t = forward_matrix(q)
    if tcp is not None:
        t = t @ pose_to_matrix(tcp)
    return matrix_to_pose(t)


def inverse_all(pose: Sequence[float], tcp: Sequence[float] | None = None) -> list[list[float]]:
    """Every joint solution (angles in (-pi, pi]) reaching ``pose``; empty when none exists.

    At the wrist singularity, where joint 6 is free, it is taken at 0.
    """
    t06 = pose_to_matrix(pose)
    if tcp is not None:
        t06 = t06 @ invert(pose_to_matrix(tcp))
    good = []
    for raw in ur10e.analytic_inverse(t06, wrist_3=0.0):
        q = [math.atan2(math.sin(x), math.cos(x)) for x in raw]
        # Keep only solutions that really reach the pose (guards the clamped acos/asin branches).
        if float(np.max(np.abs(forward_matrix(q) - t06))) < 1e-6:
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
) -> list[float]:
    """The joint solution for ``pose`` closest to ``reference``; raises :class:`IKError` if none."""
    limits = limits or [(-ur10e.POSITION_LIMIT, ur10e.POSITION_LIMIT)] * 6
    best: list[float] | None = None
    best_cost = math.inf
    for q in inverse_all(pose, tcp):
        shifted = [_nearest_equivalent(q[i], reference[i], *limits[i]) for i in range(6)]
        if any(not (limits[i][0] <= shifted[i] <= limits[i][1]) for i in range(6)):
            continue
        cost = sum((shifted[i] - reference[i]) ** 2 for i in range(6))
        if cost < best_cost:
            best, best_cost = shifted, cost
    if best is None:
        raise IKError(f"no joint solution for pose {[round(v, 4) for v in pose]}")
    return best


__all__ = [
    "IKError",
    "forward",
    "forward_matrix",
    "inverse_all",
    "inverse_nearest",
    "matrix_to_pose",
    "pose_to_matrix",
]
