"""The lifter's Teensy 4.1 firmware: its state machine (paper §V.B.1, Fig. 41) and its serial link.

:class:`LifterFirmware` is the device model. It holds plain state (encoder positions in counts,
motor velocities in counts/s, eight limit switches, ten push buttons, the potentiometer) and runs
the state machine on its own model time, advanced only by :meth:`LifterFirmware.step`, so tests
and the MuJoCo twin drive it deterministically. Bytes from the CRS go in through
:meth:`LifterFirmware.receive`, which returns the reply bytes.

The state machine, exactly as §V.B.1 states it:

* **Initializing** -> **Hardware Control** once ``init_duration_s`` has passed.
* **Hardware Control**: a pressed push button drives its motor(s) in its direction at the speed
  the potentiometer sets, for each motor only if that motor's limit switch in that direction is
  not pressed. The CRS may request CRS Control only while no button is pressed.
* **CRS Control**: velocity commands set the motor velocities; a motor drives only if its limit
  switch in the direction of its velocity is not pressed. A button press zeroes the velocities and
  returns to Hardware Control. Watchdog: when no velocity command has arrived for more than twice
  the CRS command period, the velocities are zeroed and ``watchdog_tripped`` is reported until
  the next command.
* **Safe**: buttons and velocity commands are ignored and the motors stand still. A request from
  the CRS moves Safe to Hardware Control or CRS Control (the latter, as from Hardware Control,
  only while no button is held); the CRS can request Safe from any state.

Limit switches assert from the positions against the configured travel limits, unless forced
(a stuck switch, or a switch the twin drives). :mod:`~tlt_sim.emulators.lifter_pty` serves the
model on a pseudo-terminal in real time, for the real driver (pyserial) to open. Injected faults live in
:class:`FirmwareFaults`: no answer, corrupted CRCs, stuck switches (:meth:`force_switch`) and a
dropped link.
"""

from __future__ import annotations

import enum
import math
import threading
from dataclasses import dataclass
from pathlib import Path

from tlt_common.config_schema import Field, load_validated, opt
from tlt_drivers.lifter.protocol import (
    NUM_MOTORS,
    NUM_SWITCHES,
    FirmwareState,
    FrameDecoder,
    Mode,
    ModeReply,
    ModeRequest,
    ModeResult,
    ProtocolError,
    StateRequest,
    StateTelemetry,
    VelocityCommand,
    decode_message,
)


class Button(enum.IntEnum):
    """The ten push buttons: each motor clockwise / counter-clockwise, and all motors.

    Clockwise drives a motor towards its upper limit switch (positive counts)."""

    MOTOR0_CW = 0
    MOTOR0_CCW = 1
    MOTOR1_CW = 2
    MOTOR1_CCW = 3
    MOTOR2_CW = 4
    MOTOR2_CCW = 5
    MOTOR3_CW = 6
    MOTOR3_CCW = 7
    ALL_CW = 8
    ALL_CCW = 9

    @property
    def direction(self) -> int:
        return 1 if self.name.endswith("_CW") else -1

    def drives(self, motor: int) -> bool:
        return self in (Button.ALL_CW, Button.ALL_CCW) or self.value // 2 == motor

    @classmethod
    def for_motor(cls, motor: int, direction: int) -> Button:
        return cls(2 * motor + (0 if direction > 0 else 1))


@dataclass(frozen=True)
class FirmwareConfig:
    """What the Teensy is configured with. Travel limits and positions in encoder counts."""

    command_period_s: float = 0.02
    init_duration_s: float = 0.5
    button_max_speed_counts_s: int = 20000
    max_velocity_counts_s: int = 100000
    lower_limit_counts: tuple[int, ...] = (0, 0, 0, 0)
    upper_limit_counts: tuple[int, ...] = (1_000_000, 1_000_000, 1_000_000, 1_000_000)
    initial_positions_counts: tuple[int, ...] = (0, 0, 0, 0)
    tick_s: float = 0.001

    @property
    def watchdog_timeout_s(self) -> float:
        return 2.0 * self.command_period_s


@dataclass
class FirmwareFaults:
    """Injected faults. ``corrupt_next`` replies go out with a wrong CRC, as does every
    ``corrupt_every_n``-th reply (0: never); ``link_down_until`` is model time until which nothing
    is read (incoming bytes are lost) or written."""

    no_answer: bool = False
    corrupt_next: int = 0
    corrupt_every_n: int = 0
    link_down_until: float = -math.inf


