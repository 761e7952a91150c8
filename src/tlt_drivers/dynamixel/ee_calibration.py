"""Limit-switch calibration of the end effector's width joint (paper §V.B.4).

The MX-106 keeps its absolute position only within one turn across a power cycle, so the
lead-screw width joint must be zeroed after power-up: drive it towards the limit switch at
``calibration.speed``, and when the switch closes declare that spot ``calibration.switch_position``.
Until that has happened, :meth:`WidthCalibration.refusal` gives the reason every motion command of
the end effector is refused. The seek gives up (FAILED, with the reason) after ``max_travel`` of
travel or ``timeout_s``. A hardware recovery may have rebooted the servos, so it invalidates the
calibration.

A seek drags whatever the grippers hold along the slide. So a calibration lost while a part is
held is not sought again by itself: :meth:`WidthCalibration.hold_for_operator` puts it in WAITING,
with the reason, until an operator chooses: :meth:`WidthCalibration.start` (calibrate now) or
:meth:`WidthCalibration.start_when_released` (calibrate once no part is held, which the driver
watches for).
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from typing import Any

from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
from tlt_drivers.hardware_interface import Lifecycle


class CalibrationState(enum.Enum):
    UNCALIBRATED = "uncalibrated"
    SEEKING = "seeking the limit switch"
    WAITING = "waiting for an operator"
    CALIBRATED = "calibrated"
    FAILED = "failed"


class WidthCalibration:
    """Seek-and-zero of ``joint`` on ``hw`` using ``read_switch()``; ``on_end`` runs when a seek ends."""

    #: the seek command leads the present position by at most this many seconds of travel
    LOOKAHEAD_S = 0.25

    def __init__(
        self,
        hw: DynamixelChainInterface,
        joint: str,
        settings: dict[str, Any],
        read_switch: Callable[[], bool],
        on_end: Callable[[], None] | None = None,
    ) -> None:
        self.hw = hw
        self.joint = joint
        self.settings = settings
        self.read_switch = read_switch
        self.on_end = on_end
        self.state = CalibrationState.UNCALIBRATED
        self.reason = "not calibrated since power-up"
        self._origin = 0.0
        self._t0 = 0.0
        #: while WAITING: the operator chose to calibrate once the grippers hold no part
        self.when_released = False

    @property
    def calibrated(self) -> bool:
        return self.state == CalibrationState.CALIBRATED

    def refusal(self) -> str | None:
        if self.calibrated:
            return None
        return (
            f"{self.hw.name}: width joint {self.joint!r} is not calibrated "
            f"({self.state.value}: {self.reason}); "
            "motion commands are refused until the limit-switch calibration succeeds"
        )

    def start(self, now: float) -> str | None:
        """Begin seeking; returns a reason when it cannot start."""
        if self.hw.state != Lifecycle.ACTIVE:
            return f"{self.hw.name}: cannot calibrate, hardware is {self.hw.state.name}: {self.hw.fault}"
        if self.state == CalibrationState.SEEKING:
            return None
        self.state = CalibrationState.SEEKING
        self.reason = "in progress"
        self.when_released = False
        self._origin = self.hw.position[self.joint]
        self._t0 = now
        self.hw.unclamped.add(self.joint)
        return None

    def invalidate(self, reason: str) -> None:
        self.hw.unclamped.discard(self.joint)
        self.state = CalibrationState.UNCALIBRATED
        self.reason = reason
        self.when_released = False

    def hold_for_operator(self, reason: str) -> None:
        """The calibration is lost and must not be sought by itself (a part is held): WAITING,
        with ``reason``, until :meth:`start` or :meth:`start_when_released`."""
        self.invalidate(reason)
        self.state = CalibrationState.WAITING

    def start_when_released(self) -> str | None:
        """The operator's choice to calibrate once no part is held; a reason when the calibration
        is not waiting for an operator."""
        if self.state != CalibrationState.WAITING:
            return f"{self.hw.name}: the calibration is {self.state.value}, not waiting for an operator"
        if not self.when_released:
            self.when_released = True
            self.reason += "; calibrating once the part is put down (the grippers hold none)"
        return None

    def _fail(self, reason: str) -> dict[str, float]:
        self.hw.unclamped.discard(self.joint)
        self.state = CalibrationState.FAILED
        self.reason = reason
        if self.on_end is not None:
            self.on_end()
        return {self.joint: self.hw.position[self.joint]}

    def update(self, now: float) -> dict[str, float]:
        """Commands overriding the controllers this cycle (only while seeking or on the cycle it ends)."""
        if self.state != CalibrationState.SEEKING:
            return {}
        s = self.settings
        here = self.hw.position[self.joint]
        if self.read_switch():
            self.hw.set_zero_here(self.joint, s["switch_position"])
            self.hw.unclamped.discard(self.joint)
            self.state = CalibrationState.CALIBRATED
            self.reason = ""
            if self.on_end is not None:
                self.on_end()
            return {self.joint: s["switch_position"]}
        travelled = abs(here - self._origin)
        if travelled > s["max_travel"]:
            return self._fail(
                f"limit switch not reached after {travelled:.4f} of travel (max {s['max_travel']})"
            )
        if now - self._t0 > s["timeout_s"]:
            return self._fail(f"limit switch not reached within {s['timeout_s']} s")
        # Ramp the command at the seek speed, but never let it run far ahead of a stalled joint.
        target = self._origin + s["direction"] * s["speed"] * (now - self._t0)
        lead = s["speed"] * self.LOOKAHEAD_S
        if abs(target - here) > lead:
            target = here + s["direction"] * lead
        return {self.joint: target}


__all__ = ["CalibrationState", "WidthCalibration"]
