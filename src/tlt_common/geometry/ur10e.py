"""The UR10e arm as Universal Robots publish it, and its kinematics, shared by the ARS, vision and
the twin.

The figures (standard DH table, link masses and centres of mass, joint limits, rated torques)
come from UR's published UR10e kinematic and dynamic data and data sheet (metres, radians,
kilograms). The ARS plans with them, vision places the EE camera with them, the twin builds its
MuJoCo arm and emulates the controller's kinematics from them.

:func:`flange` is the DH product (base frame -> flange). :func:`analytic_inverse` is the
closed-form inverse of a UR arm (three parallel shoulder/elbow/wrist-1 axes, intersecting wrist
axes): up to 8 branches (shoulder left/right, wrist up/down, elbow up/down).

:class:`Ur10eKinematics` is one arm placed in the world with a tool: forward kinematics (world
-> tool) and the inverse as all solutions within the joint limits, each joint wrapped to the angle
nearest the current configuration, sorted nearest first. A pose with no solution within the
limits raises :class:`IkFailed` naming the pose and why.

Poses are 4x4 homogeneous matrices in metres (see :mod:`tlt_common.geometry.transforms`).

:func:`pinocchio_model` builds the same chain as a pinocchio model (programmatically, no URDF), used
by the ARS's collision scene and to cross-check the DH product in tests.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from tlt_common.geometry.transforms import describe_pose, invert, rot_x

# UR10e, Universal Robots' published DH table (standard convention, m, rad).
D = (0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655)
A = (0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0)
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
JOINT_NAMES = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
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
# UR10e data sheet: +-360 deg on every joint (the UR ROS driver limits the elbow to +-180 deg,
# because past that the upper and fore arm meet, and so does the ARS's planner);
# 120 deg/s base and shoulder, 180 deg/s others.
POSITION_LIMIT = 2.0 * math.pi
POSITION_LOWER = (-2 * math.pi, -2 * math.pi, -math.pi, -2 * math.pi, -2 * math.pi, -2 * math.pi)
POSITION_UPPER = (2 * math.pi, 2 * math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi)
VELOCITY_LIMIT = tuple(math.radians(v) for v in (120, 120, 180, 180, 180, 180))
# Rated joint torques of the size-4 and size-3 joints (data sheet), N m.
TORQUE_LIMIT = (330.0, 330.0, 150.0, 56.0, 56.0, 56.0)
# Link capsule radii for collision, m (outer diameter of the joint housings).
LINK_RADIUS = (0.075, 0.065, 0.055, 0.045, 0.045, 0.04)
# UR's home posture: upper arm up, forearm level, tool pointing down.
HOME = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)

# A candidate whose forward kinematics misses the asked pose by more than this is dropped
# (the analytic branches are exact; this only removes numerically degenerate ones).
_POSITION_CHECK = 1e-6
_ROTATION_CHECK = 1e-6


class IkFailed(ValueError):
    """No joint configuration within the limits reaches ``pose``; ``reason`` says why."""

    def __init__(self, pose: np.ndarray, reason: str) -> None:
        self.pose = np.array(pose, dtype=float)
        self.reason = reason
        super().__init__(f"IK failed for pose {describe_pose(self.pose)}: {reason}")


def dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """One standard DH link: Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def flange(q: Sequence[float]) -> np.ndarray:
    """Flange pose (4x4) in the arm's base frame for joint angles ``q`` (six values, rad)."""
    if len(q) != 6:
        raise ValueError(f"expected six joint angles, got {len(q)}")
    t = np.eye(4)
    for i in range(6):
        t = t @ dh(float(q[i]), D[i], A[i], ALPHA[i])
    return t


