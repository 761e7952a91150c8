"""The framed binary protocol between the CRS and the lifter's Teensy 4.1 (paper §V.B.1).

Shared by the driver (``tlt_drivers.lifter``) and the firmware emulator (``tlt_sim.emulators``),
so both ends encode and decode the same bytes. The byte layout is documented in
``docs/lifter-protocol.md``; in short every frame is::

    0xA5 0x5A | type u8 | seq u8 | length u8 | payload (length bytes) | CRC-16 u16 big-endian

The CRC is CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF, no reflection, no final
XOR) over ``type, seq, length, payload``. Multi-byte payload fields are little-endian, as the
Teensy (ARM Cortex-M7) stores them.

:class:`FrameDecoder` is an incremental stream decoder: bytes go in as they arrive, whole frames
come out. It skips garbage before a sync pattern, and on a bad CRC or an impossible length it
drops one byte and searches again, so a corrupted frame costs that frame only.
"""

from __future__ import annotations

import binascii
import enum
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

SYNC = b"\xa5\x5a"
HEADER_SIZE = 5  # sync (2) + type + seq + length
CRC_SIZE = 2
MAX_PAYLOAD = 64
NUM_MOTORS = 4
NUM_SWITCHES = 2 * NUM_MOTORS
INT32_MIN = -(2**31)
INT32_MAX = 2**31 - 1


class ProtocolError(ValueError):
    """A frame or payload does not follow the protocol (wrong length, unknown type, bad value)."""


class MsgType(enum.IntEnum):
    """Message type byte. Host -> firmware below 0x80, firmware -> host from 0x80."""

    VELOCITY_COMMAND = 0x01
    MODE_REQUEST = 0x02
    STATE_REQUEST = 0x03
    STATE = 0x81
    MODE_REPLY = 0x82


class FirmwareState(enum.IntEnum):
    """States of the firmware state machine (Fig. 41); values match ``LifterState.STATE_*``."""

    INITIALIZING = 0
    HARDWARE_CONTROL = 1
    CRS_CONTROL = 2
    SAFE = 3


class Mode(enum.IntEnum):
    """States the CRS may request; values match ``SetLifterMode.MODE_*``."""

    HARDWARE_CONTROL = 1
    CRS_CONTROL = 2
    SAFE = 3


class ModeResult(enum.IntEnum):
    """Why a mode request was accepted or refused (MODE_REPLY ``result`` byte)."""

    ACCEPTED = 0
    REFUSED_BUTTON_PRESSED = 1
    REFUSED_INITIALIZING = 2
    REFUSED_UNKNOWN_MODE = 3


MODE_RESULT_TEXT = {
    ModeResult.ACCEPTED: "accepted",
    ModeResult.REFUSED_BUTTON_PRESSED: "refused: a push button is pressed",
    ModeResult.REFUSED_INITIALIZING: "refused: the firmware is still initializing",
    ModeResult.REFUSED_UNKNOWN_MODE: "refused: unknown mode",
}

# STATE flags byte
FLAG_WATCHDOG_TRIPPED = 0x01
FLAG_BUTTON_PRESSED = 0x02

_VELOCITY_FMT = struct.Struct("<4i")  # four int32 counts/s
# state, flags, limit-switch bits, ack seq, four int32 positions, four int32 velocities
_STATE_FMT = struct.Struct("<BBBB4i4i")


