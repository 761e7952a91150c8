"""Dynamixel Protocol 2.0 framing, written from the ROBOTIS e-manual, for the device side of a link.

A packet is ``FF FF FD 00 | id | length (u16 LE) | instruction | params | CRC-16 (u16 LE)``.
``length`` counts the instruction, the (stuffed) parameters and the two CRC bytes. Wherever the
bytes ``FF FF FD`` appear in the instruction/parameter region the sender inserts an extra ``FD``
(byte stuffing) so a receiver never mistakes data for a header; the CRC covers the stuffed packet.
The CRC is CRC-16 with polynomial 0x8005, initial value 0, no reflection (the "Dynamixel CRC").

This module is independent of dynamixel-sdk on purpose: the emulator must check the real driver's
bytes, not share its code.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE

# Instructions
PING = 0x01
READ = 0x02
WRITE = 0x03
REG_WRITE = 0x04
ACTION = 0x05
FACTORY_RESET = 0x06
REBOOT = 0x08
CLEAR = 0x10
STATUS = 0x55
SYNC_READ = 0x82
SYNC_WRITE = 0x83
BULK_READ = 0x92
BULK_WRITE = 0x93

# Status packet error numbers (low 7 bits of the error byte); bit 7 is the hardware alert.
ERR_RESULT_FAIL = 1
ERR_INSTRUCTION = 2
ERR_CRC = 3
ERR_DATA_RANGE = 4
ERR_DATA_LENGTH = 5
ERR_DATA_LIMIT = 6
ERR_ACCESS = 7
ERR_ALERT = 0x80


def _make_crc_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _make_crc_table()


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """Dynamixel CRC-16 (poly 0x8005, MSB first, init 0) of ``data``."""
    for byte in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` in the instruction/parameter region."""
    out = bytearray()
    for byte in body:
        out.append(byte)
        if byte == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the ``FD`` that stuffing inserted after ``FF FF FD``."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        stuffed = body[i] == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF
        if stuffed and i + 1 < len(body) and body[i + 1] == 0xFD:
            i += 1  # skip the stuffing byte
        i += 1
    return bytes(out)


def build_packet(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete packet (header, id, length, stuffed body, CRC)."""
    body = stuff(bytes([instruction]) + bytes(params))
    head = HEADER + bytes([dxl_id]) + struct.pack("<H", len(body) + 2)
    frame = head + body
    return frame + struct.pack("<H", crc16(frame))


def build_status(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet: instruction 0x55, then the error byte, then the parameters."""
    return build_packet(dxl_id, STATUS, bytes([error]) + bytes(params))


@dataclass(frozen=True)
class Packet:
    """One received packet. ``crc_ok`` is False when the CRC did not match (params then unreliable)."""

    dxl_id: int
    instruction: int
    params: bytes
    crc_ok: bool = True


class PacketParser:
    """Incremental parser: ``feed`` bytes as they arrive, get back complete packets.

    Bytes before a header are discarded. A packet whose CRC does not match is returned with
    ``crc_ok=False`` so the device can answer with a CRC error, as a real servo does.
    """

    MAX_LENGTH = 1024

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Packet]:
        self._buf.extend(data)
        packets: list[Packet] = []
        while True:
            start = self._buf.find(HEADER)
            if start < 0:
                # keep a possible partial header at the end
                del self._buf[: max(0, len(self._buf) - 3)]
                return packets
            del self._buf[:start]
            if len(self._buf) < 7:
                return packets
            length = struct.unpack_from("<H", self._buf, 5)[0]
            if length < 3 or length > self.MAX_LENGTH:
                del self._buf[:1]  # not a real header; resynchronise
                continue
            total = 7 + length
            if len(self._buf) < total:
                return packets
            frame = bytes(self._buf[:total])
            del self._buf[:total]
            crc_ok = crc16(frame[:-2]) == struct.unpack_from("<H", frame, total - 2)[0]
            body = unstuff(frame[7:-2])
            packets.append(Packet(frame[4], body[0] if body else 0, body[1:], crc_ok))

    def clear(self) -> None:
        self._buf.clear()


__all__ = [
    "BROADCAST_ID",
    "Packet",
    "PacketParser",
    "build_packet",
    "build_status",
    "crc16",
    "stuff",
    "unstuff",
]