def _four_ints(value: list) -> str | None:
    return None if len(value) == NUM_MOTORS else f"expected {NUM_MOTORS} values (one per motor)"


_INT_LIST = Field("list", item=Field("int"), check=_four_ints)
FIRMWARE_SCHEMA = {
    "command_period_s": Field("float", minimum=0.001, doc="CRS command period the watchdog doubles"),
    "init_duration_s": opt("float", 0.5, minimum=0.0),
    "button_max_speed_counts_s": opt("int", 20000, minimum=0),
    "max_velocity_counts_s": opt("int", 100000, minimum=1),
    "lower_limit_counts": _INT_LIST,
    "upper_limit_counts": _INT_LIST,
    "initial_positions_counts": opt("list", [0, 0, 0, 0], item=Field("int"), check=_four_ints),
    "tick_s": opt("float", 0.001, minimum=0.0001, maximum=0.05),
    "link_path": opt("str", ""),
    "faults": opt(
        "dict",
        {},
        schema={
            "no_answer": opt("bool", False),
            "corrupt_every_n": opt("int", 0, minimum=0),
            "stuck_switches": opt("map", {}, item=Field("bool")),
        },
    ),
}


def load_firmware_config(path: str | Path) -> tuple[FirmwareConfig, dict]:
    """Load the emulator's YAML; returns the config and the validated document (link path, faults).

    Raises ``ConfigError`` naming the file and key on any bad value."""
    doc = load_validated(path, FIRMWARE_SCHEMA)
    config = FirmwareConfig(
        command_period_s=doc["command_period_s"],
        init_duration_s=doc["init_duration_s"],
        button_max_speed_counts_s=doc["button_max_speed_counts_s"],
        max_velocity_counts_s=doc["max_velocity_counts_s"],
        lower_limit_counts=tuple(doc["lower_limit_counts"]),
        upper_limit_counts=tuple(doc["upper_limit_counts"]),
        initial_positions_counts=tuple(doc["initial_positions_counts"]),
        tick_s=doc["tick_s"],
    )
    return config, doc


@dataclass(frozen=True)
class Transition:
    """One state change of the firmware, at model time ``time``."""

    time: float
    source: FirmwareState
    target: FirmwareState
    reason: str