def analytic_inverse(t: np.ndarray, wrist_3: float = 0.0) -> list[np.ndarray]:
    """The (up to 8) closed-form joint solutions for flange pose ``t`` in the base frame.

    Angles are as the formulas give them (not wrapped, not checked against limits or against the
    forward kinematics). At the wrist singularity joints 4 and 6 share an axis and any split
    reaches the pose: wrist 3 is then held at ``wrist_3``.
    """
    d1, a2, a3, d4, d5, d6 = D[0], A[1], A[2], D[3], D[4], D[5]
    z6 = t[:3, 2]
    p06 = t[:3, 3]
    wrist = p06 - d6 * z6  # origin of frame 5
    r = math.hypot(wrist[0], wrist[1])
    if r < d4:
        return []
    phi = math.atan2(wrist[1], wrist[0])
    off = math.asin(d4 / r)
    out: list[np.ndarray] = []
    for t1 in (phi + off, phi + math.pi - off):
        s1, c1 = math.sin(t1), math.cos(t1)
        z1 = np.array([s1, -c1, 0.0])  # axis of joints 2, 3, 4
        v6 = t[:3, :3].T @ z1
        c5 = max(-1.0, min(1.0, float(v6[2])))
        for t5 in (math.acos(c5), -math.acos(c5)):
            s5 = math.sin(t5)
            t6 = wrist_3 if abs(s5) < 1e-9 else math.atan2(-v6[1] / s5, v6[0] / s5)
            t01 = dh(t1, d1, 0.0, ALPHA[0])
            t46 = dh(t5, d5, 0.0, ALPHA[4]) @ dh(t6, d6, 0.0, 0.0)
            t14 = invert(t01) @ t @ invert(t46)
            p13 = t14[:3, 3] - np.array([0.0, 0.0, d4])
            c3 = (p13[0] ** 2 + p13[1] ** 2 - a2 * a2 - a3 * a3) / (2 * a2 * a3)
            if abs(c3) > 1.0 + 1e-9:
                continue
            c3 = max(-1.0, min(1.0, c3))
            for t3 in (math.acos(c3), -math.acos(c3)):
                t2 = math.atan2(p13[1], p13[0]) - math.atan2(a3 * math.sin(t3), a2 + a3 * math.cos(t3))
                t4 = math.atan2(t14[1, 0], t14[0, 0]) - t2 - t3
                out.append(np.array([t1, t2, t3, t4, t5, t6]))
    return out


