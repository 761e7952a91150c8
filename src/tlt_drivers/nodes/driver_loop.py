"""The control loop every Dynamixel/MightyZAP driver node runs, as ros2_control's controller manager would.

Each timer tick (``rate_hz``, in the loop's time base: sim time on the twin, monotonic on hardware,
``tlt_drivers.loop_time``): ``read`` the hardware, ``update`` the controllers with the actual
positions (and speeds, where the interface reads them), copy their commands into the interface,
``write``, then let the ROS adapters resolve goals and publish. While the interface is in ERROR,
goals are aborted with HARDWARE_FAULT, group commands are refused, nothing is written, and
``recover`` is tried every ``comm.recover_period_s``; after a recovery both controllers hold the
actual positions, so a returning link never makes a joint jump. ``HardwareStatus`` and the node's
own state message are published at ``state_rate_hz``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from rclpy.node import Node
from rclpy.timer import Timer
from tlt_interfaces.msg import HardwareStatus

from tlt_common import ros_names
from tlt_common.ros.periodic_timer import create_periodic_timer
from tlt_drivers.controllers.group_position import JointGroupPositionController
from tlt_drivers.controllers.ros_adapters import GroupPositionCommandSubscriber, TrajectoryActionServer
from tlt_drivers.controllers.trajectory import JointTrajectoryController
from tlt_drivers.hardware_interface import JointGroupInterface, Lifecycle
from tlt_drivers.loop_time import loop_clock


class DriverLoop:
    """Owns ``hw`` and its controllers on ``node``; call :meth:`start` once, :meth:`stop` at the end."""

    def __init__(
        self,
        node: Node,
        hw: JointGroupInterface,
        *,
        component: str,
        rate_hz: float,
        state_rate_hz: float,
        recover_period_s: float,
        limits: Mapping[str, tuple[float, float]],
        trajectory_joints: Sequence[str] = (),
        group_joints: Sequence[str] = (),
        trajectory_tolerances: Mapping[str, float] | None = None,
        motion_gate: Callable[[], str | None] | None = None,
        publish_state: Callable[[], None] | None = None,
    ) -> None:
        self.node = node
        self.hw = hw
        self.component = component
        self.period = 1.0 / rate_hz
        self.state_period = 1.0 / state_rate_hz
        self.recover_period = recover_period_s
        self._publish_state = publish_state
        self._gate_extra = motion_gate
        self._last_recover = -1e9
        self._last_state = -1e9
        self.cycles = 0
        #: successful activations (bring-up and every recovery); a change means the servos may have rebooted
        self.activations = 0
        #: extra per-cycle hook (EE calibration) -> commands that override the controllers'
        self.override: Callable[[float], Mapping[str, float]] | None = None
        tol = trajectory_tolerances or {}
        self.trajectory: JointTrajectoryController | None = None
        self.group: JointGroupPositionController | None = None
        self.action: TrajectoryActionServer | None = None
        self.commands: GroupPositionCommandSubscriber | None = None
        if trajectory_joints:
            self.trajectory = JointTrajectoryController(
                trajectory_joints,
                {n: limits[n] for n in trajectory_joints},
                path_tolerance=tol.get("path_tolerance", 0.2),
                goal_tolerance=tol.get("goal_tolerance", 0.02),
                goal_time_tolerance=tol.get("goal_time_tolerance_s", 0.5),
                goal_velocity_tolerance=tol.get("goal_velocity_tolerance", -1.0),
                goal_settle_s=tol.get("goal_settle_s", 0.0),
                motion_gate=self.motion_refusal,
                # A starved loop resumes the path where it left it (see the controller).
                max_time_step=tol.get("max_time_step_s", 0.05),
                path_lag_window=tol.get("path_lag_window_s", 0.5),
            )
            self.action = TrajectoryActionServer(
                node,
                component,
                self.trajectory,
                self.actual,
                self.now,
                feedback_every=max(1, round(rate_hz / 10.0)),
            )
        if group_joints:
            self.group = JointGroupPositionController(
                group_joints, {n: limits[n] for n in group_joints}, motion_gate=self.motion_refusal
            )
            self.commands = GroupPositionCommandSubscriber(
                node, ros_names.position_command_topic(component), self.group
            )
        self.status_pub = node.create_publisher(
            HardwareStatus, ros_names.hardware_status_topic(component), 10
        )
        self._timer: Timer | None = None
        self._clock = loop_clock(node)

    @classmethod
    def for_chain(
        cls,
        node: Node,
        hw: JointGroupInterface,
        config: Mapping[str, Any],
        members: Sequence[Mapping[str, Any]],
        **controllers: Any,
    ) -> DriverLoop:
        """The loop of a validated chain config (``component``, ``rate_hz``, ``state_rate_hz``,
        ``comm.recover_period_s``) whose ``members`` (joints or actuators) carry ``name``, ``lower``
        and ``upper``; ``controllers`` are the rest of :class:`DriverLoop`'s keywords."""
        return cls(
            node,
            hw,
            component=config["component"],
            rate_hz=config["rate_hz"],
            state_rate_hz=config["state_rate_hz"],
            recover_period_s=config["comm"]["recover_period_s"],
            limits={m["name"]: (m["lower"], m["upper"]) for m in members},
            **controllers,
        )

    # --- helpers -----------------------------------------------------------------------------------------
    def now(self) -> float:
        """Seconds in the loop's time base (trajectories, state and recovery pacing)."""
        return self._clock()

    def actual(self) -> dict[str, float]:
        return dict(self.hw.position)

    def motion_refusal(self) -> str | None:
        """Why motion commands are refused now, or None."""
        if self.hw.state != Lifecycle.ACTIVE:
            reason = self.hw.fault or f"hardware is {self.hw.state.name}"
            return f"{self.component}: hardware not active: {reason}"
        if self._gate_extra is not None:
            return self._gate_extra()
        return None

    def bring_up(self) -> bool:
        """configure + activate; on failure the loop keeps trying to recover."""
        ok = self.hw.configure() and self.hw.activate() if self.hw.state == Lifecycle.UNCONFIGURED else False
        if ok:
            self.activations += 1
            self._hold()
        else:
            self.node.get_logger().error(f"{self.component}: bring-up failed: {self.hw.fault}")
        return ok

    def _hold(self) -> None:
        actual = self.actual()
        if self.trajectory is not None:
            self.trajectory.reset_hold(actual)
        if self.group is not None:
            self.group.reset_hold(actual)

    def start(self) -> None:
        self.bring_up()
        self._timer = create_periodic_timer(self.node, self.period, self.cycle)

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self.node.destroy_timer(self._timer)
            self._timer = None
        if self.action is not None:
            self.action.destroy()
        self.hw.shutdown()

    # --- the cycle ----------------------------------------------------------------------------------------
    def cycle(self) -> None:
        now = self.now()
        self.cycles += 1
        was_error = self.hw.state == Lifecycle.ERROR
        if was_error:
            self._fault_controllers()
            if _due(now, self._last_recover, self.recover_period):
                self._last_recover = now
                if self.hw.recover():
                    self.activations += 1
                    self.node.get_logger().info(f"{self.component}: recovered")
                    self._hold()
        elif self.hw.read(now):
            actual = self.actual()
            commands: dict[str, float] = {}
            if self.trajectory is not None:
                # Interfaces that read their joints' speeds (Dynamixel) let a goal end at rest only.
                velocity = getattr(self.hw, "velocity", None)
                commands.update(self.trajectory.update(now, actual, dict(velocity) if velocity else None))
            if self.group is not None:
                commands.update(self.group.update(actual))
            if self.override is not None:
                commands.update(self.override(now))
            self.hw.command.update(commands)
            self.hw.write(now)
        if self.hw.state == Lifecycle.ERROR and not was_error:
            # A fresh fault: abort goals now, and give the link a moment before the first reconnect.
            self._fault_controllers()
            self._last_recover = now - self.recover_period / 2
        if self.action is not None:
            self.action.tick()
        if _due(now, self._last_state, self.state_period):
            self._last_state = now
            self.publish_status()
            if self._publish_state is not None:
                self._publish_state()

    def _fault_controllers(self) -> None:
        if self.trajectory is not None:
            self.trajectory.fault(f"{self.component}: {self.hw.fault}", self.actual())

    def publish_status(self) -> None:
        msg = HardwareStatus()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.component = self.component
        msg.lifecycle_state = int(self.hw.state)
        msg.link_ok = bool(getattr(self.hw, "link_ok", False)) and self.hw.state != Lifecycle.ERROR
        msg.retries = int(getattr(self.hw, "retries", 0))
        msg.errors = int(self.hw.errors)
        msg.fault = self.hw.fault
        if hasattr(self.hw, "retries"):
            self.hw.retries = 0
        self.status_pub.publish(msg)


def _due(now: float, last: float, period: float) -> bool:
    """A period has passed since ``last``, or the loop's time went back past it (sim time from a
    restarted twin; waiting for it to come back to ``last`` would silence the node meanwhile)."""
    return now - last >= period or now < last


__all__ = ["DriverLoop"]
