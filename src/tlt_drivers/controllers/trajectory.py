"""Joint trajectory controller logic in the manner of ros2_control's JointTrajectoryController, without ROS.

A goal is a list of points (time from start, positions, optional velocities) for some of the
controller's joints. :meth:`JointTrajectoryController.start` validates it (known joints, strictly
increasing times, sizes, finite values inside the joint limits) and starts it from the joints'
actual positions; the goal it replaces ends as PREEMPTED. :meth:`update`, called once per control
cycle with the actual positions, returns the position command for every joint and judges the
running goal:

* between points the desired state is interpolated: linear when the points carry positions only,
  cubic (Hermite) when every point carries velocities;
* while the trajectory runs, a joint further than its path tolerance from the desired position
  aborts the goal (PATH_TOLERANCE_VIOLATED), unless the arm is within tolerance of where the path
  was up to ``path_lag_window`` seconds earlier: late along its path, not off it (a controller
  whose cycles were delayed); ``max_time_step`` bounds how far one cycle moves the trajectory on;
* after the last point's time, the goal SUCCEEDS once every joint is within its goal tolerance
  and, where the caller passes the joints' velocities, moves no faster than its goal velocity
  tolerance (ros2_control's ``stopped_velocity_tolerance``: a joint passing through its goal
  tolerance at speed has not arrived, and what the caller does next, a camera measuring the held
  part, expects the arm at rest), and has stayed so for ``goal_settle_s`` (an arm ringing about its
  goal passes through zero speed at each turn); it ABORTS (GOAL_TOLERANCE_VIOLATED) when that has
  not happened within the goal time tolerance.

After success the controller holds the final point; after an abort, a cancel or a hardware fault
it holds the position the joints had at that moment. Tolerances per joint follow
``tlt_interfaces/msg/JointTolerance``: 0 means the controller default, negative means no limit.
A ``motion_gate`` callable can refuse new goals with a reason (not calibrated, hardware fault).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5
HARDWARE_FAULT = -6
# Points of the path looked back at when judging an arm that is late along it.
LAG_SAMPLES = 10


class GoalStatus(enum.Enum):
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    ABORTED = "aborted"
    PREEMPTED = "preempted"
    CANCELED = "canceled"


@dataclass(frozen=True)
class TrajectoryPoint:
    time_from_start: float
    positions: tuple[float, ...]
    velocities: tuple[float, ...] = ()


@dataclass(frozen=True)
class TrajectoryGoal:
    joint_names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]
    path_tolerance: Mapping[str, float] = field(default_factory=dict)
    goal_tolerance: Mapping[str, float] = field(default_factory=dict)
    goal_time_tolerance: float = 0.0
    goal_velocity_tolerance: Mapping[str, float] = field(default_factory=dict)


@dataclass
class ExecutingGoal:
    """A goal the controller accepted; its status moves from RUNNING to one final status."""

    goal: TrajectoryGoal
    start_time: float
    path_tolerance: dict[str, float]
    goal_tolerance: dict[str, float]
    goal_time_tolerance: float
    start_positions: tuple[float, ...] = ()
    goal_velocity_tolerance: dict[str, float] = field(default_factory=dict)
    settled_since: float | None = None  # when the joints last came within every goal tolerance
    status: GoalStatus = GoalStatus.RUNNING
    error_code: int = SUCCESSFUL
    error_string: str = ""
    desired: dict[str, float] = field(default_factory=dict)
    desired_velocity: dict[str, float] = field(default_factory=dict)
    actual: dict[str, float] = field(default_factory=dict)
    elapsed: float = 0.0  # trajectory time reached, s (behind the clock after stalled cycles)
    last_update: float | None = None

    @property
    def done(self) -> bool:
        return self.status != GoalStatus.RUNNING

    def finish(self, status: GoalStatus, code: int, reason: str) -> None:
        if not self.done:
            self.status, self.error_code, self.error_string = status, code, reason


class JointTrajectoryController:
    """Trajectory execution over ``joints`` with ``limits[name] = (lower, upper)``."""

    def __init__(
        self,
        joints: Sequence[str],
        limits: Mapping[str, tuple[float, float]],
        *,
        path_tolerance: float = 0.2,
        goal_tolerance: float = 0.02,
        goal_time_tolerance: float = 0.5,
        goal_velocity_tolerance: float = -1.0,
        goal_settle_s: float = 0.0,
        motion_gate: Callable[[], str | None] | None = None,
        max_time_step: float | None = None,
        path_lag_window: float = 0.0,
    ) -> None:
        self.joints = list(joints)
        self.max_time_step = max_time_step
        self.path_lag_window = path_lag_window
        self.limits = dict(limits)
        self.default_path_tolerance = path_tolerance
        self.default_goal_tolerance = goal_tolerance
        self.default_goal_time_tolerance = goal_time_tolerance
        self.default_goal_velocity_tolerance = goal_velocity_tolerance
        self.goal_settle_s = goal_settle_s
        self.motion_gate = motion_gate
        self.hold: dict[str, float] = {}
        self.active: ExecutingGoal | None = None

    # --- goals ------------------------------------------------------------------------------------
    def validate(self, goal: TrajectoryGoal) -> tuple[int, str]:
        """(SUCCESSFUL, '') or (error code, reason naming the joint/point/limit)."""
        names = list(goal.joint_names)
        if not names:
            return INVALID_JOINTS, "the trajectory names no joints"
        if len(set(names)) != len(names):
            return INVALID_JOINTS, f"the trajectory names a joint twice: {names}"
        unknown = [n for n in names if n not in self.joints]
        if unknown:
            return INVALID_JOINTS, f"unknown joint(s) {unknown}; this controller has {self.joints}"
        for kind, tolerances in (
            ("path", goal.path_tolerance),
            ("goal", goal.goal_tolerance),
            ("goal velocity", goal.goal_velocity_tolerance),
        ):
            stray = [n for n in tolerances if n not in self.joints]
            if stray:
                return INVALID_JOINTS, f"{kind} tolerance for unknown joint(s) {stray}"
        if not goal.points:
            return INVALID_GOAL, "the trajectory has no points"
        previous = -math.inf
        for i, point in enumerate(goal.points):
            t = point.time_from_start
            if not math.isfinite(t) or t < 0 or t <= previous:
                return INVALID_GOAL, f"point {i}: time_from_start {t} is not after the previous point"
            previous = t
            if len(point.positions) != len(names):
                return INVALID_GOAL, f"point {i}: {len(point.positions)} positions for {len(names)} joints"
            if point.velocities and len(point.velocities) != len(names):
                return INVALID_GOAL, f"point {i}: {len(point.velocities)} velocities for {len(names)} joints"
            for name, value in zip(names, point.positions, strict=True):
                lower, upper = self.limits[name]
                if not math.isfinite(value):
                    return INVALID_GOAL, f"point {i}: joint {name!r} position {value} is not a number"
                if value < lower:
                    return (
                        INVALID_GOAL,
                        f"point {i}: joint {name!r} position {value} below lower limit {lower}",
                    )
                if value > upper:
                    return (
                        INVALID_GOAL,
                        f"point {i}: joint {name!r} position {value} above upper limit {upper}",
                    )
            if any(not math.isfinite(v) for v in point.velocities):
                return INVALID_GOAL, f"point {i}: a velocity is not a number"
        return SUCCESSFUL, ""

    def start(self, goal: TrajectoryGoal, now: float, actual: Mapping[str, float]) -> ExecutingGoal:
        """Accept ``goal`` (replacing the running one) or return it already ABORTED with the reason."""
        code, reason = self.validate(goal)
        if code == SUCCESSFUL and self.motion_gate is not None:
            refusal = self.motion_gate()
            if refusal:
                code, reason = HARDWARE_FAULT, refusal
        executing = ExecutingGoal(
            goal=goal,
            start_time=now,
            path_tolerance=self._tolerances(goal.path_tolerance, self.default_path_tolerance),
            goal_tolerance=self._tolerances(goal.goal_tolerance, self.default_goal_tolerance),
            goal_time_tolerance=goal.goal_time_tolerance
            if goal.goal_time_tolerance > 0
            else self.default_goal_time_tolerance,
            start_positions=tuple(actual.get(n, 0.0) for n in goal.joint_names),
            goal_velocity_tolerance=self._tolerances(
                goal.goal_velocity_tolerance, self.default_goal_velocity_tolerance
            ),
        )
        if code != SUCCESSFUL:
            executing.finish(GoalStatus.ABORTED, code, reason)
            return executing
        if self.active is not None and not self.active.done:
            self.active.finish(GoalStatus.PREEMPTED, SUCCESSFUL, "replaced by a new goal")
        self.active = executing
        return executing

    def _tolerances(self, given: Mapping[str, float], default: float) -> dict[str, float]:
        out = {}
        for name in self.joints:
            value = given.get(name, 0.0)
            out[name] = default if value == 0 else value
        return out

    def cancel(self, actual: Mapping[str, float]) -> None:
        """Stop the running goal where the joints stand."""
        if self.active is not None and not self.active.done:
            self.active.finish(GoalStatus.CANCELED, SUCCESSFUL, "canceled")
            self._hold_actual(actual)

    def fault(self, reason: str, actual: Mapping[str, float]) -> None:
        """The hardware failed: abort the running goal with HARDWARE_FAULT."""
        if self.active is not None and not self.active.done:
            self.active.finish(GoalStatus.ABORTED, HARDWARE_FAULT, reason)
            self._hold_actual(actual)

    def reset_hold(self, actual: Mapping[str, float]) -> None:
        """Hold the actual positions (after activation or recovery)."""
        self._hold_actual(actual)

    def _hold_actual(self, actual: Mapping[str, float]) -> None:
        for name in self.joints:
            if name in actual:
                self.hold[name] = actual[name]

    # --- control cycle -----------------------------------------------------------------------------
    def update(
        self, now: float, actual: Mapping[str, float], velocities: Mapping[str, float] | None = None
    ) -> dict[str, float]:
        """Position commands for every joint at ``now``; judges the running goal (its goal velocity
        tolerance only when the joints' ``velocities`` are given)."""
        for name in self.joints:
            self.hold.setdefault(name, actual.get(name, 0.0))
        commands = dict(self.hold)
        goal = self.active
        if goal is None or goal.done:
            return commands
        t = self._advance(goal, now)
        desired, desired_vel = sample(goal.goal, goal.start_positions, t)
        goal.desired, goal.desired_velocity = desired, desired_vel
        goal.actual = {n: actual[n] for n in goal.goal.joint_names}
        commands.update(desired)
        end = goal.goal.points[-1].time_from_start
        if t <= end:
            violations = self._path_violations(goal, t, desired, actual)
            if violations:
                name, want = next(iter(violations.items()))
                late = f", nor up to {self.path_lag_window:g} s earlier" if self.path_lag_window > 0 else ""
                goal.finish(
                    GoalStatus.ABORTED,
                    PATH_TOLERANCE_VIOLATED,
                    f"joint {name!r} is {abs(actual[name] - want):.4f} from the path "
                    f"(tolerance {goal.path_tolerance[name]}) at t={t:.3f} s{late}",
                )
                self._hold_actual(actual)
                return dict(self.hold)
            return commands
        final = dict(zip(goal.goal.joint_names, goal.goal.points[-1].positions, strict=True))
        off = {n: abs(actual[n] - final[n]) for n in final if goal.goal_tolerance[n] > 0}
        outside = {n: e for n, e in off.items() if e > goal.goal_tolerance[n]}
        vtol = goal.goal_velocity_tolerance
        moving = {n: abs(velocities[n]) for n in final
                  if velocities is not None and n in velocities and vtol.get(n, -1.0) > 0
                  and abs(velocities[n]) > vtol[n]}  # fmt: skip
        if not outside and not moving:
            if goal.settled_since is None:
                goal.settled_since = now
            if now - goal.settled_since >= self.goal_settle_s - 1e-9:  # clock sums round
                goal.finish(GoalStatus.SUCCEEDED, SUCCESSFUL, "")
                self.hold.update(final)
                return dict(self.hold)
        else:
            goal.settled_since = None
        if goal.settled_since is None and t > end + goal.goal_time_tolerance:
            if outside:
                name, error = max(outside.items(), key=lambda item: item[1])
                what = f"joint {name!r} is {error:.4f} from its goal (tolerance {goal.goal_tolerance[name]})"
            else:
                name, speed = max(moving.items(), key=lambda item: item[1])
                what = f"joint {name!r} still moves at {speed:.4f}/s at its goal (tolerance {vtol[name]})"
            goal.finish(
                GoalStatus.ABORTED,
                GOAL_TOLERANCE_VIOLATED,
                f"{what} {t - end:.3f} s after the trajectory's end "
                f"(goal time tolerance {goal.goal_time_tolerance} s)",
            )
            self._hold_actual(actual)
            return dict(self.hold)
        return commands

    def _path_violations(self, goal: ExecutingGoal, t: float, desired: Mapping[str, float],
                         actual: Mapping[str, float]) -> dict[str, float]:  # fmt: skip
        """The joints off the path at ``t`` (name -> desired position); none when the arm is on the
        path as it was up to ``path_lag_window`` earlier, i.e. merely late along it."""

        def off(want: Mapping[str, float]) -> dict[str, float]:
            tol = goal.path_tolerance
            return {n: w for n, w in want.items() if tol[n] > 0 and abs(actual[n] - w) > tol[n]}

        violations = off(desired)
        if not violations or self.path_lag_window <= 0:
            return violations
        for k in range(1, LAG_SAMPLES + 1):
            earlier = max(t - self.path_lag_window * k / LAG_SAMPLES, 0.0)
            if not off(sample(goal.goal, goal.start_positions, earlier)[0]):
                return {}
        return violations

    def _advance(self, goal: ExecutingGoal, now: float) -> float:
        """The goal's trajectory time at ``now``: the clock's, except that one cycle never moves it
        on by more than ``max_time_step``. A control loop that missed cycles (a starved process)
        then resumes the trajectory where it left it, slower, instead of finding the desired
        position far ahead of an arm that got no commands meanwhile."""
        step = now - (goal.start_time if goal.last_update is None else goal.last_update)
        if self.max_time_step is not None:
            step = min(step, self.max_time_step)
        goal.elapsed += max(step, 0.0)
        goal.last_update = now
        return goal.elapsed


def sample(
    goal: TrajectoryGoal, start_positions: Sequence[float], t: float
) -> tuple[dict[str, float], dict[str, float]]:
    """Desired positions and velocities at ``t`` seconds after the start.

    The first segment runs from the start positions (at rest, t=0) to the first point. Within a
    segment: cubic Hermite when both ends have velocities, else linear. After the end: the last point.
    """
    names = goal.joint_names
    points = goal.points
    cubic = all(p.velocities for p in points)
    prev_t, prev_pos = 0.0, tuple(start_positions)
    prev_vel: tuple[float, ...] = (0.0,) * len(names)
    for point in points:
        if t <= point.time_from_start:
            span = point.time_from_start - prev_t
            if span <= 0:
                return dict(zip(names, point.positions, strict=True)), dict.fromkeys(names, 0.0)
            s = max(0.0, (t - prev_t) / span)
            pos, vel = {}, {}
            for i, name in enumerate(names):
                p0, p1 = prev_pos[i], point.positions[i]
                if cubic:
                    v0, v1 = prev_vel[i] * span, point.velocities[i] * span
                    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
                    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
                    pos[name] = h00 * p0 + h10 * v0 + h01 * p1 + h11 * v1
                    d00, d10 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1
                    d01, d11 = -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
                    vel[name] = (d00 * p0 + d10 * v0 + d01 * p1 + d11 * v1) / span
                else:
                    pos[name] = p0 + (p1 - p0) * s
                    vel[name] = (p1 - p0) / span
            return pos, vel
        prev_t, prev_pos = point.time_from_start, point.positions
        prev_vel = point.velocities or (0.0,) * len(names)
    last = points[-1]
    return dict(zip(names, last.positions, strict=True)), dict.fromkeys(names, 0.0)


__all__ = [
    "GOAL_TOLERANCE_VIOLATED",
    "HARDWARE_FAULT",
    "INVALID_GOAL",
    "INVALID_JOINTS",
    "PATH_TOLERANCE_VIOLATED",
    "SUCCESSFUL",
    "ExecutingGoal",
    "GoalStatus",
    "JointTrajectoryController",
    "TrajectoryGoal",
    "TrajectoryPoint",
    "sample",
]