def crc16_ccitt(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (check value for b"123456789" is 0x29B1)."""
    return binascii.crc_hqx(data, 0xFFFF)


@dataclass(frozen=True)
class Frame:
    """One decoded frame: its type byte (not necessarily a known :class:`MsgType`), seq, payload."""

    type: int
    seq: int
    payload: bytes


def encode_frame(msg_type: int, seq: int, payload: bytes = b"") -> bytes:
    """Build the bytes of one frame. Raises :class:`ProtocolError` on an oversize payload."""
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"payload of {len(payload)} bytes exceeds the maximum of {MAX_PAYLOAD}")
    if not 0 <= msg_type <= 0xFF or not 0 <= seq <= 0xFF:
        raise ProtocolError(f"type {msg_type} and seq {seq} must each fit in one byte")
    body = bytes((msg_type, seq, len(payload))) + payload
    return SYNC + body + struct.pack(">H", crc16_ccitt(body))


# --- typed messages --------------------------------------------------------------------------------


def _int32s(values: Sequence[int], what: str) -> tuple[int, ...]:
    if len(values) != NUM_MOTORS:
        raise ProtocolError(f"{what}: expected {NUM_MOTORS} values, got {len(values)}")
    out = []
    for i, v in enumerate(values):
        iv = int(v)
        if iv != v or not INT32_MIN <= iv <= INT32_MAX:
            raise ProtocolError(f"{what}[{i}] = {v!r} is not an int32")
        out.append(iv)
    return tuple(out)


@dataclass(frozen=True)
class VelocityCommand:
    """Joint velocities for the four motors, counts/s (host -> firmware, 16 bytes)."""

    velocities: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "velocities", _int32s(self.velocities, "velocities"))

    def encode(self, seq: int) -> bytes:
        return encode_frame(MsgType.VELOCITY_COMMAND, seq, _VELOCITY_FMT.pack(*self.velocities))

    @classmethod
    def decode(cls, payload: bytes) -> VelocityCommand:
        _expect_len(payload, _VELOCITY_FMT.size, "VELOCITY_COMMAND")
        return cls(_VELOCITY_FMT.unpack(payload))


@dataclass(frozen=True)
class ModeRequest:
    """Ask the firmware to enter a state (host -> firmware, 1 byte)."""

    mode: int

    def encode(self, seq: int) -> bytes:
        return encode_frame(MsgType.MODE_REQUEST, seq, bytes((self.mode & 0xFF,)))

    @classmethod
    def decode(cls, payload: bytes) -> ModeRequest:
        _expect_len(payload, 1, "MODE_REQUEST")
        return cls(payload[0])


@dataclass(frozen=True)
class StateRequest:
    """Ask for one STATE frame without commanding anything (host -> firmware, empty)."""

    def encode(self, seq: int) -> bytes:
        return encode_frame(MsgType.STATE_REQUEST, seq)

    @classmethod
    def decode(cls, payload: bytes) -> StateRequest:
        _expect_len(payload, 0, "STATE_REQUEST")
        return cls()


@dataclass(frozen=True)
class ModeReply:
    """The firmware's answer to a MODE_REQUEST (firmware -> host, 3 bytes)."""

    requested: int
    result: ModeResult
    state: FirmwareState

    @property
    def accepted(self) -> bool:
        return self.result == ModeResult.ACCEPTED

    def encode(self, seq: int) -> bytes:
        return encode_frame(MsgType.MODE_REPLY, seq, bytes((self.requested, self.result, self.state)))

    @classmethod
    def decode(cls, payload: bytes) -> ModeReply:
        _expect_len(payload, 3, "MODE_REPLY")
        return cls(
            payload[0], _enum(ModeResult, payload[1], "result"), _enum(FirmwareState, payload[2], "state")
        )


@dataclass(frozen=True)
class StateTelemetry:
    """Firmware state (firmware -> host, 36 bytes).

    ``limit_switches``: [0..3] upper switches of motors 0..3, [4..7] lower switches, as in
    ``LifterState``. ``buttons_pressed`` says whether any push button is held.
    """

    state: FirmwareState
    positions: tuple[int, ...]
    velocities: tuple[int, ...]
    limit_switches: tuple[bool, ...]
    watchdog_tripped: bool = False
    buttons_pressed: bool = False
    ack_seq: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "positions", _int32s(self.positions, "positions"))
        object.__setattr__(self, "velocities", _int32s(self.velocities, "velocities"))
        if len(self.limit_switches) != NUM_SWITCHES:
            raise ProtocolError(
                f"limit_switches: expected {NUM_SWITCHES} values, got {len(self.limit_switches)}"
            )
        object.__setattr__(self, "limit_switches", tuple(bool(s) for s in self.limit_switches))

    def encode(self, seq: int) -> bytes:
        flags = (FLAG_WATCHDOG_TRIPPED if self.watchdog_tripped else 0) | (
            FLAG_BUTTON_PRESSED if self.buttons_pressed else 0
        )
        switches = sum(1 << i for i, s in enumerate(self.limit_switches) if s)
        payload = _STATE_FMT.pack(
            self.state, flags, switches, self.ack_seq & 0xFF, *self.positions, *self.velocities
        )
        return encode_frame(MsgType.STATE, seq, payload)

    @classmethod
    def decode(cls, payload: bytes) -> StateTelemetry:
        _expect_len(payload, _STATE_FMT.size, "STATE")
        state, flags, switches, ack, *rest = _STATE_FMT.unpack(payload)
        return cls(
            state=_enum(FirmwareState, state, "state"),
            positions=tuple(rest[:NUM_MOTORS]),
            velocities=tuple(rest[NUM_MOTORS:]),
            limit_switches=tuple(bool(switches >> i & 1) for i in range(NUM_SWITCHES)),
            watchdog_tripped=bool(flags & FLAG_WATCHDOG_TRIPPED),
            buttons_pressed=bool(flags & FLAG_BUTTON_PRESSED),
            ack_seq=ack,
        )


