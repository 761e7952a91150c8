"""The emulated UR10e arm: plain joint state and the motion the controller commands on it.

The arm holds six joint positions and velocities. Motions (``move_joints``, ``move_linear``,
``servo``, ``speed``, ``stop``, ``halt``) set a motion generator; ``step(dt)`` advances it by
``dt`` seconds. Nothing here reads a clock: the controller (or the MuJoCo twin) calls ``step``
with real or simulated time, so tests can step it deterministically.

Limits are UR10e published limits: joint velocities 120 deg/s (base, shoulder) and 180 deg/s
(elbow, wrists), joint range +-360 deg. A motion that would leave the joint range stops at the
limit and is reported through ``fault``.

The twin reads ``positions()``/``velocities()`` and may overwrite the measured state with
``set_state``; everything is guarded by one lock so the controller thread and the twin can share
the object.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from tlt_common.geometry import ur10e
from tlt_common.geometry.transforms import matrix_to_rotvec, rotvec_to_matrix
from tlt_sim.emulators import ur_kinematics as kin

UR10E_MAX_VELOCITY = ur10e.VELOCITY_LIMIT
UR10E_MAX_ACCELERATION = (15.0,) * 6  # rad/s^2; the controller's software ceiling is 40
UR10E_POSITION_LIMIT = ur10e.POSITION_LIMIT
HOME = ur10e.HOME


@dataclass
class _Profile:
    """A synchronised trapezoidal velocity profile along a scalar path s in [0, length]."""

    length: float
    v: float
    a: float
    t_acc: float = field(init=False)
    total: float = field(init=False)

    def __post_init__(self) -> None:
        if self.length <= 0:
            self.t_acc, self.total = 0.0, 0.0
            return
        if self.length >= self.v * self.v / self.a:
            self.t_acc = self.v / self.a
            self.total = self.length / self.v + self.t_acc
        else:
            self.t_acc = math.sqrt(self.length / self.a)
            self.v = self.a * self.t_acc
            self.total = 2 * self.t_acc

    def at(self, t: float) -> tuple[float, float]:
        """Path position and speed at time ``t`` since the start."""
        if self.total == 0 or t >= self.total:
            return self.length, 0.0
        t = max(t, 0.0)
        if t < self.t_acc:
            return 0.5 * self.a * t * t, self.a * t
        t_dec = self.total - self.t_acc
        if t <= t_dec:
            return 0.5 * self.a * self.t_acc**2 + self.v * (t - self.t_acc), self.v
        rest = self.total - t
        return self.length - 0.5 * self.a * rest * rest, self.a * rest


class UR10eArm:
    """Six joints and the active motion generator. Thread-safe."""

    def __init__(
        self,
        q0: Sequence[float] = HOME,
        max_velocity: Sequence[float] = UR10E_MAX_VELOCITY,
        max_acceleration: Sequence[float] = UR10E_MAX_ACCELERATION,
    ) -> None:
        self._lock = threading.RLock()
        self.q = np.array(q0, dtype=float)
        self.qd = np.zeros(6)
        self.target_q = self.q.copy()
        self.vmax = np.array(max_velocity, dtype=float)
        self.amax = np.array(max_acceleration, dtype=float)
        self.tcp = [0.0] * 6
        self.mode = "idle"
        self.fault = ""
        self._t = 0.0
        self._start = self.q.copy()
        self._delta = np.zeros(6)
        self._profile: _Profile | None = None
        self._line: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._servo_target = self.q.copy()
        self._servo_tau = 0.1
        self._speed_target = np.zeros(6)
        self._speed_acc = 1.0
        self._stop_dec = np.full(6, 10.0)
        # The last TCP pose and the joints and tool it is for: every RTDE data package carries
        # the pose, and most of them are of an arm at rest.
        self._tcp_pose: tuple[bytes, tuple[float, ...], list[float]] | None = None

    # --- state for the controller and the twin ------------------------------------------
    def positions(self) -> list[float]:
        with self._lock:
            return self.q.tolist()

    def velocities(self) -> list[float]:
        with self._lock:
            return self.qd.tolist()

    def set_state(self, q: Sequence[float], qd: Sequence[float] | None = None) -> None:
        """Overwrite the measured joint state (the twin's physics is the truth)."""
        with self._lock:
            self.q = np.array(q, dtype=float)
            self.qd = np.zeros(6) if qd is None else np.array(qd, dtype=float)

    def tcp_pose(self) -> list[float]:
        with self._lock:
            q, tcp = self.q.tobytes(), tuple(self.tcp)
            if self._tcp_pose is None or self._tcp_pose[:2] != (q, tcp):
                self._tcp_pose = (q, tcp, kin.forward(self.q, self.tcp))
            return list(self._tcp_pose[2])

    def set_tcp(self, tcp: Sequence[float]) -> None:
        with self._lock:
            self.tcp = list(tcp)

    @property
    def moving(self) -> bool:
        with self._lock:
            return self.mode != "idle"

    # --- motion commands ------------------------------------------------------------------
    def move_joints(self, target: Sequence[float], v: float, a: float) -> None:
        """Joint-space move: all joints start and stop together, the slowest sets the pace."""
        target_arr = np.array(target, dtype=float)
        self._check_range(target_arr)
        with self._lock:
            delta = target_arr - self.q
            v_j = np.minimum(max(v, 1e-6), self.vmax)
            a_j = np.minimum(max(a, 1e-6), self.amax)
            durations = [_Profile(abs(d), vv, aa).total for d, vv, aa in zip(delta, v_j, a_j, strict=True)]
            lead = int(np.argmax(durations))
            self._profile = _Profile(abs(delta[lead]), float(v_j[lead]), float(a_j[lead]))
            self._start, self._delta, self._t = self.q.copy(), delta, 0.0
            self.target_q = target_arr
            self.mode = "move_joints"

    def move_linear(self, pose: Sequence[float], v: float, a: float) -> None:
        """Straight-line TCP move: position along the segment, orientation about one axis."""
        with self._lock:
            start = kin.pose_to_matrix(kin.forward(self.q, self.tcp))
            goal = kin.pose_to_matrix(pose)
            # Reachability of the end point is checked before moving, as the controller does.
            self.target_q = np.array(kin.inverse_nearest(pose, self.q, self.tcp, self._limits()))
            p0, p1 = start[:3, 3], goal[:3, 3]
            rel = matrix_to_rotvec(start[:3, :3].T @ goal[:3, :3])
            length = float(np.linalg.norm(p1 - p0))
            angle = float(np.linalg.norm(rel))
            # A pure reorientation is paced by v read as rad/s, as movel does for rotations.
            self._profile = _Profile(max(length, angle, 1e-9), max(v, 1e-6), max(a, 1e-6))
            self._line = (p0, p1, start[:3, :3], rel)
            self._t = 0.0
            self.mode = "move_linear"

    def servo(self, target: Sequence[float], lookahead: float, gain: float) -> None:
        """Track ``target`` with a first-order lag; lookahead and gain set the time constant."""
        target_arr = np.array(target, dtype=float)
        self._check_range(target_arr)
        with self._lock:
            self._servo_target = target_arr
            self.target_q = target_arr
            self._servo_tau = max(lookahead * 300.0 / max(gain, 1.0), 1e-3)
            self.mode = "servo"

    def speed(self, qd: Sequence[float], a: float) -> None:
        with self._lock:
            self._speed_target = np.clip(np.array(qd, dtype=float), -self.vmax, self.vmax)
            self._speed_acc = max(a, 1e-6)
            self.mode = "speed"

    def stop(self, deceleration: float) -> None:
        """Decelerate every joint to rest at ``deceleration`` rad/s^2."""
        with self._lock:
            if self.mode == "idle":
                return
            self._stop_dec = np.full(6, max(deceleration, 1e-3))
            self.mode = "stopping"

    def halt(self) -> None:
        """Stop dead (protective stop category 1 is modelled as an immediate stop)."""
        with self._lock:
            self.qd = np.zeros(6)
            self.target_q = self.q.copy()
            self.mode = "idle"

    # --- time -------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance the active motion by ``dt`` seconds."""
        if dt <= 0:
            return
        with self._lock:
            mode = self.mode
            if mode == "move_joints":
                self._t += dt
                s, sd = self._profile.at(self._t)
                length = self._profile.length or 1.0
                self.q = self._start + self._delta * (s / length)
                self.qd = self._delta * (sd / length)
                if self._t >= self._profile.total:
                    self.q, self.qd, self.mode = self.target_q.copy(), np.zeros(6), "idle"
            elif mode == "move_linear":
                self._step_linear(dt)
            elif mode == "servo":
                err = self._servo_target - self.q
                # First-order approach, capped so the arm can still brake within its acceleration.
                speed = np.minimum(
                    np.abs(err) / max(self._servo_tau, dt), np.sqrt(2 * self.amax * np.abs(err))
                )
                self._apply_velocity(np.sign(err) * speed, dt)
            elif mode == "speed":
                self._apply_velocity(self._speed_target, dt, acc=np.full(6, self._speed_acc))
            elif mode == "stopping":
                self._apply_velocity(np.zeros(6), dt, acc=self._stop_dec)
                if not self.qd.any():
                    self.target_q, self.mode = self.q.copy(), "idle"

    def _step_linear(self, dt: float) -> None:
        p0, p1, r0, rel = self._line
        self._t += dt
        s, _ = self._profile.at(self._t)
        frac = s / self._profile.length
        t = np.eye(4)
        t[:3, 3] = p0 + (p1 - p0) * frac
        t[:3, :3] = r0 @ rotvec_to_matrix(rel * frac)
        try:
            q = np.array(kin.inverse_nearest(kin.matrix_to_pose(t), self.q, self.tcp, self._limits()))
        except kin.IKError as exc:
            self.fault = f"movel: {exc}"
            self.qd, self.mode = np.zeros(6), "idle"
            return
        self.qd = (q - self.q) / dt
        self.q = q
        if self._t >= self._profile.total:
            self.qd, self.mode = np.zeros(6), "idle"

    def _apply_velocity(self, desired: np.ndarray, dt: float, acc: np.ndarray | None = None) -> None:
        acc = self.amax if acc is None else acc
        desired = np.clip(desired, -self.vmax, self.vmax)
        change = np.clip(desired - self.qd, -acc * dt, acc * dt)
        self.qd = self.qd + change
        q = self.q + self.qd * dt
        over = np.abs(q) > UR10E_POSITION_LIMIT
        if over.any():
            q = np.clip(q, -UR10E_POSITION_LIMIT, UR10E_POSITION_LIMIT)
            self.qd[over] = 0.0
            self.fault = f"joint {int(np.argmax(over))} reached its position limit"
        self.q = q

    def _limits(self) -> list[tuple[float, float]]:
        return [(-UR10E_POSITION_LIMIT, UR10E_POSITION_LIMIT)] * 6

    def _check_range(self, q: np.ndarray) -> None:
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ValueError(f"expected six finite joint values, got {q.tolist()}")
        bad = np.abs(q) > UR10E_POSITION_LIMIT + 1e-9
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"joint {i} target {q[i]:.4f} rad is outside +-{UR10E_POSITION_LIMIT:.4f} rad")
