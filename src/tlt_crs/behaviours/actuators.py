"""Lifter, gripper and camera-mount behaviours of the CRS, driven and confirmed by sensors.

Every step is a guard and the work, ``Fallback(memory)[sensor condition?, Sequence(memory)[command,
wait for the sensor]]``, so a step already true by the sensors is skipped (after a resume, a
restart or a fault) and a step is only done when the sensors say so (paper §V.C.2):

* Top Grippers engaged/disengaged: ``GripperState.engaged`` on ``/top_grippers/state``; commanded
  by ``Float64MultiArray`` on ``/top_grippers/position_command`` (group position controller).
* Active Grippers engaged/disengaged: ``GripperState.engaged`` on ``/active_grippers/state``;
  commanded by ``FollowJointTrajectory`` on ``/active_grippers/follow_joint_trajectory``.
* Lifter in CRS Control: ``LifterState.state``; requested with ``SetLifterMode`` on ``/lifter/set_mode``.
* Lifter raised/lowered: the linear encoders (``LifterState.encoder_positions``) within
  ``lifter.tolerance_m`` of the target; moved by ``FollowJointTrajectory`` on the lifter joints at
  blackboard ``lifter_speed``.

Trajectory goals are :class:`MotionGoal`\\ s: on Pause the CRS node pre-empts a running one (the
goal is canceled, so the controller holds position) and on Resume it starts again from where the
joints stand.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import py_trees
from py_trees.common import Status

from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import ActionGoal, ServiceCall, TopicCondition
from tlt_common.ros.stamps import set_stamp, stamp_seconds
from tlt_crs.context import CrsContext

Predicate = Callable[[Any], bool]
LIFTER_INITIALIZING = 0  # LifterState.STATE_INITIALIZING
LIFTER_CRS_CONTROL = 2  # LifterState.STATE_CRS_CONTROL / SetLifterMode.MODE_CRS_CONTROL
LIFTER_SAFE = 3


def engaged(msg: Any) -> bool:
    return not msg.fault and len(msg.engaged) > 0 and all(msg.engaged)


def disengaged(msg: Any) -> bool:
    return not msg.fault and len(msg.engaged) > 0 and not any(msg.engaged)


def lifter_at(target: float, tolerance: float) -> Predicate:
    def at(msg: Any) -> bool:
        return bool(msg.link_ok) and all(abs(p - target) <= tolerance for p in msg.encoder_positions)

    return at


def lifter_in(state: int) -> Predicate:
    return lambda msg: bool(msg.link_ok) and msg.state == state


CAMERA_MOUNT_SETTLED_RAD = 0.005  # a ZED ~1 m from the joints it inspects: 5 mm
CAMERA_MOUNT_STILL_RAD_S = 0.01


class WaitFor(Action):
    """Wait until ``predicate`` holds on the latest message of ``topic`` (a sensor confirmation).

    Reads: the topic through the context's cache. Writes: nothing.
    RUNNING: not yet true (or no fresh message). SUCCESS: true on a message ≤ ``sensor_max_age_s``
    old. FAILURE: not true within ``timeout`` seconds of mission time (the last state is reported).
    """

    def __init__(
        self, name: str, ctx: CrsContext, topic: str, msg_type: Any, predicate: Predicate, timeout: float
    ):
        super().__init__(name)
        self.ctx = ctx
        self.topic = topic
        self.predicate = predicate
        self.timeout = timeout
        self._started = 0.0
        ctx.cache.watch(topic, msg_type)

    def initialise(self) -> None:
        self._started = self.ctx.clock()

    def update(self) -> Status:
        entry = self.ctx.cache.latest(self.topic)
        fresh = (
            entry is not None
            and self.ctx.ros_seconds() - entry[1] <= self.ctx.config.timeouts.sensor_max_age_s
        )
        if fresh and entry is not None and self.predicate(entry[0]):
            self.feedback_message = f"'{self.topic}' confirms"
            return Status.SUCCESS
        if self.ctx.clock() - self._started > self.timeout:
            if entry is None:
                return self.fail(f"no message on '{self.topic}' within {self.timeout:g} s")
            if not fresh:
                return self.fail(f"'{self.topic}' stale; not confirmed within {self.timeout:g} s")
            return self.fail(
                f"'{self.topic}' did not confirm within {self.timeout:g} s: {_describe(entry[0])}"
            )
        self.feedback_message = f"waiting for '{self.topic}'"
        return Status.RUNNING


def _describe(msg: Any) -> str:
    if hasattr(msg, "engaged"):
        return f"engaged={list(msg.engaged)} fault={msg.fault_reason or msg.fault}"
    if hasattr(msg, "encoder_positions"):
        return (
            f"state={msg.state} positions={[round(p, 4) for p in msg.encoder_positions]} fault={msg.fault!r}"
        )
    return repr(msg)


class PublishCommand(Action):
    """Publish ``make()`` on a topic once.

    Writes: the topic. SUCCESS at once; FAILURE if the message cannot be built.
    """

    def __init__(self, name: str, publisher: Any, make: Callable[[], Any]) -> None:
        super().__init__(name)
        self.publisher = publisher
        self.make = make

    def update(self) -> Status:
        try:
            msg = self.make()
        except Exception as exc:
            return self.fail(f"cannot build command: {exc}")
        self.publisher.publish(msg)
        self.feedback_message = "commanded"
        return Status.SUCCESS


class MotionGoal(ActionGoal):
    """A trajectory goal of a CRS actuator; the node pre-empts it on Pause (see module docstring).

    Waits for the result as long as the trajectory itself takes plus ``margin``: a raise by a bay
    (0.75 m at 0.01 m/s) takes 75 s, longer than any fixed bound for a gripper's motion (a fixed
    60 s bound would fault the build with "no result" while the lifter is still raising).
    """

    hold_on_pause = True

    def __init__(self, name: str, node: Any, action_type: Any, action_name: str, goal: Callable[[], Any],
                 *, margin: float, **kwargs: Any) -> None:  # fmt: skip
        def build() -> Any:
            built = goal()
            points = built.trajectory.points
            self.result_timeout = (stamp_seconds(points[-1].time_from_start) if points else 0.0) + margin
            return built

        super().__init__(name, node, action_type, action_name, build, result_timeout=margin, **kwargs)


def trajectory_goal(joints: tuple[str, ...], positions: list[float], seconds: float) -> Any:
    from tlt_interfaces.action import FollowJointTrajectory
    from trajectory_msgs.msg import JointTrajectoryPoint

    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = list(joints)
    point = JointTrajectoryPoint()
    point.positions = [float(p) for p in positions]
    seconds = max(seconds, 0.05)
    set_stamp(point.time_from_start, seconds)
    goal.trajectory.points = [point]
    return goal


def trajectory_ok(result: Any) -> tuple[bool, str]:
    return result.error_code == 0, f"error {result.error_code}: {result.error_string}"


class Actuators:
    """Builds the actuator subtrees of one context (shared publishers and sensor topics)."""

    def __init__(self, ctx: CrsContext) -> None:
        from std_msgs.msg import Float64MultiArray
        from tlt_interfaces.msg import GripperState, LifterState

        self.ctx = ctx
        self.GripperState, self.LifterState, self.Float64MultiArray = (
            GripperState,
            LifterState,
            Float64MultiArray,
        )
        self.top_state = ros_names.state_topic(ros_names.TOP_GRIPPERS)
        self.active_state = ros_names.state_topic(ros_names.ACTIVE_GRIPPERS)
        self.lifter_state = ros_names.state_topic(ros_names.LIFTER)
        self.top_command = ctx.node.create_publisher(
            Float64MultiArray, ros_names.position_command_topic(ros_names.TOP_GRIPPERS), 10
        )

    def _condition(self, name: str, topic: str, msg_type: Any, predicate: Predicate) -> TopicCondition:
        return TopicCondition(
            name,
            self.ctx.cache,
            topic,
            msg_type,
            predicate,
            max_age=self.ctx.config.timeouts.sensor_max_age_s,
        )

    def _guarded(
        self, name: str, guard: py_trees.behaviour.Behaviour, work: list[Any]
    ) -> py_trees.behaviour.Behaviour:
        return py_trees.composites.Selector(
            name,
            memory=True,
            children=[guard, py_trees.composites.Sequence(f"Do {name}", memory=True, children=work)],
        )

    def _goal(self, name: str, action: str, goal: Callable[[], Any]) -> MotionGoal:
        from tlt_interfaces.action import FollowJointTrajectory

        return MotionGoal(
            name,
            self.ctx.node,
            FollowJointTrajectory,
            action,
            goal,
            server_timeout=self.ctx.config.timeouts.service_s,
            margin=self.ctx.config.timeouts.actuator_s,
            result_ok=trajectory_ok,
            clock=self.ctx.clock,
        )

    # ----- grippers -----
    def top_grippers(self, engage: bool) -> py_trees.behaviour.Behaviour:
        setup, verb = self.ctx.config.top_grippers, "Engage" if engage else "Disengage"
        predicate = engaged if engage else disengaged
        stroke = setup.engage if engage else setup.disengage

        def command() -> Any:
            return self.Float64MultiArray(data=[stroke] * len(setup.joints))

        return self._guarded(
            f"{verb} Top Grippers",
            self._condition(f"Top Grippers {verb}d?", self.top_state, self.GripperState, predicate),
            [
                PublishCommand(f"Command Top Grippers {verb}", self.top_command, command),
                WaitFor(
                    f"Wait Top Grippers {verb}d",
                    self.ctx,
                    self.top_state,
                    self.GripperState,
                    predicate,
                    self.ctx.config.timeouts.actuator_s,
                ),
            ],
        )

    def active_grippers(self, engage: bool) -> py_trees.behaviour.Behaviour:
        setup, verb = self.ctx.config.active_grippers, "Engage" if engage else "Disengage"
        predicate = engaged if engage else disengaged
        position = setup.engage if engage else setup.disengage
        action = ros_names.trajectory_action(ros_names.ACTIVE_GRIPPERS)
        return self._guarded(
            f"{verb} Active Grippers",
            self._condition(f"Active Grippers {verb}d?", self.active_state, self.GripperState, predicate),
            [
                self._goal(
                    f"Move Active Grippers {verb}",
                    action,
                    lambda: trajectory_goal(setup.joints, [position] * len(setup.joints), setup.move_time_s),
                ),
                WaitFor(
                    f"Wait Active Grippers {verb}d",
                    self.ctx,
                    self.active_state,
                    self.GripperState,
                    predicate,
                    self.ctx.config.timeouts.actuator_s,
                ),
            ],
        )

    # ----- lifter -----
    def lifter_crs_control(self) -> py_trees.behaviour.Behaviour:
        from tlt_interfaces.srv import SetLifterMode

        predicate = lifter_in(LIFTER_CRS_CONTROL)
        return self._guarded(
            "Lifter CRS Control",
            self._condition("Lifter In CRS Control?", self.lifter_state, self.LifterState, predicate),
            [
                # Fig. 41: the firmware takes no mode request until it has finished initializing.
                WaitFor(
                    "Wait Lifter Initialized",
                    self.ctx,
                    self.lifter_state,
                    self.LifterState,
                    lambda msg: bool(msg.link_ok) and msg.state != LIFTER_INITIALIZING,
                    self.ctx.config.timeouts.actuator_s,
                ),
                ServiceCall(
                    "Request CRS Control",
                    self.ctx.node,
                    SetLifterMode,
                    ros_names.LIFTER_SET_MODE,
                    lambda: SetLifterMode.Request(mode=LIFTER_CRS_CONTROL),
                    service_timeout=self.ctx.config.timeouts.service_s,
                    timeout=self.ctx.config.timeouts.service_s,
                    clock=self.ctx.clock,
                ),
                WaitFor(
                    "Wait Lifter CRS Control",
                    self.ctx,
                    self.lifter_state,
                    self.LifterState,
                    predicate,
                    self.ctx.config.timeouts.actuator_s,
                ),
            ],
        )

    def _lifter_positions(self) -> list[float]:
        entry = self.ctx.cache.latest(self.lifter_state)
        if entry is None:
            raise RuntimeError(f"no lifter state on '{self.lifter_state}'")
        return list(entry[0].encoder_positions)

    def lifter_goal(self, targets: Callable[[list[float]], list[float]]) -> Callable[[], Any]:
        """A goal builder moving the lifter joints from their encoder positions to ``targets(now)``."""
        setup = self.ctx.config.lifter

        def goal() -> Any:
            now = self._lifter_positions()
            target = targets(now)
            speed = float(self.ctx.board.get("lifter_speed", 0.02))
            distance = max(abs(t - p) for t, p in zip(target, now, strict=True))
            return trajectory_goal(setup.joints, target, distance / speed)

        return goal

    def lifter_move(self, verb: str, target: float) -> py_trees.behaviour.Behaviour:
        setup = self.ctx.config.lifter
        predicate = lifter_at(target, setup.tolerance_m)
        state = "Raised" if verb == "Raise" else "Lowered"
        return self._guarded(
            f"{verb} Lifter",
            self._condition(f"Lifter {state}?", self.lifter_state, self.LifterState, predicate),
            [
                self._goal(
                    f"Move Lifter {verb}",
                    ros_names.trajectory_action(ros_names.LIFTER),
                    self.lifter_goal(lambda now: [target] * len(now)),
                ),
                WaitFor(
                    f"Wait Lifter {state}",
                    self.ctx,
                    self.lifter_state,
                    self.LifterState,
                    predicate,
                    self.ctx.config.timeouts.actuator_s,
                ),
            ],
        )

    def compression(self) -> py_trees.behaviour.Behaviour:
        """Drive the lifter ``compression_force / lifter.compression_stiffness_n_per_m`` above its
        lowered position against the bay held by both gripper sets (Fig. 26). The target is absolute,
        so repeating the step after a fault does not add up."""
        setup = self.ctx.config.lifter

        def targets(now: list[float]) -> list[float]:
            travel = (
                float(self.ctx.board.get("compression_force", 50.0)) / setup.compression_stiffness_n_per_m
            )
            return [setup.lowered_m + travel for _ in now]

        return self._goal(
            "Apply Compression", ros_names.trajectory_action(ros_names.LIFTER), self.lifter_goal(targets)
        )

    # ----- camera mounts -----
    def cameras(self, inward: bool) -> py_trees.behaviour.Behaviour:
        """Turn the ZED mounts, then wait until their joint states stand still at the goal.

        The mounts' trajectory ends while the servos still trail it, and vision places a frame by
        the joint states near its stamp: a bay inspected as the mounts come to rest has every
        corner joint millimetres off, and a good bay fails."""
        from sensor_msgs.msg import JointState

        setup = self.ctx.config.camera_mounts
        positions = list(setup.inward if inward else setup.outward)
        way = "Inward" if inward else "Outward"

        def still(msg: Any) -> bool:
            at = dict(zip(msg.name, msg.position, strict=False))
            speeds = [abs(v) for v in msg.velocity]
            return (
                all(
                    abs(at.get(j, math.inf) - p) <= CAMERA_MOUNT_SETTLED_RAD
                    for j, p in zip(setup.joints, positions, strict=True)
                )
                and max(speeds, default=0.0) <= CAMERA_MOUNT_STILL_RAD_S
            )

        return py_trees.composites.Sequence(
            f"Rotate Cameras {way}",
            memory=True,
            children=[
                self._goal(
                    f"Turn Camera Mounts {way}",
                    ros_names.trajectory_action(ros_names.CAMERA_MOUNTS),
                    lambda: trajectory_goal(setup.joints, positions, setup.move_time_s),
                ),
                WaitFor(
                    f"Wait Cameras Still {way}",
                    self.ctx,
                    ros_names.joint_states_topic(ros_names.CAMERA_MOUNTS),
                    JointState,
                    still,
                    self.ctx.config.timeouts.actuator_s,
                ),
            ],
        )

    # ----- Figs. 18 and 19 -----
    def raise_payload(self) -> py_trees.behaviour.Behaviour:
        """Fig. 18: engage Active, disengage Top, lifter to CRS Control, raise."""
        return py_trees.composites.Sequence(
            "Raise Payload",
            memory=True,
            children=[
                self.active_grippers(True),
                self.top_grippers(False),
                self.lifter_crs_control(),
                self.lifter_move("Raise", self.raised_m()),
            ],
        )

    def raised_m(self) -> float:
        """Raise Payload's target: configured, or one of the mission's bay heights above lowered."""
        setup = self.ctx.config.lifter
        return setup.raised_m if setup.raised_m is not None else setup.lowered_m + self.ctx.mission.bay_height

    def lower_lifter(self) -> py_trees.behaviour.Behaviour:
        """Fig. 19: engage Top, disengage Active, lifter to CRS Control, lower."""
        return py_trees.composites.Sequence(
            "Lower Lifter",
            memory=True,
            children=[
                self.top_grippers(True),
                self.active_grippers(False),
                self.lifter_crs_control(),
                self.lifter_move("Lower", self.ctx.config.lifter.lowered_m),
            ],
        )


__all__ = [
    "Actuators",
    "MotionGoal",
    "PublishCommand",
    "WaitFor",
    "disengaged",
    "engaged",
    "lifter_at",
    "lifter_in",
    "trajectory_goal",
]
