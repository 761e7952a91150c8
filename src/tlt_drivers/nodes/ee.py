"""``ee_x`` / ``ee_y`` driver node: one ARS end effector (paper §V.B.4, Fig. 12).

One Dynamixel chain carries three MX-106T with different operating modes: the two grasp joints
(current-based position, so a grasp presses with a bounded current) under the trajectory
controller (``/<ee>/follow_joint_trajectory``), and the lead-screw width joint (extended position,
multi-turn) under the group position controller (``/<ee>/position_command``). GPIO: a limit-switch
input for the width joint's calibration and two rivet-gun outputs, reached through any object
with ``read_input(name) -> bool`` and ``write_output(name, value)`` (:class:`DigitalIO`).

Calibration runs on activation when ``ee.calibration.on_start`` is set, and on request through
``/<ee>/calibrate`` (``std_srvs/Trigger``). Until it has succeeded every motion command is refused
with the reason. A width servo that rebooted and lost its multi-turn count while the grippers hold
a part is not calibrated by the driver on its own, since the seek would drag the part along the
slide: the driver holds, says why in ``EndEffectorState`` (``fault`` set, ``fault_reason``) and in
its log, and waits for an operator's choice: ``/<ee>/calibrate`` (now) or
``/<ee>/calibrate_when_released`` (``std_srvs/Trigger``: once the part is put down). Meanwhile the
grasp joints may move (to put the part down), the width joint may not.

Rivet guns: ``/<ee>/set_rivet_gun`` (``tlt_interfaces/srv/SetActuatorState``, actuator
``rivet_gun_0`` or ``rivet_gun_1``, state ``on`` or ``off``). State:
``tlt_interfaces/msg/EndEffectorState`` on ``/<ee>/state``; ``part_grasped`` is true when every
grasp joint presses with at least ``ee.grasp_effort_threshold`` of stall current.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from std_srvs.srv import Trigger
from tlt_interfaces.msg import EndEffectorState
from tlt_interfaces.srv import SetActuatorState

from tlt_common import ros_names
from tlt_drivers.dynamixel.config import load_chain
from tlt_drivers.dynamixel.ee_calibration import CalibrationState, WidthCalibration
from tlt_drivers.gpio.lines import open_gpio
from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.node_main import (
    HARDWARE_CONFIG_DIR,
    Driver,
    DriverStartError,
    chain_driver,
    run_driver,
)
from tlt_drivers.nodes.dynamixel_node import DynamixelDriverNode


class DigitalIO(Protocol):
    """The two GPIO calls the end effector needs (implemented by the GPIO driver and its emulator)."""

    def read_input(self, name: str) -> bool: ...

    def write_output(self, name: str, value: bool) -> None: ...


class EndEffectorNode(DynamixelDriverNode):
    """The end-effector driver over ``gpio`` and the chain in ``config`` (which must have ``ee``)."""

    def __init__(self, config: dict[str, Any], gpio: DigitalIO, *, start: bool = True, context=None) -> None:
        if not config.get("ee"):
            raise ValueError(f"{config['component']}: an end-effector config needs an 'ee' section")
        self.ee = config["ee"]
        self.gpio = gpio
        self._calibration: WidthCalibration | None = None
        super().__init__(
            config["component"], config, motion_gate=self._calibration_refusal, start=False, context=context
        )
        self.calibration = WidthCalibration(
            self.hw,
            self.ee["width_joint"],
            self.ee["calibration"],
            self._limit_switch,
            on_end=self._calibration_ended,
        )
        self._calibration = self.calibration
        self.loop.override = self._override
        self.rivet_outputs = [False] * len(self.ee["rivet_gun_outputs"])
        self._activations_seen = 0
        self._width_read: float | None = None  # the width joint's last reading while active
        component = config["component"]
        self._grasped_read = False  # whether the grippers held a part at that reading
        # Where the grasp joints stood when the calibration began to wait with a part held.
        self._held_at: dict[str, float] = {}
        self.state_pub = self.create_publisher(EndEffectorState, ros_names.state_topic(component), 10)
        self.create_service(Trigger, ros_names.ee_calibrate_service(component), self._on_calibrate)
        self.create_service(
            Trigger,
            ros_names.ee_calibrate_when_released_service(component),
            self._on_calibrate_when_released,
        )
        if self.loop.trajectory is not None:
            self.loop.trajectory.motion_gate = self._grasp_refusal
        self.create_service(SetActuatorState, ros_names.ee_rivet_gun_service(component), self._on_rivet_gun)
        for name in self.ee["rivet_gun_outputs"]:
            self.gpio.write_output(name, False)
        if start:
            self.loop.start()

    # --- calibration ---------------------------------------------------------------------------------------
    def _limit_switch(self) -> bool:
        return bool(self.gpio.read_input(self.ee["limit_switch_input"]))

    def _calibration_refusal(self) -> str | None:
        return self._calibration.refusal() if self._calibration is not None else "starting up"

    def _grasp_refusal(self) -> str | None:
        """The grasp joints' gate: as every motion's, except while the calibration waits for an
        operator, when the jaws may open to put the held part down."""
        refusal = self.loop.motion_refusal()
        if (
            refusal is not None
            and self.calibration.state == CalibrationState.WAITING
            and self.hw.state == Lifecycle.ACTIVE
        ):
            return None
        return refusal

    def _part_grasped(self) -> bool:
        """Every grasp joint presses with at least ``ee.grasp_effort_threshold`` of stall current."""
        threshold = self.ee["grasp_effort_threshold"]
        return self.hw.state == Lifecycle.ACTIVE and all(
            abs(self.hw.effort[n]) >= threshold for n in self.ee["grasp_joints"]
        )

    def _calibration_ended(self) -> None:
        if self.calibration.calibrated:
            self.get_logger().info(f"{self.config['component']}: width joint zeroed on the limit switch")
        else:
            self.get_logger().error(
                f"{self.config['component']}: calibration failed: {self.calibration.reason}"
            )
        # Hold where the width joint stopped (in the new coordinates after a zeroing).
        if self.loop.group is not None:
            self.loop.group.reset_hold(self.hw.position)

    def _override(self, now: float) -> dict[str, float]:
        width = self.ee["width_joint"]
        grasped = self._part_grasped()
        waiting = CalibrationState.WAITING
        if self.loop.activations != self._activations_seen:
            if self._activations_seen:
                self._check_count_after_fault(width, held=grasped or self._grasped_read)
            self._activations_seen = self.loop.activations
            if self.ee["calibration"]["on_start"] and self.calibration.state not in (
                CalibrationState.CALIBRATED,
                waiting,
            ):
                self.calibration.start(now)
        if self.calibration.state == waiting and self.calibration.when_released and self._put_down(grasped):
            self.get_logger().info(f"{self.config['component']}: the part is put down: calibrating the width")
            self.calibration.start(now)
        self._width_read = self.hw.position[width]
        self._grasped_read = grasped
        return self.calibration.update(now)

    def _put_down(self, grasped: bool) -> bool:
        """Whether the part held when the calibration began to wait is put down: no grasp presses
        and a grasp joint moved ``calibration.release_travel`` from where it stood then. Pressing
        alone does not tell, as a re-activation holds the jaws where they stand, pressing on
        nothing, with the part still between them."""
        travel = self.ee["calibration"]["release_travel"]
        return not grasped and any(abs(self.hw.position[n] - at) >= travel for n, at in self._held_at.items())

    def _check_count_after_fault(self, width: str, held: bool) -> None:
        """Re-activated after a fault: a width servo that rebooted or lost power lost its
        multi-turn count (its encoder covers one turn), and its position then reads off by whole
        turns from the last one read before the fault. Only then is the calibration lost: a seek
        to the limit switch drags whatever part the grippers hold along the slide, so a fault of
        the link alone must not start one, and with a part ``held`` (before the fault or now) the
        driver waits for an operator's choice instead of seeking."""
        before, after = self._width_read, self.hw.position[width]
        if self.calibration.state == CalibrationState.SEEKING:
            # A seek cut by the fault starts again: its travel was counted from where it began.
            self.calibration.invalidate("hardware was re-activated during the seek")
            return
        if before is None or not self.calibration.calibrated:
            return
        keep = self.ee["calibration"]["keep_within"]
        if abs(after - before) > keep:
            lost = (
                f"the width read {after:.4f} after a fault, {before:.4f} before: its servo lost its "
                "multi-turn count"
            )
            component = self.config["component"]
            if held:
                self._held_at = {n: self.hw.position[n] for n in self.ee["grasp_joints"]}
                self.calibration.hold_for_operator(
                    f"{lost} while a part is held: not seeking the limit switch with the part in the"
                    f" grippers; an operator chooses {ros_names.ee_calibrate_service(component)}"
                    f" (now) or {ros_names.ee_calibrate_when_released_service(component)}"
                    " (once the part is put down)"
                )
                self.get_logger().error(f"{component}: {self.calibration.reason}")
                return
            self.calibration.invalidate(lost)
            self.get_logger().warning(f"{component}: {self.calibration.reason}; calibrating again")
        else:
            self.get_logger().info(
                f"{self.config['component']}: width calibration kept after the fault (it reads "
                f"{abs(after - before) * 1000:.1f} mm from where it stood)"
            )

    def _on_calibrate(self, _request, response):
        problem = self.calibration.start(self.loop.now())
        response.success = problem is None
        response.message = problem or f"calibration {self.calibration.state.value}"
        return response

    def _on_calibrate_when_released(self, _request, response):
        problem = self.calibration.start_when_released()
        response.success = problem is None
        response.message = problem or self.calibration.reason
        return response

    # --- rivet guns ----------------------------------------------------------------------------------------
    def _on_rivet_gun(self, request, response):
        names = [f"rivet_gun_{i}" for i in range(len(self.rivet_outputs))]
        if request.actuator not in names:
            response.accepted, response.reason = (
                False,
                f"unknown actuator {request.actuator!r}; expected {names}",
            )
            return response
        if request.state not in ("on", "off"):
            response.accepted, response.reason = False, f"state {request.state!r} is not 'on' or 'off'"
            return response
        index = names.index(request.actuator)
        value = request.state == "on"
        try:
            self.gpio.write_output(self.ee["rivet_gun_outputs"][index], value)
        except Exception as exc:  # a GPIO failure is reported to the caller, not raised into the executor
            response.accepted, response.reason = False, f"GPIO write failed: {exc}"
            return response
        self.rivet_outputs[index] = value
        response.accepted, response.reason = True, ""
        return response

    def shutdown(self) -> None:
        """Stop the loop, close the chain and release both rivet guns."""
        super().shutdown()
        for name in self.ee["rivet_gun_outputs"]:
            try:
                self.gpio.write_output(name, False)  # never leave a rivet gun firing
            except Exception as exc:  # shutting down anyway; the GPIO may already be gone
                self.get_logger().warning(f"rivet gun {name} not released: {exc}")
        close = getattr(self.gpio, "close", None)
        if close is not None:
            close()

    # --- state ---------------------------------------------------------------------------------------------
    def publish_state(self) -> None:
        names = self.hw.joint_names
        msg = EndEffectorState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.ars = self.ee["ars"]
        msg.joint_names = names
        msg.position = [self.hw.position[n] for n in names]
        msg.velocity = [self.hw.velocity[n] for n in names]
        msg.effort = [self.hw.effort[n] for n in names]
        msg.hardware_error = [self.hw.hardware_error[n] & 0xFF for n in names]
        msg.calibrated = self.calibration.calibrated
        try:
            msg.limit_switch = self._limit_switch()
        except Exception:  # a failing GPIO read must not stop the state stream
            msg.limit_switch = False
        msg.part_grasped = self._part_grasped()
        msg.rivet_gun_output = [bool(v) for v in self.rivet_outputs[:2]]
        # Waiting for an operator's choice of calibration is a fault too: it says why nothing moves.
        waiting = self.calibration.state == CalibrationState.WAITING
        errored = self.hw.state == Lifecycle.ERROR
        msg.fault = errored or waiting
        msg.fault_reason = self.calibration.reason if waiting and not errored else self.hw.fault
        self.state_pub.publish(msg)


