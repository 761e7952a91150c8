"""MightyZAP IR serial protocol: packet building and feedback parsing for the driver side.

Instruction: ``FF FF FF | id | size | command | factors | checksum``; feedback:
``FF FF FF | id | size | error | data | checksum``. ``size`` counts the factors (or data) plus the
command (or error) byte and the checksum; ``checksum = ~(id + size + command + factors) & 0xFF``.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = b"\xff\xff\xff"
BROADCAST_ID = 0xFE

CMD_ECHO = 0xF1
CMD_LOAD_DATA = 0xF2
CMD_STORE_DATA = 0xF3
CMD_SEND_DATA = 0xF4
CMD_EXECUTION = 0xF5
CMD_RESTART = 0xF8
CMD_SYMMETRIC_STORE = 0x73

ADDR_SHORT_STROKE_LIMIT = 0x06
ADDR_LONG_STROKE_LIMIT = 0x08
ADDR_FEEDBACK_RETURN_MODE = 0x10
ADDR_GOAL_SPEED = 0x15
ADDR_GOAL_CURRENT = 0x34
ADDR_FORCE_ON_OFF = 0x80
ADDR_GOAL_POSITION = 0x86
ADDR_PRESENT_POSITION = 0x8C  # 2 bytes, then Present Current at 0x8E (2 bytes)

ERROR_BITS = {
    0: "input voltage error",
    1: "stroke limit error",
    4: "checksum error",
    5: "overload",
    6: "instruction error",
}
#: error bits that mean the actuator protects itself (force off): the driver faults on them
FAULT_BITS = (1 << 0) | (1 << 5)


def checksum(body: bytes) -> int:
    return ~sum(body) & 0xFF


def instruction(act_id: int, command: int, factors: bytes = b"") -> bytes:
    body = bytes([act_id, len(factors) + 2, command]) + bytes(factors)
    return HEADER + body + bytes([checksum(body)])


def describe_error(bits: int) -> str:
    return ", ".join(name for bit, name in ERROR_BITS.items() if bits & (1 << bit)) or (
        f"error bits 0x{bits:02x}" if bits else ""
    )


class FeedbackError(ValueError):
    """A feedback packet that is malformed or has a wrong checksum."""


@dataclass(frozen=True)
class Feedback:
    act_id: int
    error: int
    data: bytes


def parse_feedback(packet: bytes) -> Feedback:
    """Check header, size and checksum of one complete feedback packet."""
    if len(packet) < 7 or packet[:3] != HEADER:
        raise FeedbackError(f"not a feedback packet: {packet.hex(' ')}")
    size = packet[4]
    if len(packet) != 5 + size:
        raise FeedbackError(f"size byte {size} does not match {len(packet)} bytes")
    if checksum(packet[3:-1]) != packet[-1]:
        raise FeedbackError("checksum mismatch")
    return Feedback(packet[3], packet[5], bytes(packet[6:-1]))
