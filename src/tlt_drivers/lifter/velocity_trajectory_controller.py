"""The lifter's velocity trajectory controller (paper §V.B.1): joint trajectories in, counts/s out.

The paper's custom ros2_control controller turns the points of a joint trajectory into motor
velocities in encoder counts per second, which the hardware interface sends to the Teensy each
cycle. This one samples the trajectory at the cycle time (cubic Hermite between points that carry
velocities, linear otherwise), adds a proportional correction towards the sampled position, clamps
to the joint's speed limit and scales by the joint's counts per metre.

It reads the encoder positions (m) each cycle and checks them against the tolerances of the goal,
in the manner of ros2_control's JointTrajectoryController: during the motion each joint must stay
within its path tolerance of the sampled position (else the goal aborts, naming the joint); after
the last point's time, every joint must come within its goal tolerance before the goal time
tolerance runs out (else it aborts). A tolerance of 0 takes the configured default; a negative one
means no limit. Goals with unknown joints, badly timed points, or positions or speeds outside the
configured limits are refused by :meth:`VelocityTrajectoryController.validate`, naming the joint
and the limit. Starting a new goal replaces the running one.
"""

from __future__ import annotations

import bisect
import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .config import ControllerConfig, JointConfig


class GoalRejected(ValueError):
    """A goal the controller will not execute. ``invalid_joints`` tells unknown joints apart."""

    def __init__(self, message: str, *, invalid_joints: bool = False) -> None:
        super().__init__(message)
        self.invalid_joints = invalid_joints


class Outcome(enum.Enum):
    IDLE = "idle"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    PATH_TOLERANCE_VIOLATED = "path tolerance violated"
    GOAL_TOLERANCE_VIOLATED = "goal tolerance violated"


@dataclass(frozen=True)
class TrajectoryPoint:
    """Positions (m) of the goal's joints at ``time_s`` after the start; velocities optional."""

    time_s: float
    positions: tuple[float, ...]
    velocities: tuple[float, ...] = ()


@dataclass
class ControllerStep:
    """What one update decided: the command for every motor and the tracking of the goal's joints."""

    outcome: Outcome
    commands: list[int]
    desired: list[float] = field(default_factory=list)
    desired_velocity: list[float] = field(default_factory=list)
    actual: list[float] = field(default_factory=list)
    message: str = ""

    @property
    def errors(self) -> list[float]:
        return [d - a for d, a in zip(self.desired, self.actual, strict=True)]


