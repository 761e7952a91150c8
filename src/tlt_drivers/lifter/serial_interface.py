"""The lifter's hardware interface: the CRS end of the serial link to the Teensy 4.1 (§V.B.1).

A ros2_control-style :class:`~tlt_drivers.hardware_interface.HardwareInterface` over pyserial:

* ``configure`` opens the port and succeeds only when the firmware answers a state request within
  ``answer_timeout_s``;
* ``read(now)`` takes every byte waiting, decodes the firmware's frames (bad CRCs are counted and
  skipped) and keeps the newest telemetry; when no telemetry has arrived for ``link_timeout_s``
  of the caller's ``now`` it fails, which puts the interface in ERROR with the reason, so motion
  stops being commanded. ``now`` is the control loop's own time base: on the twin that is sim
  time, so a simulation that pauses (and answers nothing meanwhile) is not a dead link;
* ``write`` sends the velocity command (counts/s, one per motor) every control cycle, which is
  what keeps the firmware's watchdog from tripping;
* ``recover`` (base class) closes and reopens the port: the node calls it every
  ``reconnect_period_s`` while in ERROR, so the link comes back when the port does.

Nothing here waits longer than ``answer_timeout_s``; read and write never block.
"""

from __future__ import annotations

import dataclasses
import select
import time
from collections.abc import Callable, Sequence

import serial

from tlt_drivers.hardware_interface import HardwareInterface, Lifecycle

from .config import LifterConfig
from .protocol import (
    MODE_RESULT_TEXT,
    NUM_MOTORS,
    FirmwareState,
    FrameDecoder,
    Mode,
    ModeReply,
    ModeRequest,
    ProtocolError,
    StateRequest,
    StateTelemetry,
    VelocityCommand,
    decode_message,
)


class LinkError(RuntimeError):
    """The firmware does not answer, or the link carries nothing usable."""


class CommandRejected(ValueError):
    """A command outside the configured limits; the message names the joint and the limit."""


