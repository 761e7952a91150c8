"""The ``ur`` driver node: one UR10e arm over ur-rtde (paper §V.B, Fig. 5), e.g. ``ur_x``.

Interfaces (names relative to the node's namespace; ``<c>`` is the configured component):

* ``/<c>/joint_states`` (``sensor_msgs/JointState``): actual positions and velocities, every
  control cycle while the controller's data is fresh;
* ``hardware_status`` (``tlt_interfaces/msg/HardwareStatus``, component ``<c>``): at
  ``status_rate_hz`` and at once on any change of lifecycle state or fault;
* ``/<c>/follow_joint_trajectory`` (``tlt_interfaces/action/FollowJointTrajectory``): the shared
  :class:`~tlt_drivers.controllers.trajectory.JointTrajectoryController` interpolates the goal
  and judges tolerances; each control cycle its position command is streamed with servoJ. A new
  goal replaces the running one; a protective stop, a stopped control script or a lost link
  aborts it with HARDWARE_FAULT; goals outside the joint limits end at once with INVALID_GOAL
  naming the joint and the limit;
* ``/<c>/unlock_protective_stop`` (``std_srvs/Trigger``): asks the controller's dashboard to
  release a protective stop; the node then returns to ACTIVE by itself.

One timer at ``control_rate_hz`` runs the cycle (read, controller, write). While the interface is
in ERROR the cycle tries to recover every ``reconnect_period_s``: the probe waits at most
``probe_timeout_s``; a reconnect re-runs ur-rtde's handshake, whose first connection holds the
interpreter for the few milliseconds the controller needs to answer.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from tlt_interfaces.msg import HardwareStatus

from tlt_common import ros_names
from tlt_common.config_schema import ConfigError
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.periodic_timer import create_periodic_timer
from tlt_drivers.controllers.ros_adapters import TrajectoryActionServer
from tlt_drivers.controllers.trajectory import JointTrajectoryController
from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.loop_time import loop_clock
from tlt_drivers.node_main import Driver, DriverStartError, run_driver

from .config import DEFAULT_CONFIG, URConfig, load_ur_config, with_link_timeout, with_rtde_frequency
from .hardware import URHardware
from .rtde_link import LinkDown


class URNode(LeanNode):
    """The driver node of one arm; ``hw`` is its :class:`URHardware`."""

    def __init__(self, config: URConfig, *, hardware: URHardware | None = None, **node_kwargs) -> None:
        super().__init__(node_kwargs.pop("node_name", config.component), **node_kwargs)
        self.config = config
        self._loop_now = loop_clock(self)  # trajectories, joint-state pacing, RTDE data watchdog
        self.hw = hardware or URHardware(config, data_clock=self._loop_now)
        c = config.component
        self.controller = JointTrajectoryController(
            config.joint_names,
            config.limits,
            path_tolerance=config.default_path_tolerance,
            goal_tolerance=config.default_goal_tolerance,
            goal_time_tolerance=config.default_goal_time_tolerance_s,
            goal_velocity_tolerance=config.default_goal_velocity_tolerance,
            goal_settle_s=config.goal_settle_s,
            motion_gate=self._motion_gate,
            max_time_step=config.max_trajectory_step_s,
            path_lag_window=config.path_lag_window_s,
        )
        self._joint_pub = self.create_publisher(JointState, ros_names.joint_states_topic(c), 10)
        self._status_pub = self.create_publisher(HardwareStatus, ros_names.hardware_status_topic(c), 10)
        self.action = TrajectoryActionServer(
            self, c, self.controller, lambda: self.hw.positions, self._loop_now
        )
        self.create_service(Trigger, ros_names.ur_unlock_service(c), self._on_unlock)
        self._reported: tuple[Lifecycle, str] | None = None
        self._settling = False
        self._joints_due = -1e9  # loop time the next JointState is due
        self._last_recovery = time.monotonic()
        if not (self.hw.configure() and self.hw.activate()):
            self.get_logger().error(
                f"{c}: arm not ready: {self.hw.fault}; retrying every {config.reconnect_period_s} s"
            )
        self._timer = create_periodic_timer(self, 1.0 / config.control_rate_hz, self._control_cycle)
        self._status_timer = create_periodic_timer(self, 1.0 / config.status_rate_hz, self._publish_status)

    # --- control cycle -------------------------------------------------------------------------
    def _motion_gate(self) -> str | None:
        if self.hw.state != Lifecycle.ACTIVE:
            return f"{self.config.component} is not active: {self.hw.fault or self.hw.state.name.lower()}"
        return None

    def _control_cycle(self) -> None:
        hw = self.hw
        now = time.monotonic()
        if hw.state in (Lifecycle.INACTIVE, Lifecycle.ACTIVE):
            hw.read(now)
        if hw.state == Lifecycle.ACTIVE:
            goal = self.controller.active
            if goal is not None and not goal.done:
                commands = self.controller.update(self._loop_now(), hw.positions, hw.velocities)
                self._settling = True
            elif self._settling and self._still_moving():
                # After a goal ends the controller holds a point (the final one after success);
                # it is streamed until the arm is at rest there, so the arm does not coast past it.
                commands = self.controller.hold
            else:
                commands, self._settling = None, False
            target = None if commands is None else [commands[n] for n in self.config.joint_names]
            try:
                hw.set_servo_target(target)
            except ValueError as exc:  # a hold or interpolated point outside the limits
                self.controller.fault(str(exc), hw.positions)
                hw.set_servo_target(None)
            hw.write(now)
        if hw.state == Lifecycle.ERROR:
            self.controller.fault(f"{self.config.component}: {hw.fault}", hw.positions)
            if now - self._last_recovery >= self.config.reconnect_period_s:
                self._last_recovery = now
                if hw.try_recover():
                    self.controller.reset_hold(hw.positions)
                    self.get_logger().info(f"{self.config.component}: arm active again")
        self.action.tick()
        if hw.link_ok and hw.reading is not None and hw.state != Lifecycle.ERROR:
            self._publish_joints_when_due()
        if (hw.state, hw.fault) != self._reported:
            self._publish_status()

    def _still_moving(self) -> bool:
        """Whether the arm is moving or away from the held point (rest: 1 mrad/s, 1 mrad)."""
        reading, hold = self.hw.reading, self.controller.hold
        if reading is None:
            return False
        if max(abs(v) for v in reading.qd) > 1e-3:
            return True
        names = self.config.joint_names
        return any(abs(q - hold.get(n, q)) > 1e-3 for n, q in zip(names, reading.q, strict=True))

    # --- services --------------------------------------------------------------------------------
    def _on_unlock(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            answer = self.hw.unlock_protective_stop()
        except (LinkDown, RuntimeError) as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success = answer == "Protective stop releasing"
        response.message = answer
        self._last_recovery = 0.0  # try to come back on the next cycle
        return response

    # --- publication -----------------------------------------------------------------------------
    def _publish_joints_when_due(self) -> None:
        # Every subscriber (both ARSs, vision, the CRS, the recorder) wakes for each message: the
        # arm's state goes out at joint_state_rate_hz, not at the servo stream's control rate.
        now = self._loop_now()
        period = 1.0 / self.config.joint_state_rate_hz
        # Half a control period early counts as due (on the twin cycles fire as /clock steps sim
        # time); a due time more than a period ahead means the loop's time went back (a restarted
        # twin's clock): the next one is then a period from now, as after a stall.
        due = self._joints_due
        if now + 0.5 / self.config.control_rate_hz < due <= now + period:
            return
        self._joints_due = due + period if now < due + period <= now + period * 1.5 else now + period
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = list(self.config.joint_names)
        reading = self.hw.reading
        assert reading is not None  # the caller publishes only after a reading
        msg.position = list(reading.q)
        msg.velocity = list(reading.qd)
        self._joint_pub.publish(msg)

    def _publish_status(self) -> None:
        msg = HardwareStatus()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.component = self.hw.name
        msg.lifecycle_state = int(self.hw.state)
        msg.link_ok = bool(self.hw.link_ok)
        msg.errors = self.hw.errors
        msg.fault = self.hw.fault
        self._reported = (self.hw.state, self.hw.fault)
        self._status_pub.publish(msg)

    def shutdown(self) -> None:
        """Abort any goal, stop the arm and the control script, close the link."""
        self.controller.fault(f"{self.config.component} driver shutting down", self.hw.positions)
        self.action.tick()
        self.hw.shutdown()


def driver(args: list[str]) -> Driver:
    """One arm's driver from its arguments; raises :class:`DriverStartError`."""
    parser = argparse.ArgumentParser(prog="tlt-ur", description="UR10e driver node (ur-rtde)")
    parser.add_argument(
        "--config", type=Path, default=DEFAULT_CONFIG, help="arm YAML (config/hardware/ur_x.yaml)"
    )
    parser.add_argument("--host", help="controller address, overriding the configured host")
    parser.add_argument(
        "--rtde-frequency-hz",
        type=float,
        help="RTDE output rate asked of the controller, overriding rtde_frequency_hz (1-500)",
    )
    parser.add_argument(
        "--link-timeout-s",
        type=float,
        help="seconds of the loop's clock without new controller data before the link counts as down, "
        "overriding link_timeout_s",
    )
    own = parser.parse_args(args)
    try:
        config = load_ur_config(own.config)
        if own.link_timeout_s is not None:
            config = with_link_timeout(config, own.link_timeout_s, own.config)
        if own.rtde_frequency_hz is not None:
            config = with_rtde_frequency(config, own.rtde_frequency_hz, own.config)
    except ConfigError as exc:
        raise DriverStartError(str(exc)) from exc
    if own.host:
        config = replace(config, host=own.host)
    return Driver(config.component, lambda: URNode(config))


def main(argv: list[str] | None = None) -> int:
    """Run one UR driver node until interrupted. Returns the process exit status."""
    return run_driver("tlt-ur", driver, argv)


if __name__ == "__main__":
    sys.exit(main())