@dataclass
class Ur10eKinematics:
    """Forward and inverse kinematics of one UR10e.

    ``base`` is the arm base in the world; ``tool`` the tool frame in the flange frame (the end
    effector's grasp centre). ``lower``/``upper`` are the joint position limits (rad).
    """

    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    tool: np.ndarray = field(default_factory=lambda: np.eye(4))
    lower: np.ndarray = field(default_factory=lambda: np.array(POSITION_LOWER))
    upper: np.ndarray = field(default_factory=lambda: np.array(POSITION_UPPER))

    def __post_init__(self) -> None:
        self.base = np.asarray(self.base, dtype=float)
        self.tool = np.asarray(self.tool, dtype=float)
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        self._base_inv = invert(self.base)
        self._tool_inv = invert(self.tool)

    # ----- forward -----
    def link_frames(self, q: Sequence[float]) -> list[np.ndarray]:
        """Frames 0..6 of the DH chain in the world (frame 0 is the base, frame 6 the flange)."""
        if len(q) != 6:
            raise ValueError(f"expected six joint angles, got {len(q)}")
        frames = [self.base]
        t = self.base
        for i in range(6):
            t = t @ dh(float(q[i]), D[i], A[i], ALPHA[i])
            frames.append(t)
        return frames

    def flange(self, q: Sequence[float]) -> np.ndarray:
        """Flange pose in the arm's base frame."""
        return flange(q)

    def forward(self, q: Sequence[float]) -> np.ndarray:
        """Tool pose in the world for joint angles ``q``."""
        return self.base @ self.flange(q) @ self.tool

    # ----- inverse -----
    def inverse(self, pose: np.ndarray, current: Sequence[float] | None = None) -> list[np.ndarray]:
        """Every configuration within the limits whose tool reaches ``pose`` (world), nearest first.

        Each joint is wrapped (by multiples of 2 pi) to the angle within the limits nearest
        ``current`` (all zeros when omitted); "nearest" is the largest single-joint
        move. Raises :class:`IkFailed` naming the pose when there is none.
        """
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise IkFailed(
                np.eye(4) if pose.shape != (4, 4) else np.nan_to_num(pose), "not a finite 4x4 pose"
            )
        ref = np.zeros(6) if current is None else np.asarray(current, dtype=float)
        target = self._base_inv @ pose @ self._tool_inv
        raw = analytic_inverse(target, float(ref[5]))
        if not raw:
            reach = float(np.linalg.norm(target[:3, 3] - np.array([0.0, 0.0, D[0]])))
            raise IkFailed(pose, f"outside the workspace (wrist {reach:.3f} m from the shoulder)")
        qs = np.array(raw)
        wrapped = self._wrap_batch(qs, ref)
        if wrapped.shape[0] == 0:
            raise IkFailed(pose, f"{len(raw)} solution(s), none within the joint limits")
        # Keep only branches whose forward kinematics meets the pose (drops degenerate ones).
        t = flange_batch(wrapped)
        dp = np.linalg.norm(t[:, :3, 3] - target[:3, 3], axis=1)
        r = np.einsum("nji,jk->nik", t[:, :3, :3], target[:3, :3])
        sin = np.linalg.norm(
            np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=1),
            axis=1,
        )
        dr = np.arctan2(sin / 2.0, (np.trace(r, axis1=1, axis2=2) - 1.0) / 2.0)
        good = wrapped[(dp <= _POSITION_CHECK) & (dr <= _ROTATION_CHECK)]
        if good.shape[0] == 0:
            raise IkFailed(pose, f"{len(raw)} solution(s), none exact within the joint limits")
        order = np.argsort(np.max(np.abs(good - ref), axis=1), kind="stable")
        unique: list[np.ndarray] = []
        for q in good[order]:
            if all(np.max(np.abs(q - u)) > 1e-9 for u in unique):
                unique.append(q.copy())
        return unique

    def _wrap_batch(self, qs: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """Each row wrapped joint by joint to the angle within the limits nearest ``ref``; rows
        with a joint that has no such angle are dropped."""
        turn = 2 * math.pi
        a = qs + turn * np.round((ref - qs) / turn)
        cands = np.stack([a - turn, a, a + turn])
        inside = (cands >= self.lower - 1e-12) & (cands <= self.upper + 1e-12)
        dist = np.where(inside, np.abs(cands - ref), np.inf)
        pick = np.argmin(dist, axis=0)
        out = np.take_along_axis(cands, pick[None], axis=0)[0]
        return out[np.all(np.isfinite(np.min(dist, axis=0)), axis=1)]

    def turn_variants(self, q: np.ndarray, joints: Sequence[int] = (0,)) -> list[np.ndarray]:
        """Configurations equal to ``q`` but with the given joints a full turn away, within the
        limits: the same pose, reached by turning the other way round (the base joint can go
        round a lifter post the short way or the long way)."""
        out = []
        for i in joints:
            for k in (-1, 1):
                v = q.copy()
                v[i] += 2 * math.pi * k
                if self.lower[i] <= v[i] <= self.upper[i]:
                    out.append(v)
        return out

    def nearest(self, pose: np.ndarray, current: Sequence[float]) -> np.ndarray:
        """The solution of :meth:`inverse` nearest ``current``."""
        return self.inverse(pose, current)[0]


def flange_batch(qs: np.ndarray) -> np.ndarray:
    """Flange poses (n x 4 x 4, base frame) of n configurations at once."""
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    n = qs.shape[0]
    t = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    for i in range(6):
        ct, st = np.cos(qs[:, i]), np.sin(qs[:, i])
        ca, sa = math.cos(ALPHA[i]), math.sin(ALPHA[i])
        m = np.zeros((n, 4, 4))
        m[:, 0, 0], m[:, 0, 1], m[:, 0, 2], m[:, 0, 3] = ct, -st * ca, st * sa, A[i] * ct
        m[:, 1, 0], m[:, 1, 1], m[:, 1, 2], m[:, 1, 3] = st, ct * ca, -ct * sa, A[i] * st
        m[:, 2, 1], m[:, 2, 2], m[:, 2, 3], m[:, 3, 3] = sa, ca, D[i], 1.0
        t = t @ m
    return t


def pinocchio_model(base: np.ndarray | None = None, tool: np.ndarray | None = None):
    """The UR10e DH chain as a pinocchio ``Model`` with frames ``flange`` and ``tool``.

    Joint i is a revolute joint about z placed at DH frame i-1; the placement of joint i+1 in
    joint i is Tz(d_i) Tx(a_i) Rx(alpha_i), which is the DH product with the rotation taken by the
    joint. Joint limits are the UR10e's.
    """
    import pinocchio as pin

    model = pin.Model()
    model.name = "ur10e"
    placement = pin.SE3(np.eye(4) if base is None else np.asarray(base, dtype=float))
    parent = 0
    for i in range(6):
        jid = model.addJoint(
            parent,
            pin.JointModelRZ(),
            placement,
            JOINT_NAMES[i],
            np.array([TORQUE_LIMIT[i]]),
            np.array([VELOCITY_LIMIT[i]]),
            np.array([POSITION_LOWER[i]]),
            np.array([POSITION_UPPER[i]]),
        )
        # Inertia is irrelevant to kinematics and collision; a small sphere keeps the model valid.
        model.appendBodyToJoint(jid, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
        placement = pin.SE3(rot_x(ALPHA[i]), np.array([A[i], 0.0, D[i]]))
        parent = jid
    flange_id = model.addFrame(pin.Frame("flange", parent, 0, placement, pin.FrameType.OP_FRAME))
    tool_t = np.eye(4) if tool is None else np.asarray(tool, dtype=float)
    model.addFrame(pin.Frame("tool", parent, flange_id, placement * pin.SE3(tool_t), pin.FrameType.OP_FRAME))
    return model


__all__ = [
    "ALPHA",
    "COM",
    "HOME",
    "JOINT_NAMES",
    "LINK_RADIUS",
    "MASS",
    "POSITION_LIMIT",
    "POSITION_LOWER",
    "POSITION_UPPER",
    "TORQUE_LIMIT",
    "VELOCITY_LIMIT",
    "A",
    "D",
    "IkFailed",
    "Ur10eKinematics",
    "analytic_inverse",
    "dh",
    "flange",
    "flange_batch",
    "pinocchio_model",
]
