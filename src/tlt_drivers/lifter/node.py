"""The ``lifter`` driver node: owns the serial link to the lifter's Teensy (paper §V.B.1, Fig. 9).

Publishes ``lifter/state`` (``tlt_interfaces/msg/LifterState``) every control cycle and
``lifter/hardware_status`` (``tlt_interfaces/msg/HardwareStatus``, component "lifter") at
``status_rate_hz``. Serves ``lifter/set_mode`` (``SetLifterMode``) and the action
``lifter/follow_joint_trajectory`` (``tlt_interfaces/action/FollowJointTrajectory``), recording
each goal once it ended on ``lifter/executed_trajectories``.

One timer at ``command_rate_hz`` runs the control cycle: read telemetry, run the velocity
trajectory controller, write the velocity command. Nothing blocks the executor except a mode
request, which waits at most ``answer_timeout_s`` for the firmware's answer. The action's execute
callback is a coroutine that waits for the control cycle to finish the goal, so goals never hold
up the timer. A goal is executed only while the firmware is in CRS Control (the CRS requests it
first, as in Figs. 18 and 19); goals outside the joint limits end at once with INVALID_GOAL and
the joint and limit named; a path-tolerance violation, the firmware leaving CRS Control, or a
link fault aborts the running goal. While the link is in fault the node stops commanding, reports
the fault on both topics and tries to reopen the port every ``reconnect_period_s``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.task import Future
from tlt_interfaces.action import FollowJointTrajectory
from tlt_interfaces.msg import HardwareStatus, LifterState
from tlt_interfaces.srv import SetLifterMode

from tlt_common import ros_names
from tlt_common.config_schema import ConfigError
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.periodic_timer import create_periodic_timer
from tlt_drivers.controllers import executed_trajectories
from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.loop_time import loop_clock
from tlt_drivers.node_main import Driver, DriverStartError, run_driver

from .config import DEFAULT_CONFIG, LifterConfig, load_lifter_config
from .protocol import FirmwareState
from .serial_interface import CommandRejected, LifterSerialInterface
from .velocity_trajectory_controller import (
    GoalRejected,
    Outcome,
    TrajectoryPoint,
    VelocityTrajectoryController,
)

STATE_TOPIC = ros_names.state_topic(ros_names.LIFTER)
STATUS_TOPIC = ros_names.hardware_status_topic(ros_names.LIFTER)
MODE_SERVICE = ros_names.LIFTER_SET_MODE
TRAJECTORY_ACTION = ros_names.trajectory_action(ros_names.LIFTER)

Result = FollowJointTrajectory.Result
# How a goal ended (the goal handle's method) -> its ExecutedTrajectory outcome.
_OUTCOMES = {
    "succeed": executed_trajectories.SUCCEEDED,
    "abort": executed_trajectories.ABORTED,
    "canceled": executed_trajectories.CANCELED,
}


@dataclass
class _Goal:
    handle: ServerGoalHandle
    done: Future


class LifterNode(LeanNode):
    """The driver node. ``hw`` is the hardware interface, ``controller`` the trajectory controller."""

    def __init__(self, config: LifterConfig, *, node_name: str = "lifter", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.config = config
        self.hw = LifterSerialInterface(config)
        self.controller = VelocityTrajectoryController(config.joints, config.controller)
        self._goal: _Goal | None = None
        self._reported: tuple[Lifecycle, str] | None = None
        self._last_reconnect = time.monotonic()
        self._loop_clock = loop_clock(self)
        self._state_pub = self.create_publisher(LifterState, STATE_TOPIC, 10)
        self._status_pub = self.create_publisher(HardwareStatus, STATUS_TOPIC, 10)
        self.create_service(SetLifterMode, MODE_SERVICE, self._on_set_mode)
        self._action = ActionServer(
            self,
            FollowJointTrajectory,
            TRAJECTORY_ACTION,
            execute_callback=self._execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=lambda _goal: CancelResponse.ACCEPT,
        )
        self._executed = executed_trajectories.ExecutedTrajectoryPublisher(self, ros_names.LIFTER)
        if self.hw.configure():
            self.hw.activate()
        else:
            self.get_logger().error(
                f"lifter link not up: {self.hw.fault}; retrying every {config.reconnect_period_s} s"
            )
        self._timer = create_periodic_timer(self, config.command_period_s, self._control_cycle)
        self._status_timer = create_periodic_timer(self, 1.0 / config.status_rate_hz, self._publish_status)

    # --- control cycle --------------------------------------------
    def _control_cycle(self) -> None:
        self._cycle()
        if (self.hw.state, self.hw.fault) != self._reported:
            self._publish_status()  # a change of health is reported at once, not at the next tick

    def _cycle(self) -> None:
        hw = self.hw
        now = time.monotonic()
        loop_now = self._loop_clock()  # the link watchdog's and trajectories' time base
        if hw.state == Lifecycle.ERROR:
            self._end_goal("abort", Result.HARDWARE_FAULT, f"lifter link fault: {hw.fault}")
            if now - self._last_reconnect >= self.config.reconnect_period_s:
                self._last_reconnect = now
                if hw.recover():
                    self.get_logger().info("lifter link recovered")
            self._publish_state()
            return
        hw.read(loop_now)
        if hw.state == Lifecycle.ERROR:
            self._last_reconnect = now
            self._end_goal("abort", Result.HARDWARE_FAULT, f"lifter link fault: {hw.fault}")
            self._publish_state()
            return
        self._run_controller()
        hw.write(loop_now)
        self._publish_state()

    def _run_controller(self) -> None:
        goal = self._goal
        if goal is None:
            self.hw.stop_motion()
            return
        if goal.handle.is_cancel_requested:
            self.controller.stop()
            self._end_goal("canceled", Result.SUCCESSFUL, "cancelled")
            return
        state = self.hw.firmware_state
        if state != FirmwareState.CRS_CONTROL:
            name = state.name if state is not None else "unknown"
            self._end_goal("abort", Result.HARDWARE_FAULT, f"lifter firmware left CRS Control (now {name})")
            return
        step = self.controller.update(self._loop_clock(), self._positions_m())
        try:
            self.hw.set_velocity_command(step.commands)
        except CommandRejected as exc:
            self._end_goal("abort", Result.INVALID_GOAL, str(exc))
            return
        if step.desired:
            feedback = FollowJointTrajectory.Feedback()
            feedback.header.stamp = self.get_clock().now().to_msg()
            feedback.joint_names = list(self.controller.joint_names)
            feedback.desired.positions = step.desired
            feedback.desired.velocities = step.desired_velocity
            feedback.actual.positions = step.actual
            feedback.error.positions = step.errors
            goal.handle.publish_feedback(feedback)
        if step.outcome == Outcome.SUCCEEDED:
            self._end_goal("succeed", Result.SUCCESSFUL, step.message)
        elif step.outcome == Outcome.PATH_TOLERANCE_VIOLATED:
            self._end_goal("abort", Result.PATH_TOLERANCE_VIOLATED, step.message)
        elif step.outcome == Outcome.GOAL_TOLERANCE_VIOLATED:
            self._end_goal("abort", Result.GOAL_TOLERANCE_VIOLATED, step.message)

    def _end_goal(self, how: str, code: int, text: str) -> None:
        """Finish the running goal (if any): the execute coroutine resolves it as ``how``."""
        goal, self._goal = self._goal, None
        self.controller.stop()
        self.hw.stop_motion()
        if goal is None or goal.done.done():
            return
        if how != "succeed":
            self.get_logger().warning(f"trajectory goal ended ({how}): {text}")
        goal.done.set_result((how, Result(error_code=code, error_string=text)))

    # --- action --------------------------------------------
    async def _execute(self, goal_handle) -> Result:
        started = self._executed.now()
        how, result = await self._run_goal(goal_handle)
        getattr(goal_handle, how)()
        traj = goal_handle.request.trajectory
        self._executed.publish(
            started, traj.joint_names, executed_trajectories.planned_seconds(traj), _OUTCOMES[how],
            result.error_code, result.error_string,
        )  # fmt: skip
        return result

    async def _run_goal(self, goal_handle) -> tuple[str, Result]:
        """How the goal ended (``succeed``, ``abort`` or ``canceled``) and its result."""
        request = goal_handle.request
        traj = request.trajectory
        points = [
            TrajectoryPoint(
                p.time_from_start.sec + p.time_from_start.nanosec * 1e-9,
                tuple(p.positions),
                tuple(p.velocities),
            )
            for p in traj.points
        ]
        problem = None
        if self.hw.state != Lifecycle.ACTIVE:
            problem = (
                Result.HARDWARE_FAULT,
                f"lifter link is not active: {self.hw.fault or self.hw.state.name}",
            )
        elif self.hw.firmware_state != FirmwareState.CRS_CONTROL:
            name = self.hw.firmware_state.name if self.hw.firmware_state is not None else "unknown"
            problem = (Result.INVALID_GOAL, f"lifter firmware is in {name}; request CRS Control first")
        if problem is None:
            try:
                self.controller.validate(list(traj.joint_names), points)
            except GoalRejected as exc:
                code = Result.INVALID_JOINTS if exc.invalid_joints else Result.INVALID_GOAL
                problem = (code, str(exc))
        if problem is not None:
            self.get_logger().warning(f"trajectory goal rejected: {problem[1]}")
            return "abort", Result(error_code=problem[0], error_string=problem[1])
        # a new goal replaces the running one
        self._end_goal("abort", Result.INVALID_GOAL, "preempted by a newer goal")
        self.controller.start(
            list(traj.joint_names),
            points,
            self._loop_clock(),
            self._positions_m(),
            path_tolerance={t.name: t.position for t in request.path_tolerance},
            goal_tolerance={t.name: t.position for t in request.goal_tolerance},
            goal_time_tolerance=request.goal_time_tolerance.sec + request.goal_time_tolerance.nanosec * 1e-9,
        )
        goal = _Goal(goal_handle, Future())
        self._goal = goal
        return await goal.done

    # --- mode service --------------------------------------------
    def _on_set_mode(self, request: SetLifterMode.Request, response: SetLifterMode.Response):
        if self._goal is not None and request.mode != SetLifterMode.Request.MODE_CRS_CONTROL:
            self._end_goal("abort", Result.INVALID_GOAL, f"lifter mode changed to {request.mode} by request")
        accepted, reason, state = self.hw.request_mode(request.mode)
        response.success = accepted
        response.reason = reason
        response.state = int(state) if state is not None else 0
        self._publish_state()
        return response

    # --- publication --------------------------------------------
    def _positions_m(self) -> list[float]:
        tel = self.hw.telemetry
        if tel is None:
            return [0.0] * len(self.config.joints)
        return [c / j.counts_per_m for c, j in zip(tel.positions, self.config.joints, strict=True)]

    def _publish_state(self) -> None:
        msg = LifterState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.joint_names = list(self.config.joint_names)
        tel = self.hw.telemetry
        if tel is not None:
            msg.state = int(tel.state)
            msg.encoder_counts = list(tel.positions)
            msg.encoder_positions = self._positions_m()
            msg.motor_velocities = list(tel.velocities)
            msg.limit_switches = list(tel.limit_switches)
            msg.watchdog_tripped = tel.watchdog_tripped
        msg.link_ok = self.hw.link_ok and self.hw.state in (Lifecycle.INACTIVE, Lifecycle.ACTIVE)
        msg.fault = self.hw.fault
        self._state_pub.publish(msg)

    def _publish_status(self) -> None:
        msg = HardwareStatus()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.component = self.hw.name
        msg.lifecycle_state = int(self.hw.state)
        msg.link_ok = self.hw.link_ok and self.hw.state in (Lifecycle.INACTIVE, Lifecycle.ACTIVE)
        msg.retries = self.hw.retries
        msg.errors = self.hw.errors + self.hw.crc_errors + self.hw.bad_frames
        msg.fault = self.hw.fault
        self.hw.retries = 0
        self._reported = (self.hw.state, self.hw.fault)
        self._status_pub.publish(msg)

    def shutdown(self) -> None:
        """Stop the motors (a zero command) and close the port."""
        self._end_goal("abort", Result.HARDWARE_FAULT, "lifter driver shutting down")
        self.hw.shutdown()


def driver(args: list[str]) -> Driver:
    """The lifter's driver from its arguments; raises :class:`DriverStartError`."""
    parser = argparse.ArgumentParser(
        prog="tlt-lifter", description="Lifter driver node (serial link to the Teensy)"
    )
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="lifter hardware YAML")
    parser.add_argument("--port", help="serial device, overriding the configured port")
    parser.add_argument(
        "--answer-timeout-s",
        type=float,
        help="how long the firmware has to answer a state or mode request, overriding the YAML's (the "
        "twin answers from a busy process)",
    )
    parser.add_argument(
        "--link-timeout-s",
        type=float,
        help="how long without telemetry is a link fault, overriding the YAML's (an emulated firmware "
        "on a busy machine pauses longer than a Teensy)",
    )
    own = parser.parse_args(args)
    try:
        config = load_lifter_config(own.config)
    except ConfigError as exc:
        raise DriverStartError(str(exc)) from exc
    if own.port:
        config = config.with_port(own.port)
    if own.answer_timeout_s is not None:
        if not 0.0 < own.answer_timeout_s <= 10.0:
            raise DriverStartError("--answer-timeout-s must be in (0, 10] s")
        config = dataclasses.replace(config, answer_timeout_s=own.answer_timeout_s)
    if own.link_timeout_s is not None:
        if not 0.0 < own.link_timeout_s <= 10.0:
            raise DriverStartError("--link-timeout-s must be in (0, 10] s")
        config = dataclasses.replace(config, link_timeout_s=own.link_timeout_s)
    return Driver("lifter", lambda: LifterNode(config))


def main(argv: list[str] | None = None) -> int:
    """Run the lifter driver node until interrupted. Returns the process exit status."""
    return run_driver("tlt-lifter", driver, argv)


if __name__ == "__main__":
    sys.exit(main())
