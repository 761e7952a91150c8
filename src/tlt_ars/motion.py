"""Plan-and-execute motion behaviours (paper §V.D): "Approach Dispenser", "Move To Member
Inspection" and the rest are sequences of a plan request and its execution. The plans come from
:class:`~tlt_ars.motion_planner.MotionPlanner`, the ARS's interface to the planning package.

:func:`move` returns ``Sequence[Plan <name>, Execute <name>]``:

* :class:`PlanMotion` runs the planning in the context's planning thread (the tick never
  blocks) and leaves the trajectory in a :class:`TrajectorySlot`.
* :class:`ExecuteTrajectory` sends it to the UR driver's FollowJointTrajectory action
  (``ros_names.trajectory_action(ur(ars))``); when pre-empted (cancel, Pause, Stop) it cancels the
  goal, and the driver's controller holds the arm where it stands.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import py_trees
from py_trees.common import Status
from tlt_interfaces.action import FollowJointTrajectory
from tlt_interfaces.msg import JointTolerance

from tlt_ars.context import ArsContext
from tlt_ars.motion_planner import MotionGoal, MotionPlanner, PlannedMotion, duration_msg
from tlt_ars.planning.planner import PlanningFailed
from tlt_ars.planning.world import Width
from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import ActionGoal

# Largest joint offset (rad) between the arm and a trajectory's first point when it is sent.
START_TOLERANCE = 0.05


class TrajectorySlot:
    """The planned motion handed from a PlanMotion to its ExecuteTrajectory."""

    def __init__(self) -> None:
        self.motion: PlannedMotion | None = None


class PlanMotion(Action):
    """Plan one motion in the planning thread.

    Reads: the arm's JointState (start), the EE's width (calibrated) and the width last
    commanded, the mission state (tower), the held part, the other arm. Writes: the slot's
    trajectory; ``RequestData.targets[goal.key]`` when a candidate is chosen. RUNNING while the arm
    still moves (an aborted motion decelerating: a plan from a moving start would not match where
    the arm is when it is sent), while its joint state is stale (a gap of a second under load is no
    fault), while the EE's width is not known (no fresh state, or not calibrated since a fault) and
    while planning, together at most ``timeouts.planning_s``. A search that ran out of its time
    (``arm.planning_time_s``: wall-clock, so a loaded machine gives it less CPU) is run again from
    the same start with twice the time, while that still fits in ``timeouts.planning_s``. While the
    width slide moves (Extend Width beside the approach) the motion is checked over the rest of the
    slide's move; when no path clears that, RUNNING until the slide stands (at most
    ``timeouts.width_s`` more), then it is planned again. SUCCESS with a checked trajectory.
    FAILURE when no fresh arm state or calibrated width comes in time, when the goal cannot be
    built, or with the planner's reason.
    """

    def __init__(self, name: str, ctx: ArsContext, planner: MotionPlanner, goal: Callable[[], MotionGoal],
                 slot: TrajectorySlot) -> None:  # fmt: skip
        super().__init__(name)
        self.ctx, self.planner, self.goal, self.slot = ctx, planner, goal, slot
        self._future = None
        self._started = 0.0
        self._goal: MotionGoal | None = None
        self._start_q: np.ndarray | None = None
        self._width: Width | None = None
        self._sweep_blocked = False
        self._search_time = planner.search_time

    def initialise(self) -> None:
        self.slot.motion = None
        self._future = None
        self._started = self.ctx.clock()
        self._sweep_blocked = False
        self._search_time = self.planner.search_time

    def update(self) -> Status:
        if self._future is None:
            start, width = self.ctx.arm_q(), self.ctx.planning_width()
            limit = self.ctx.config.timeouts["planning_s"]
            waiting = None
            if start is None:
                stale = f"no fresh joint state on '{self.ctx.joint_topic}'"
                waiting = ("waiting for a fresh joint state", stale)
            elif not self._arm_stopped():
                waiting = ("waiting for the arm to stop", "the arm did not stop")
            elif width is None:
                # Gripper b and its gun ride the width slide: where they are is part of the plan. A
                # servo rebooted after a fault reads a wrong width until the EE recalibrates it,
                # which runs the slide to its limit switch: as long as a width move, not a plan.
                waiting = ("waiting for a calibrated end-effector width",
                           f"no calibrated end-effector width on '{self.ctx.ee_topic}'")  # fmt: skip
                limit += self.ctx.config.timeouts["width_s"]
            elif self._sweep_blocked and not np.isscalar(width):
                waiting = ("waiting for the end-effector width to stand",
                           f"the end-effector width did not reach {width[1]:.4f} m")  # fmt: skip
                limit += self.ctx.config.timeouts["width_s"]
            if waiting is not None:
                if self.ctx.clock() - self._started > limit:
                    return self.fail(f"{waiting[1]} within {limit:g} s")
                self.feedback_message = waiting[0]
                return Status.RUNNING
            try:
                self._goal = self.goal()
            except Exception as exc:
                return self.fail(f"cannot tell where to go: {exc}")
            self._submit(start, width)
            self.feedback_message = "planning"
            return Status.RUNNING
        if not self._future.done():
            if self.ctx.clock() - self._started > self.ctx.config.timeouts["planning_s"]:
                self._future.cancel()
                self._future = None
                return self.fail(f"planning took longer than {self.ctx.config.timeouts['planning_s']:g} s")
            return Status.RUNNING
        future, self._future = self._future, None
        try:
            motion = future.result()
        except PlanningFailed as exc:
            if not np.isscalar(self._width):
                # Nothing clears the slide's whole move: where it stands, something may.
                self._sweep_blocked = True
                self._started = self.ctx.clock()
                self.feedback_message = f"no path clears the moving width ({exc.reason}): waiting for it"
                return Status.RUNNING
            longer = 2.0 * self._search_time
            spent = self.ctx.clock() - self._started
            if exc.kind == "timeout" and spent + longer <= self.ctx.config.timeouts["planning_s"]:
                # The arm has not moved: the same start, with more time.
                self.ctx.node.get_logger().warning(
                    f"{self.name}: the search ran out of its {self._search_time:g} s ({exc.reason}); "
                    f"searching again for {longer:g} s"
                )
                self._search_time = longer
                self._submit(self._start_q, self._width)
                self.feedback_message = f"planning again with {longer:g} s to search"
                return Status.RUNNING
            return self.fail(f"planning failed ({exc.kind}): {exc.reason}")
        except Exception as exc:  # a planner bug must fail the request, not kill the tick
            return self.fail(f"planning failed: {exc!r}")
        self.slot.motion = motion
        goal = self._goal
        if goal is not None and goal.key and motion.target is not None:
            self.ctx.data.targets[goal.key] = motion.target
        self.feedback_message = f"planned {motion.duration:.2f} s"
        return Status.SUCCESS

    def _submit(self, start: np.ndarray, width: Width) -> None:
        data = self.ctx.data
        self._future = self.ctx.planning_pool.submit(
            self.planner.plan,
            start,
            self._goal,
            placed=self.ctx.state.placed(),
            bay=data.member.bay if data.member is not None else 1,
            carrying=data.holding,
            other_q=self.ctx.other_arm_q(),
            width=width,
            search_time=self._search_time,
        )
        self._start_q, self._width = start, width

    def _arm_stopped(self) -> bool:
        velocity = self.ctx.arm_velocity()
        return velocity is None or float(np.max(np.abs(velocity))) <= self.ctx.config.arm["stopped_velocity"]

    def terminate(self, new_status: Status) -> None:
        if self._future is not None:
            self._future.cancel()  # a plan already running finishes in its thread and is dropped
            self._future = None


class Settle(Action):
    """Wait until the arm has stood still for ``arm.settle_s`` of mission time.

    Reads: the arm's JointState (velocities, or positions tick to tick where it has none). Writes:
    nothing. RUNNING while the arm moves (faster than ``arm.stopped_velocity``), has not yet stood
    still long enough, or its joint state is stale (a gap of a second under load is no fault);
    SUCCESS then. FAILURE when the arm has not settled within ``timeouts.planning_s``, naming a
    stale joint state if that is why.
    """

    def __init__(self, name: str, ctx: ArsContext) -> None:
        super().__init__(name)
        self.ctx = ctx
        self._started = 0.0
        self._still_since: float | None = None

    def initialise(self) -> None:
        self._started = self.ctx.clock()
        self._still_since = None
        self._last: tuple[float, np.ndarray] | None = None

    def _moving(self, now: float, q: np.ndarray) -> bool:
        """Faster than ``stopped_velocity``, by the state's velocities or, where the driver sends
        none, by the positions since the last tick."""
        limit = self.ctx.config.arm["stopped_velocity"]
        velocity = self.ctx.arm_velocity()
        last, self._last = self._last, (now, q)
        if velocity is not None:
            return float(np.max(np.abs(velocity))) > limit
        if last is None or now <= last[0]:
            return True  # no speed to judge by yet
        return float(np.max(np.abs(q - last[1]))) / (now - last[0]) > limit

    def update(self) -> Status:
        now = self.ctx.clock()
        q = self.ctx.arm_q()
        if q is None or self._moving(now, np.asarray(q, dtype=float)):
            self._still_since = None
            if q is None:
                self._last = None  # judge the speed afresh once states come again
        elif self._still_since is None:
            self._still_since = now
        if self._still_since is not None and now - self._still_since >= self.ctx.config.arm["settle_s"]:
            return Status.SUCCESS
        limit = self.ctx.config.timeouts["planning_s"]
        if now - self._started > limit:
            why = f"no fresh joint state on '{self.ctx.joint_topic}'" if q is None else "still moving"
            return self.fail(f"the arm did not settle within {limit:g} s: {why}")
        self.feedback_message = "settling" if q is not None else "waiting for a fresh joint state"
        return Status.RUNNING


def _trajectory_ok(result: Any) -> tuple[bool, str]:
    code = getattr(result, "error_code", 0)
    return code == 0, f"error {code}: {getattr(result, 'error_string', '')}"


class ExecuteTrajectory(ActionGoal):
    """Send the slot's trajectory to the UR driver and follow it to its end.

    Reads: the slot. Writes: nothing. RUNNING while no fresh joint state has come to start from (up
    to ``timeouts.planning_s``) and while the arm moves (≤ duration +
    ``timeouts.trajectory_margin_s``). SUCCESS when the driver reports it reached the goal within
    tolerance. FAILURE on rejection, abort (tolerance, protective stop) or timeout, with the
    driver's reason. Pre-empted: the goal is canceled and the driver holds the arm.
    """

    def __init__(self, name: str, ctx: ArsContext, slot: TrajectorySlot) -> None:
        self.slot = slot
        self.ctx = ctx
        super().__init__(
            name,
            ctx.node,
            FollowJointTrajectory,
            ros_names.trajectory_action(ros_names.ur(ctx.ars)),
            self._make_goal,
            server_timeout=ctx.config.timeouts["server_s"],
            result_ok=_trajectory_ok,
            clock=ctx.clock,
        )

    def _make_goal(self) -> Any:
        if self.slot.motion is None:
            raise RuntimeError("nothing was planned")
        q = self.ctx.arm_q()
        start = np.asarray(self.slot.motion.trajectory.points[0].positions)
        if q is None:
            raise RuntimeError(f"no fresh joint state on '{self.ctx.joint_topic}' to start from")
        off = float(np.max(np.abs(q - start)))
        if off > START_TOLERANCE:
            # The path was checked from where the arm stood when it was planned, and only from there.
            raise RuntimeError(f"the arm is {off:.3f} rad from where this trajectory was planned from")
        arm = self.ctx.config.arm
        goal = FollowJointTrajectory.Goal()
        goal.trajectory = self.slot.motion.trajectory
        names = goal.trajectory.joint_names
        goal.path_tolerance = [JointTolerance(name=n, position=arm["path_tolerance"]) for n in names]
        goal.goal_tolerance = [JointTolerance(name=n, position=arm["goal_tolerance"]) for n in names]
        goal.goal_time_tolerance = duration_msg(arm["goal_time_tolerance_s"])
        return goal

    def initialise(self) -> None:
        super().initialise()
        self._waiting_since = self.ctx.clock()
        duration = self.slot.motion.duration if self.slot.motion is not None else 0.0
        self.result_timeout = duration + self.ctx.config.timeouts["trajectory_margin_s"]

    def update(self) -> Status:
        # The goal's start is checked against the arm's state when it is built; a gap in the joint
        # states while planning kept the executor busy is waited out, as PlanMotion does, up to
        # timeouts.planning_s, after which building the goal fails with the reason. So is a UR
        # driver reconnecting after a lost link (about a second): sent at once, the goal of the next
        # attempt would be aborted too, and a Retreat after the part was riveted fail its request.
        waited = self.ctx.clock() - self._waiting_since
        if self._send_future is None and waited <= self.ctx.config.timeouts["planning_s"]:
            if self.ctx.arm_q() is None:
                self.feedback_message = "waiting for a fresh joint state to start from"
                return Status.RUNNING
            if (down := self.ctx.arm_down()) is not None:
                self.feedback_message = f"waiting for the arm to be active again ({down})"
                return Status.RUNNING
        return super().update()


class RetryMotion(py_trees.decorators.Retry):
    """A motion tried again, planned afresh from where the arm stands, until it has failed
    ``attempts`` times; each failed attempt is logged with its reason, so a retry is never silent.

    Carries ``replan_on_resume``: ArsTree.hold() stops the whole motion and Resume plans it afresh.
    """

    replan_on_resume = True

    def __init__(self, name: str, ctx: ArsContext, attempt: py_trees.behaviour.Behaviour,
                 attempts: int) -> None:  # fmt: skip
        super().__init__(name, attempt, attempts)
        self.ctx = ctx

    def update(self) -> Status:
        status = super().update()
        if status == Status.RUNNING and self.decorated.status == Status.FAILURE:
            leaf = self.decorated
            while leaf.children:
                leaf = next((c for c in leaf.children if c.status == Status.FAILURE), leaf.children[-1])
            self.ctx.node.get_logger().warning(
                f"{self.name}: attempt {self.failures} of {self.num_failures} failed "
                f"({leaf.name}: {leaf.feedback_message}); planning again from where the arm stands"
            )
        return status


def move(
    name: str, ctx: ArsContext, planner: MotionPlanner, goal: Callable[[], MotionGoal]
) -> py_trees.behaviour.Behaviour:
    """A named motion: ``Sequence[Plan, Execute]`` (memory: a finished plan is not redone), tried
    up to ``arm.motion_attempts`` times in all (:class:`RetryMotion`). A search that ran out of
    time, or an execution the driver aborted because the arm trailed its path (a busy
    controller), is worth a fresh plan; a goal that cannot be reached fails every attempt alike."""
    slot = TrajectorySlot()
    attempts = ctx.config.arm["motion_attempts"]
    seq = py_trees.composites.Sequence(name if attempts <= 1 else "Attempt", memory=True)
    seq.add_children(
        [
            PlanMotion(f"Plan {name}", ctx, planner, goal, slot),
            ExecuteTrajectory(f"Execute {name}", ctx, slot),
        ]
    )
    if attempts <= 1:
        seq.replan_on_resume = True  # ArsTree.hold() stops the whole motion: Resume plans it afresh
        return seq
    return RetryMotion(name, ctx, seq, attempts)


__all__ = [
    "ExecuteTrajectory",
    "PlanMotion",
    "RetryMotion",
    "Settle",
    "TrajectorySlot",
    "move",
]