class LifterSerialInterface(HardwareInterface):
    """State: ``telemetry`` (newest :class:`StateTelemetry`), ``link_ok``, error counters.
    Command: ``command`` (counts/s per motor), set through :meth:`set_velocity_command`."""

    def __init__(self, config: LifterConfig, *, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__("lifter")
        self.config = config
        self.clock = clock
        self.port: serial.Serial | None = None
        self.decoder = FrameDecoder()
        self.telemetry: StateTelemetry | None = None
        self.frames_received = 0  # telemetry and mode replies since the port was opened
        self._frames_at_read = 0
        self._last_rx_at: float | None = None  # caller's ``now`` when a read last found telemetry
        self.link_ok = False
        self.command: list[int] = [0] * NUM_MOTORS
        self.bad_frames = 0
        self.retries = 0
        self.commands_sent = 0
        self._seq = 0
        self._mode_replies: list[ModeReply] = []

    # --- counters --------------------------------------------
    @property
    def crc_errors(self) -> int:
        return self.decoder.stats.crc_errors

    @property
    def firmware_state(self) -> FirmwareState | None:
        return self.telemetry.state if self.telemetry else None

    # --- commands --------------------------------------------
    def set_velocity_command(self, counts_per_s: Sequence[int]) -> None:
        """Set the per-motor velocity (counts/s) sent from the next ``write`` on.

        Raises :class:`CommandRejected` naming the joint and its limit when a value exceeds the
        joint's ``max_velocity_m_s``; the previous command then stays in force."""
        if len(counts_per_s) != NUM_MOTORS:
            raise CommandRejected(f"expected {NUM_MOTORS} velocities, got {len(counts_per_s)}")
        values = []
        for joint, v in zip(self.config.joints, counts_per_s, strict=True):
            iv = int(v)
            if abs(iv) > joint.max_velocity_counts_s:
                raise CommandRejected(
                    f"joint {joint.name}: velocity {iv} counts/s exceeds its limit max_velocity_m_s = "
                    f"{joint.max_velocity_m_s} m/s ({joint.max_velocity_counts_s} counts/s)"
                )
            values.append(iv)
        self.command = values

    def poll(self) -> None:
        """Ask for one STATE frame without commanding anything; ``read`` picks it up."""
        self._send(StateRequest())

    def stop_motion(self) -> None:
        self.command = [0] * NUM_MOTORS

    def request_mode(self, mode: int) -> tuple[bool, str, FirmwareState | None]:
        """Ask the firmware for ``mode`` and wait (at most ``answer_timeout_s``) for its answer.

        Returns (accepted, reason, firmware state). Never raises: a closed port or no answer is a
        refusal with the reason."""
        try:
            mode = Mode(mode)
        except ValueError:
            return (
                False,
                f"unknown mode {mode} (1 Hardware Control, 2 CRS Control, 3 Safe)",
                self.firmware_state,
            )
        if self.port is None or self.state not in (Lifecycle.INACTIVE, Lifecycle.ACTIVE):
            reason = f"lifter link is {self.state.name.lower()}"
            return False, f"{reason}: {self.fault}" if self.fault else reason, self.firmware_state
        # A new mode starts from standstill, whatever was being commanded.
        self.stop_motion()
        self._mode_replies.clear()
        try:
            self._send(ModeRequest(mode))
            deadline = self.clock() + self.config.answer_timeout_s
            while self.clock() < deadline:
                self._drain(block_s=0.002)
                for reply in self._mode_replies:
                    if reply.requested == mode:
                        if self.telemetry is not None:
                            self.telemetry = dataclasses.replace(self.telemetry, state=reply.state)
                        return reply.accepted, MODE_RESULT_TEXT[reply.result], reply.state
        except (serial.SerialException, OSError) as exc:
            self.set_error(f"mode request failed: {exc}")
            return False, self.fault, self.firmware_state
        return False, f"no answer from the lifter firmware within {self.config.answer_timeout_s} s", None

    # --- lifecycle hooks --------------------------------------------
    def on_configure(self) -> None:
        cfg = self.config
        try:
            self.port = serial.Serial(cfg.port, cfg.baudrate, timeout=0, write_timeout=cfg.answer_timeout_s)
        except (serial.SerialException, OSError) as exc:
            self.port = None
            raise LinkError(f"cannot open lifter port {cfg.port}: {exc}") from exc
        self.port.reset_input_buffer()
        self.decoder.reset()
        self.telemetry = None
        self._last_rx_at = None
        self._send(StateRequest())
        deadline = self.clock() + cfg.answer_timeout_s
        while self.telemetry is None and self.clock() < deadline:
            self._drain(block_s=0.002)
        if self.telemetry is None:
            self._close()
            self.retries += 1
            raise LinkError(f"lifter firmware on {cfg.port} did not answer within {cfg.answer_timeout_s} s")
        self.link_ok = True

    def on_activate(self) -> None:
        self.stop_motion()

    def on_deactivate(self) -> None:
        self.stop_motion()
        if self.port is not None and self.port.is_open:
            self._send(VelocityCommand(tuple(self.command)))

    def on_cleanup(self) -> None:
        self._close()

    def on_read(self, now: float) -> None:
        self._drain()
        if self.frames_received != self._frames_at_read or self._last_rx_at is None:
            self._frames_at_read = self.frames_received
            self._last_rx_at = now
        if now - self._last_rx_at > self.config.link_timeout_s:
            self.link_ok = False
            raise LinkError(
                f"no telemetry from the lifter firmware for more than {self.config.link_timeout_s} s"
            )
        self.link_ok = True
        if self.state != Lifecycle.ACTIVE:
            # write() is not called while inactive, so ask for telemetry to keep it flowing
            self.poll()

    def on_write(self, now: float) -> None:
        self._send(VelocityCommand(tuple(self.command)))
        self.commands_sent += 1

    def set_error(self, reason: str) -> None:
        self.link_ok = False
        super().set_error(reason)

    # --- bytes --------------------------------------------
    def _send(self, message) -> None:
        if self.port is None:
            raise LinkError("lifter port is closed")
        self._seq = (self._seq + 1) & 0xFF
        self.port.write(message.encode(self._seq))

    def _drain(self, block_s: float = 0.0) -> None:
        """Decode everything waiting; with ``block_s`` wait that long for the first byte."""
        if self.port is None:
            raise LinkError("lifter port is closed")
        waiting = self.port.in_waiting
        if not waiting and block_s > 0:
            select.select([self.port.fileno()], [], [], block_s)
            waiting = self.port.in_waiting
        data = self.port.read(waiting) if waiting else b""
        if not data:
            return
        for frame in self.decoder.feed(data):
            try:
                msg = decode_message(frame)
            except ProtocolError as exc:
                self.bad_frames += 1
                self._log.warning("lifter: unusable frame: %s", exc)
                continue
            if isinstance(msg, StateTelemetry):
                self.telemetry = msg
                self.frames_received += 1
            elif isinstance(msg, ModeReply):
                self._mode_replies.append(msg)
                self.frames_received += 1

    def _close(self) -> None:
        self.link_ok = False
        if self.port is not None:
            try:
                self.port.close()
            finally:
                self.port = None


__all__ = ["CommandRejected", "LifterSerialInterface", "LinkError"]
