"""The UR10e hardware interface: the ros2_control lifecycle over a :class:`URLink`.

* ``configure`` opens the state stream (RTDE receive), ``activate`` the control connection and
  the control script; ``deactivate`` stops motion and the script.
* ``read`` takes the controller's state. It fails (the interface goes to ERROR and stops
  commanding) when the data stops arriving, when the controller reports a protective or
  emergency stop, and, while ACTIVE, when the control script is no longer running.
* ``write`` streams the current servo target with ``servoJ`` (trajectory execution); with no
  target it sends nothing, so a point-to-point ``move_joints`` runs undisturbed.
* :meth:`try_recover` is called periodically while in ERROR: it probes the controller, waits for
  a protective stop to be cleared, and only then brings the interface back, re-uploading the
  control script (if ``auto_restart_program``) and reconnecting a dropped link.

Joint targets outside the configured limits are refused with :class:`JointLimitError` naming the
joint and the limit; motion of any kind is refused with :class:`MotionRefused` unless ACTIVE.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

from tlt_drivers.hardware_interface import HardwareInterface, Lifecycle

from .config import URConfig
from .rtde_link import ArmReading, LinkDown, URLink


class JointLimitError(ValueError):
    """A commanded joint value is outside its configured limit."""


class MotionRefused(RuntimeError):
    """Motion was not started: the interface is not ACTIVE or the controller refused it."""


class URHardware(HardwareInterface):
    """One UR10e arm. ``reading`` holds the latest state (None before the first read)."""

    def __init__(
        self,
        config: URConfig,
        link: URLink | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        data_clock: Callable[[], float] | None = None,
    ) -> None:
        super().__init__(config.component)
        self.config = config
        self.link = link or URLink(
            config.host,
            frequency=config.rtde_frequency_hz,
            link_timeout=config.link_timeout_s,
            probe_timeout=config.probe_timeout_s,
            clock=clock,
            data_clock=data_clock,
        )
        self.reading: ArmReading | None = None
        self.link_ok = False
        self._servo_target: list[float] | None = None
        self._servoing = False

    # --- lifecycle hooks ----------------------------------------------------------------------
    def on_configure(self) -> None:
        self.link.open_receive()
        self._take_reading(require_program=False)

    def on_activate(self) -> None:
        reading = self._take_reading(require_program=False)
        if reading.protective_stopped:
            raise MotionRefused("protective stop is active: unlock it before activating")
        self.link.open_control()
        self._take_reading(require_program=True)

    def on_deactivate(self) -> None:
        self._servo_target, self._servoing = None, False
        if self.link.control_connected:
            self.link.stop_joints(self.config.stop_deceleration)

    def on_cleanup(self) -> None:
        self._servo_target, self._servoing = None, False

    def on_read(self, now: float) -> None:
        self._take_reading(require_program=self.state == Lifecycle.ACTIVE)

    def on_write(self, now: float) -> None:
        target = self._servo_target
        if target is None:
            if self._servoing:
                self._servoing = False
                self.link.servo_stop(self.config.stop_deceleration)
            return
        period = 1.0 / self.config.control_rate_hz
        if not self.link.servo(target, period, self.config.servo_lookahead_s, self.config.servo_gain):
            raise MotionRefused(self._refusal_reason("servoJ"))
        self._servoing = True

    def shutdown(self) -> None:
        super().shutdown()
        self.link.close()

    # --- state -------------------------------------------------------------------------------------
    def _take_reading(self, *, require_program: bool) -> ArmReading:
        try:
            reading = self.link.read()
        except LinkDown:
            self.link_ok = False
            raise
        self.link_ok = True
        self.reading = reading
        if reading.emergency_stopped:
            raise MotionRefused("emergency stop")
        if reading.protective_stopped:
            raise MotionRefused("protective stop")
        if require_program and not reading.program_running:
            raise MotionRefused("the control script on the controller stopped")
        return reading

    def _refusal_reason(self, command: str, wait_s: float = 0.1) -> str:
        """Why the controller refused ``command``, from the state stream.

        ur-rtde judges a command on the control connection's stream, which can be a cycle ahead
        of the receive stream, so the state is re-read for up to ``wait_s``.
        """
        deadline = time.monotonic() + wait_s
        while True:
            try:
                reading = self.link.read()
            except LinkDown as exc:
                return str(exc)
            if reading.emergency_stopped:
                return "emergency stop"
            if reading.protective_stopped:
                return "protective stop"
            if not reading.program_running:
                return "the control script on the controller stopped"
            if time.monotonic() > deadline:
                return f"the controller refused {command}"
            time.sleep(0.005)

    @property
    def positions(self) -> dict[str, float]:
        if self.reading is None:
            return {}
        return dict(zip(self.config.joint_names, self.reading.q, strict=True))

    @property
    def velocities(self) -> dict[str, float]:
        if self.reading is None:
            return {}
        return dict(zip(self.config.joint_names, self.reading.qd, strict=True))

    @property
    def protective_stopped(self) -> bool:
        return self.reading is not None and self.reading.protective_stopped

    # --- commands ----------------------------------------------------------------------------------
    def check_limits(self, q: Sequence[float]) -> list[float]:
        """``q`` as a list if every joint is inside its limits; :class:`JointLimitError` otherwise."""
        values = [float(v) for v in q]
        if len(values) != len(self.config.joints):
            raise JointLimitError(f"expected {len(self.config.joints)} joint values, got {len(values)}")
        for joint, value in zip(self.config.joints, values, strict=True):
            if not math.isfinite(value):
                raise JointLimitError(f"joint {joint.name!r}: {value} is not a number")
            if value < joint.min_position:
                raise JointLimitError(
                    f"joint {joint.name!r}: {value:.4f} rad is below its lower limit {joint.min_position} rad"
                )
            if value > joint.max_position:
                raise JointLimitError(
                    f"joint {joint.name!r}: {value:.4f} rad is above its upper limit {joint.max_position} rad"
                )
        return values

    def _require_active(self) -> None:
        if self.state != Lifecycle.ACTIVE:
            reason = self.fault or self.state.name.lower()
            raise MotionRefused(f"{self.name} is not active ({reason})")

    def move_joints(
        self,
        q: Sequence[float],
        velocity: float | None = None,
        acceleration: float | None = None,
        *,
        wait: bool = False,
    ) -> None:
        """Point-to-point joint move (moveJ). Asynchronous unless ``wait``; refused with a reason."""
        target = self.check_limits(q)
        self._require_active()
        self._servo_target = None
        v = min(velocity or self.config.move_velocity, max(j.max_velocity for j in self.config.joints))
        a = acceleration or self.config.move_acceleration
        if self._servoing:
            self._servoing = False
            self.link.servo_stop(self.config.stop_deceleration)
        if not self.link.move_joints(target, v, a, not wait):
            why = self._refusal_reason("moveJ")
            raise MotionRefused(f"moveJ to {[round(x, 4) for x in target]} failed: {why}")

    def move_running(self) -> bool:
        return self.link.motion_running()

    def set_servo_target(self, q: Sequence[float] | None) -> None:
        """Stream ``q`` with servoJ from the next ``write`` on; None stops streaming."""
        if q is None:
            self._servo_target = None
            return
        target = self.check_limits(q)
        self._require_active()
        self._servo_target = target

    def stop(self) -> None:
        """Stop any motion (servo streaming or a move) at the configured deceleration."""
        self._servo_target = None
        if self.state == Lifecycle.ACTIVE and self.link.control_connected:
            self._servoing = False
            self.link.stop_joints(self.config.stop_deceleration)

    def unlock_protective_stop(self) -> str:
        """Release a protective stop through the dashboard; returns the controller's answer."""
        return self.link.unlock_protective_stop()

    # --- recovery --------------------------------------------------------------------------------
    def recovery_blocker(self) -> str | None:
        """Why the interface cannot recover now (None when it can)."""
        problem = self.link.probe()
        if problem:
            return problem
        wait = self.link.control_wait()
        if wait > 0:
            return f"waiting {wait:.1f} s more for ur-rtde's own reconnect attempt to end"
        try:
            if self.link.receive is None or not self.link.receive.isConnected():
                self.link.open_receive()
            reading = self.link.read()
        except (LinkDown, RuntimeError) as exc:
            return str(exc)
        self.reading, self.link_ok = reading, True
        if reading.protective_stopped:
            return "protective stop still active (unlock it)"
        if reading.emergency_stopped:
            return "emergency stop still active"
        if not reading.program_running and not self.config.auto_restart_program:
            return "control script stopped (auto_restart_program is off)"
        return None

    def try_recover(self) -> bool:
        """From ERROR: come back to ACTIVE once the cause is gone. Returns whether it did."""
        if self.state != Lifecycle.ERROR:
            return self.state == Lifecycle.ACTIVE
        if self.recovery_blocker() is not None:
            return False
        return self.recover()


__all__ = ["JointLimitError", "MotionRefused", "URHardware"]