class LifterFirmware:
    """The firmware model. Every public method is thread-safe (one re-entrant lock).

    Reads: bytes from the CRS (:meth:`receive`), buttons, potentiometer, forced switches.
    Writes: reply bytes, positions, velocities. Never raises on bad input bytes: a frame it cannot
    use is counted in ``bad_frames`` and otherwise ignored, as firmware would.
    """

    def __init__(self, config: FirmwareConfig | None = None, faults: FirmwareFaults | None = None) -> None:
        self.config = config or FirmwareConfig()
        self.faults = faults or FirmwareFaults()
        self.lock = threading.RLock()
        self.time = 0.0
        self.state = FirmwareState.INITIALIZING
        self.positions = [float(p) for p in self.config.initial_positions_counts]
        self.commanded = [0] * NUM_MOTORS  # CRS velocities in force, counts/s
        self.velocities = [0] * NUM_MOTORS  # what each motor is driven at, counts/s
        self.buttons: set[Button] = set()
        self.potentiometer = 0.5  # fraction of full scale
        self.switch_overrides: dict[int, bool] = {}
        self.watchdog_tripped = False
        self.watchdog_trips = 0
        self.last_command_time = 0.0
        self.transitions: list[Transition] = []
        self.decoder = FrameDecoder()
        self.frames_received = 0
        self.bad_frames = 0
        self.replies_sent = 0
        self._tx_seq = 0

    # --- the device's physical inputs -------------------------------------------------------------
    def press(self, button: Button) -> None:
        with self.lock:
            self.buttons.add(Button(button))
            if self.state == FirmwareState.CRS_CONTROL:
                self._enter(FirmwareState.HARDWARE_CONTROL, "push button pressed in CRS Control")
            self._update_drive()

    def release(self, button: Button) -> None:
        with self.lock:
            self.buttons.discard(Button(button))
            self._update_drive()

    def release_all(self) -> None:
        with self.lock:
            self.buttons.clear()
            self._update_drive()

    def set_potentiometer(self, fraction: float) -> None:
        """Potentiometer position, 0 (stopped) to 1 (``button_max_speed_counts_s``)."""
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"potentiometer fraction must be within 0..1, got {fraction}")
        with self.lock:
            self.potentiometer = fraction
            self._update_drive()

    def force_switch(self, index: int, pressed: bool) -> None:
        """Hold limit switch ``index`` (0..3 upper, 4..7 lower) at ``pressed`` whatever the
        position says: a stuck switch, or a switch the twin computes from contact."""
        self._check_switch(index)
        with self.lock:
            self.switch_overrides[index] = bool(pressed)
            self._update_drive()

    def release_switch(self, index: int) -> None:
        """Let limit switch ``index`` follow the position again."""
        self._check_switch(index)
        with self.lock:
            self.switch_overrides.pop(index, None)
            self._update_drive()

    def set_position(self, motor: int, counts: float) -> None:
        """Move an encoder reading (the twin writes the simulated carriage position here)."""
        with self.lock:
            self.positions[motor] = float(counts)
            self._update_drive()

    def set_positions(self, counts: list[float]) -> None:
        """Move every encoder reading at once (one drive decision, not one per motor)."""
        if len(counts) != NUM_MOTORS:
            raise ValueError(f"expected {NUM_MOTORS} encoder readings, got {len(counts)}")
        with self.lock:
            self.positions[:] = [float(c) for c in counts]
            self._update_drive()

    def drop_link(self, duration_s: float) -> None:
        """Read and write nothing for ``duration_s`` of model time; bytes sent meanwhile are lost."""
        with self.lock:
            self.faults.link_down_until = self.time + duration_s

    # --- readings --------------------------------------------
    def limit_switches(self) -> tuple[bool, ...]:
        """[0..3] upper switches of motors 0..3, [4..7] lower switches."""
        with self.lock:
            cfg = self.config
            upper = [self.positions[i] >= cfg.upper_limit_counts[i] for i in range(NUM_MOTORS)]
            lower = [self.positions[i] <= cfg.lower_limit_counts[i] for i in range(NUM_MOTORS)]
            return tuple(self.switch_overrides.get(i, s) for i, s in enumerate(upper + lower))

    def encoder_counts(self) -> tuple[int, ...]:
        with self.lock:
            return tuple(round(p) for p in self.positions)

    def telemetry(self, ack_seq: int = 0) -> StateTelemetry:
        with self.lock:
            return StateTelemetry(
                state=self.state,
                positions=self.encoder_counts(),
                velocities=tuple(self.velocities),
                limit_switches=self.limit_switches(),
                watchdog_tripped=self.watchdog_tripped,
                buttons_pressed=bool(self.buttons),
                ack_seq=ack_seq,
            )

    # --- time --------------------------------------------
    def step(self, dt: float, *, integrate: bool = True) -> None:
        """Advance model time by ``dt`` s: the motors move at the velocities decided at the start
        of the interval, then the state machine runs at the new time.

        With ``integrate=False`` the positions are left alone: the twin, which moves the carriages
        in MuJoCo from ``velocities``, writes them back with :meth:`set_position`."""
        if dt < 0:
            raise ValueError(f"dt must not be negative, got {dt}")
        with self.lock:
            if integrate:
                for i in range(NUM_MOTORS):
                    self.positions[i] += self.velocities[i] * dt
            self.time += dt
            if self.state == FirmwareState.INITIALIZING and self.time >= self.config.init_duration_s:
                self._enter(FirmwareState.HARDWARE_CONTROL, "initialization finished")
            elif self.state == FirmwareState.CRS_CONTROL:
                if self.buttons:
                    self._enter(FirmwareState.HARDWARE_CONTROL, "push button pressed in CRS Control")
                elif self.time - self.last_command_time > self.config.watchdog_timeout_s:
                    if not self.watchdog_tripped:
                        self.watchdog_trips += 1
                    self.watchdog_tripped = True
                    self.commanded = [0] * NUM_MOTORS
            self._update_drive()

    # --- the serial link --------------------------------------------
    def receive(self, data: bytes) -> bytes:
        """Take bytes from the CRS; return the bytes the firmware answers with (maybe none)."""
        with self.lock:
            if self.time < self.faults.link_down_until:
                return b""
            out = bytearray()
            for frame in self.decoder.feed(data):
                self.frames_received += 1
                try:
                    msg = decode_message(frame)
                except ProtocolError:
                    self.bad_frames += 1
                    continue
                reply = self._handle(msg, frame.seq)
                if reply is not None and not self.faults.no_answer:
                    out += self._corrupt(reply)
            return bytes(out)

    def _handle(self, msg, seq: int) -> bytes | None:
        if isinstance(msg, VelocityCommand):
            if self.state == FirmwareState.CRS_CONTROL:
                top = self.config.max_velocity_counts_s
                self.commanded = [max(-top, min(top, v)) for v in msg.velocities]
                self.last_command_time = self.time
                self.watchdog_tripped = False
                self._update_drive()
            return self._reply(self.telemetry(seq))
        if isinstance(msg, ModeRequest):
            result = self._request_mode(msg.mode)
            return self._reply(ModeReply(msg.mode, result, self.state))
        if isinstance(msg, StateRequest):
            return self._reply(self.telemetry(seq))
        self.bad_frames += 1  # a firmware-to-host message sent to the firmware
        return None

    def _reply(self, message: StateTelemetry | ModeReply) -> bytes:
        self._tx_seq = (self._tx_seq + 1) & 0xFF
        self.replies_sent += 1
        return message.encode(self._tx_seq)

    def _corrupt(self, frame: bytes) -> bytes:
        faults = self.faults
        bad = faults.corrupt_next > 0 or (
            faults.corrupt_every_n > 0 and self.replies_sent % faults.corrupt_every_n == 0
        )
        if not bad:
            return frame
        faults.corrupt_next = max(0, faults.corrupt_next - 1)
        return frame[:-1] + bytes((frame[-1] ^ 0xFF,))

    # --- the state machine --------------------------------------------
    def request_mode(self, mode: int) -> ModeResult:
        """The CRS asks for ``mode`` (a :class:`Mode` value); returns whether and why not."""
        with self.lock:
            return self._request_mode(mode)

    def _request_mode(self, mode: int) -> ModeResult:
        if mode == Mode.SAFE:
            self._enter(FirmwareState.SAFE, "CRS requested Safe")
            return ModeResult.ACCEPTED
        if mode not in (Mode.HARDWARE_CONTROL, Mode.CRS_CONTROL):
            return ModeResult.REFUSED_UNKNOWN_MODE
        if self.state == FirmwareState.INITIALIZING:
            return ModeResult.REFUSED_INITIALIZING
        if mode == Mode.HARDWARE_CONTROL:
            self._enter(FirmwareState.HARDWARE_CONTROL, "CRS requested Hardware Control")
            return ModeResult.ACCEPTED
        if self.buttons:
            # a held button would throw CRS Control straight back to Hardware Control
            return ModeResult.REFUSED_BUTTON_PRESSED
        self._enter(FirmwareState.CRS_CONTROL, "CRS requested CRS Control")
        return ModeResult.ACCEPTED

    def _enter(self, target: FirmwareState, reason: str) -> None:
        # Every entry starts with the motors stopped: a new state never inherits old velocities.
        self.commanded = [0] * NUM_MOTORS
        self.watchdog_tripped = False
        self.last_command_time = self.time
        if target != self.state:
            self.transitions.append(Transition(self.time, self.state, target, reason))
            self.state = target
        self._update_drive()

    def _update_drive(self) -> None:
        """Decide each motor's velocity from the state, the inputs and its limit switches."""
        switches = self.limit_switches()
        for i in range(NUM_MOTORS):
            if self.state == FirmwareState.HARDWARE_CONTROL:
                directions = {b.direction for b in self.buttons if b.drives(i)}
                # both directions held at once on one motor: no clear intention, stand still
                wanted = directions.pop() if len(directions) == 1 else 0
                speed = round(self.potentiometer * self.config.button_max_speed_counts_s)
                velocity = wanted * speed
            elif self.state == FirmwareState.CRS_CONTROL:
                velocity = self.commanded[i]
            else:
                velocity = 0
            if (velocity > 0 and switches[i]) or (velocity < 0 and switches[NUM_MOTORS + i]):
                velocity = 0
            self.velocities[i] = velocity

    @staticmethod
    def _check_switch(index: int) -> None:
        if not 0 <= index < NUM_SWITCHES:
            raise ValueError(f"limit switch index must be 0..{NUM_SWITCHES - 1}, got {index}")


__all__ = [
    "FIRMWARE_SCHEMA",
    "Button",
    "FirmwareConfig",
    "FirmwareFaults",
    "LifterFirmware",
    "Transition",
    "load_firmware_config",
]