class GpioUnavailable(DriverStartError):
    """No GPIO backend could be opened for the end effector."""


def open_ee_gpio(config: dict[str, Any]) -> DigitalIO:
    """The EE's GPIO lines from ``ee.gpio_config`` through :func:`tlt_drivers.gpio.lines.open_gpio`
    (character device on the Jetsons, the twin's emulated chip otherwise, as that file says)."""
    name = config["ee"].get("gpio_config")
    if not name:
        raise GpioUnavailable(f"{config['component']}: ee.gpio_config names no GPIO map")
    path = Path(name)
    if not path.is_absolute():
        path = HARDWARE_CONFIG_DIR / path
    try:
        return open_gpio(path)
    except OSError as exc:
        raise GpioUnavailable(f"{config['component']}: cannot open GPIO from {path}: {exc}") from exc


def _driver(default_config: str, args: list[str]) -> Driver:
    def build(config: dict[str, Any]) -> EndEffectorNode:
        return EndEffectorNode(config, open_ee_gpio(config))

    return chain_driver("ee", default_config, load_chain, build, args)


def driver_x(args: list[str]) -> Driver:
    """``ee_x``: the end effector of ars_x (config/hardware/ee_x.yaml unless ``--config``)."""
    return _driver("ee_x.yaml", args)


def driver_y(args: list[str]) -> Driver:
    """``ee_y``: the end effector of ars_y (config/hardware/ee_y.yaml unless ``--config``)."""
    return _driver("ee_y.yaml", args)


def main_x(argv: list[str] | None = None) -> int:
    return run_driver("tlt-ee-x", driver_x, argv)


def main_y(argv: list[str] | None = None) -> int:
    return run_driver("tlt-ee-y", driver_y, argv)


if __name__ == "__main__":
    raise SystemExit(main_x())