class VelocityTrajectoryController:
    """Executes one trajectory at a time over the four lifter joints."""

    def __init__(self, joints: Sequence[JointConfig], config: ControllerConfig | None = None) -> None:
        self.joints = tuple(joints)
        self.config = config or ControllerConfig()
        self._index = {j.name: i for i, j in enumerate(self.joints)}
        self.outcome = Outcome.IDLE
        self._names: tuple[str, ...] = ()
        self._slots: tuple[int, ...] = ()
        self._points: list[TrajectoryPoint] = []
        self._times: list[float] = []
        self._start = 0.0
        self._path_tol: list[float] = []
        self._goal_tol: list[float] = []
        self._goal_time_tol = 0.0

    @property
    def active(self) -> bool:
        return self.outcome == Outcome.RUNNING

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    # --- goals --------------------------------------------
    def validate(self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint]) -> None:
        """Raise :class:`GoalRejected` when the goal cannot be executed as given."""
        if not joint_names:
            raise GoalRejected("the trajectory names no joints", invalid_joints=True)
        if len(set(joint_names)) != len(joint_names):
            raise GoalRejected(f"joint names repeat: {list(joint_names)}", invalid_joints=True)
        for name in joint_names:
            if name not in self._index:
                known = ", ".join(self._index)
                raise GoalRejected(f"unknown joint {name!r} (lifter joints: {known})", invalid_joints=True)
        if not points:
            raise GoalRejected("the trajectory has no points")
        joints = [self.joints[self._index[n]] for n in joint_names]
        previous_time = -1.0
        for k, point in enumerate(points):
            if len(point.positions) != len(joint_names):
                raise GoalRejected(
                    f"point {k}: {len(point.positions)} positions for {len(joint_names)} joints"
                )
            if point.velocities and len(point.velocities) != len(joint_names):
                raise GoalRejected(
                    f"point {k}: {len(point.velocities)} velocities for {len(joint_names)} joints"
                )
            if point.time_s <= previous_time or point.time_s < 0:
                raise GoalRejected(f"point {k}: time_from_start {point.time_s} s does not increase")
            previous_time = point.time_s
            for j, p in zip(joints, point.positions, strict=True):
                if p > j.max_position_m:
                    raise GoalRejected(
                        f"point {k}: joint {j.name} position {p} m exceeds its limit "
                        f"max_position_m = {j.max_position_m} m"
                    )
                if p < j.min_position_m:
                    raise GoalRejected(
                        f"point {k}: joint {j.name} position {p} m is below its limit "
                        f"min_position_m = {j.min_position_m} m"
                    )
            for j, v in zip(joints, point.velocities or (0.0,) * len(joints), strict=True):
                if abs(v) > j.max_velocity_m_s:
                    raise GoalRejected(
                        f"point {k}: joint {j.name} velocity {v} m/s exceeds its limit "
                        f"max_velocity_m_s = {j.max_velocity_m_s} m/s"
                    )
        for k in range(1, len(points)):
            dt = points[k].time_s - points[k - 1].time_s
            for i, j in enumerate(joints):
                speed = abs(points[k].positions[i] - points[k - 1].positions[i]) / dt
                if speed > j.max_velocity_m_s * (1 + 1e-9):
                    raise GoalRejected(
                        f"segment to point {k}: joint {j.name} needs {speed:.4g} m/s, above its limit "
                        f"max_velocity_m_s = {j.max_velocity_m_s} m/s"
                    )

    def start(
        self,
        joint_names: Sequence[str],
        points: Sequence[TrajectoryPoint],
        now: float,
        actual_positions: Sequence[float],
        *,
        path_tolerance: Mapping[str, float] | None = None,
        goal_tolerance: Mapping[str, float] | None = None,
        goal_time_tolerance: float = 0.0,
    ) -> None:
        """Validate and start a goal at time ``now`` from ``actual_positions`` (all four joints, m),
        replacing any running goal. Raises :class:`GoalRejected` and keeps nothing on a bad goal.

        When the first point lies after ``now``, the trajectory starts from where the joints are,
        so the lifter moves there smoothly instead of jumping."""
        points = list(points)
        self.validate(joint_names, points)
        slots = tuple(self._index[n] for n in joint_names)
        # clamped into the limits: an encoder a hair outside them must not make the goal invalid
        start_positions = tuple(
            min(max(actual_positions[s], self.joints[s].min_position_m), self.joints[s].max_position_m)
            for s in slots
        )
        if points[0].time_s > 0:
            start_point = TrajectoryPoint(0.0, start_positions, (0.0,) * len(slots))
            self.validate(joint_names, [start_point, *points])
            points.insert(0, start_point)
        cfg = self.config
        self._names = tuple(joint_names)
        self._slots = slots
        self._points = points
        self._times = [p.time_s for p in points]
        self._start = now
        self._path_tol = [
            _tolerance((path_tolerance or {}).get(n, 0.0), cfg.default_path_tolerance_m) for n in joint_names
        ]
        self._goal_tol = [
            _tolerance((goal_tolerance or {}).get(n, 0.0), cfg.default_goal_tolerance_m) for n in joint_names
        ]
        self._goal_time_tol = (
            goal_time_tolerance if goal_time_tolerance > 0 else cfg.default_goal_time_tolerance_s
        )
        self.outcome = Outcome.RUNNING

    def stop(self) -> None:
        """Drop the running goal (cancelled, replaced from outside, or a fault); motors stop."""
        self.outcome = Outcome.IDLE

    # --- control cycle --------------------------------------------
    def update(self, now: float, actual_positions: Sequence[float]) -> ControllerStep:
        """One control cycle: the counts/s command for each motor and how the goal stands.

        Joints the goal does not name, and every joint once the goal has ended, get 0."""
        commands = [0] * len(self.joints)
        if self.outcome != Outcome.RUNNING:
            return ControllerStep(self.outcome, commands)
        t = now - self._start
        desired, desired_vel = self._sample(t)
        actual = [actual_positions[s] for s in self._slots]
        step = ControllerStep(Outcome.RUNNING, commands, desired, desired_vel, actual)
        end = self._times[-1]
        errors = step.errors
        if t <= end:
            for i, err in enumerate(errors):
                if abs(err) > self._path_tol[i]:
                    return self._finish(
                        step,
                        Outcome.PATH_TOLERANCE_VIOLATED,
                        f"joint {self._names[i]}: position error {abs(err):.4f} m exceeds the path "
                        f"tolerance {self._path_tol[i]} m at t = {t:.2f} s",
                    )
        else:
            worst = max(range(len(errors)), key=lambda i: abs(errors[i]) - self._goal_tol[i])
            if all(abs(e) <= tol for e, tol in zip(errors, self._goal_tol, strict=True)):
                return self._finish(step, Outcome.SUCCEEDED, "goal reached within tolerance")
            if t > end + self._goal_time_tol:
                return self._finish(
                    step,
                    Outcome.GOAL_TOLERANCE_VIOLATED,
                    f"joint {self._names[worst]}: position error {abs(errors[worst]):.4f} m exceeds the goal "
                    f"tolerance {self._goal_tol[worst]} m {self._goal_time_tol} s after the goal time",
                )
        for i, slot in enumerate(self._slots):
            joint = self.joints[slot]
            velocity = desired_vel[i] + self.config.position_gain * errors[i]
            velocity = max(-joint.max_velocity_m_s, min(joint.max_velocity_m_s, velocity))
            commands[slot] = round(velocity * joint.counts_per_m)
        return step

    def _finish(self, step: ControllerStep, outcome: Outcome, message: str) -> ControllerStep:
        self.outcome = outcome
        step.outcome = outcome
        step.message = message
        step.commands = [0] * len(self.joints)
        return step

    def _sample(self, t: float) -> tuple[list[float], list[float]]:
        points, times = self._points, self._times
        if t >= times[-1]:
            return list(points[-1].positions), [0.0] * len(self._slots)
        if t <= times[0]:
            return list(points[0].positions), [0.0] * len(self._slots)
        k = bisect.bisect_right(times, t)
        a, b = points[k - 1], points[k]
        h = b.time_s - a.time_s
        s = (t - a.time_s) / h
        positions, velocities = [], []
        for i in range(len(self._slots)):
            p0, p1 = a.positions[i], b.positions[i]
            if a.velocities and b.velocities:
                m0, m1 = a.velocities[i] * h, b.velocities[i] * h
                h00, h10, h01, h11 = (
                    2 * s**3 - 3 * s**2 + 1,
                    s**3 - 2 * s**2 + s,
                    -2 * s**3 + 3 * s**2,
                    s**3 - s**2,
                )
                d00, d10, d01, d11 = (
                    6 * s**2 - 6 * s,
                    3 * s**2 - 4 * s + 1,
                    -6 * s**2 + 6 * s,
                    3 * s**2 - 2 * s,
                )
                positions.append(h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1)
                velocities.append((d00 * p0 + d10 * m0 + d01 * p1 + d11 * m1) / h)
            else:
                positions.append(p0 + s * (p1 - p0))
                velocities.append((p1 - p0) / h)
        return positions, velocities


def _tolerance(value: float, default: float) -> float:
    if value < 0:
        return float("inf")
    return value if value > 0 else default


__all__ = ["ControllerStep", "GoalRejected", "Outcome", "TrajectoryPoint", "VelocityTrajectoryController"]