Message = VelocityCommand | ModeRequest | StateRequest | ModeReply | StateTelemetry

_DECODERS: dict[MsgType, Callable[[bytes], Message]] = {
    MsgType.VELOCITY_COMMAND: VelocityCommand.decode,
    MsgType.MODE_REQUEST: ModeRequest.decode,
    MsgType.STATE_REQUEST: StateRequest.decode,
    MsgType.STATE: StateTelemetry.decode,
    MsgType.MODE_REPLY: ModeReply.decode,
}


def decode_message(frame: Frame) -> Message:
    """Turn a frame into its typed message. Raises :class:`ProtocolError` on an unknown type or
    a payload of the wrong size or value."""
    try:
        decoder = _DECODERS[MsgType(frame.type)]
    except ValueError:
        raise ProtocolError(f"unknown message type 0x{frame.type:02X}") from None
    return decoder(frame.payload)


def _expect_len(payload: bytes, size: int, what: str) -> None:
    if len(payload) != size:
        raise ProtocolError(f"{what} payload must be {size} bytes, got {len(payload)}")


def _enum(kind: type[enum.IntEnum], value: int, what: str):
    try:
        return kind(value)
    except ValueError:
        raise ProtocolError(f"{what} value {value} is not a {kind.__name__}") from None


# --- stream decoding -------------------------------------------------------------------------------


@dataclass
class DecoderStats:
    """Counters of what the decoder saw since it was made."""

    frames: int = 0
    crc_errors: int = 0
    bad_lengths: int = 0
    bytes_discarded: int = 0


class FrameDecoder:
    """Incremental decoder: ``feed`` bytes as they arrive, get back every whole frame they complete.

    Never raises on bad input. Garbage before a sync pattern is discarded; a frame with a wrong
    CRC (counted in ``stats.crc_errors``) or a length above :data:`MAX_PAYLOAD` (``bad_lengths``)
    loses its first byte and the search resumes right after it, so a real frame hidden inside
    corrupted bytes is still found. The buffer never holds more than one maximal frame of
    unconsumed bytes plus what one ``feed`` adds.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = DecoderStats()

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        frames: list[Frame] = []
        buf = self._buf
        while True:
            start = buf.find(SYNC)
            if start < 0:
                # keep a trailing first sync byte: its partner may come in the next read
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self._discard(len(buf) - keep)
                break
            if start:
                self._discard(start)
            if len(buf) < HEADER_SIZE:
                break
            length = buf[4]
            if length > MAX_PAYLOAD:
                self.stats.bad_lengths += 1
                self._discard(1)
                continue
            total = HEADER_SIZE + length + CRC_SIZE
            if len(buf) < total:
                break
            body = bytes(buf[2 : HEADER_SIZE + length])
            (crc,) = struct.unpack_from(">H", buf, HEADER_SIZE + length)
            if crc != crc16_ccitt(body):
                self.stats.crc_errors += 1
                self._discard(1)
                continue
            frames.append(Frame(body[0], body[1], body[3:]))
            self.stats.frames += 1
            del buf[:total]
        return frames

    def reset(self) -> None:
        """Forget buffered bytes (after the link was reopened); counters are kept."""
        self._buf.clear()

    def _discard(self, n: int) -> None:
        if n > 0:
            del self._buf[:n]
            self.stats.bytes_discarded += n


__all__ = [
    "MAX_PAYLOAD",
    "MODE_RESULT_TEXT",
    "NUM_MOTORS",
    "NUM_SWITCHES",
    "SYNC",
    "DecoderStats",
    "FirmwareState",
    "Frame",
    "FrameDecoder",
    "Message",
    "Mode",
    "ModeReply",
    "ModeRequest",
    "ModeResult",
    "MsgType",
    "ProtocolError",
    "StateRequest",
    "StateTelemetry",
    "VelocityCommand",
    "crc16_ccitt",
    "decode_message",
    "encode_frame",
]
