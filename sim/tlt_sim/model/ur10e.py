"""The UR10e arm as published by Universal Robots: DH parameters, link masses and joint limits.

These figures come from UR's published UR10e kinematic and dynamic data sheet (standard DH
convention, metres, radians, kilograms). :func:`forward` is the DH product, used by the model
generator to place links and by tests to check the MuJoCo chain against the published kinematics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

D = (0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655)
A = (0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0)
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
MASS = (7.369, 13.051, 3.989, 2.1, 1.98, 0.615)
# Centres of mass in each DH link frame (UR's published dynamic parameters).
COM = (
    (0.021, 0.0, 0.027),
    (0.38, 0.0, 0.158),
    (0.24, 0.0, 0.068),
    (0.0, 0.007, 0.018),
    (0.0, 0.007, 0.018),
    (0.0, 0.0, -0.026),
)
JOINT_NAMES = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
POSITION_LIMIT = 2.0 * math.pi
# Base and shoulder 120 deg/s, elbow and wrists 180 deg/s (UR10e data sheet).
VELOCITY_LIMIT = tuple(math.radians(v) for v in (120, 120, 180, 180, 180, 180))
# Rated joint torques of the size-4 and size-3 joints (data sheet), N m.
TORQUE_LIMIT = (330.0, 330.0, 150.0, 56.0, 56.0, 56.0)
# Link capsule radii for collision, m (outer diameter of the joint housings).
LINK_RADIUS = (0.075, 0.065, 0.055, 0.045, 0.045, 0.04)
HOME = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)


def dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Homogeneous transform of one standard DH link: Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def forward(q: Sequence[float]) -> np.ndarray:
    """Flange pose (4x4) in the arm's base frame for joint angles ``q`` (six values, rad)."""
    if len(q) != 6:
        raise ValueError(f"expected six joint angles, got {len(q)}")
    t = np.eye(4)
    for i in range(6):
        t = t @ dh(float(q[i]), D[i], A[i], ALPHA[i])
    return t
