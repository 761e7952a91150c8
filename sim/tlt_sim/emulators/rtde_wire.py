"""The RTDE wire format of a UR controller (port 30004), from the controller's side.

Every RTDE message is a 3-byte header (big-endian uint16 total size including the header, then
a uint8 message type) followed by a payload. This module frames and unframes messages and packs
the typed values of data packages. It knows the RTDE type of every controller variable a client
may name in a recipe (``OUTPUT_TYPES`` / ``INPUT_TYPES``), the way the controller answers
``CONTROL_PACKAGE_SETUP_OUTPUTS`` and ``..._SETUP_INPUTS`` with a comma-separated type list.

Names are taken from Universal Robots' published RTDE guide; the emulator never invents a type
for a name that is not in these tables (the real controller answers ``NOT_FOUND`` for those).
"""

from __future__ import annotations

import re
import socket
import struct
from collections.abc import Sequence
from typing import Any

HEADER = struct.Struct(">HB")

# Message types (ASCII letters on the wire).
REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")

NOT_FOUND = "NOT_FOUND"
IN_USE = "IN_USE"

# Big-endian struct codes of each RTDE type.
TYPE_FORMATS: dict[str, str] = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}

_V6 = "VECTOR6D"
OUTPUT_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": _V6,
    "target_qd": _V6,
    "target_qdd": _V6,
    "target_current": _V6,
    "target_moment": _V6,
    "actual_q": _V6,
    "actual_qd": _V6,
    "actual_qdd": _V6,
    "actual_current": _V6,
    "actual_current_window": _V6,
    "actual_moment": _V6,
    "joint_control_output": _V6,
    "actual_TCP_pose": _V6,
    "actual_TCP_speed": _V6,
    "actual_TCP_force": _V6,
    "target_TCP_pose": _V6,
    "target_TCP_speed": _V6,
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": _V6,
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": _V6,
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "euromap67_input_bits": "UINT32",
    "euromap67_output_bits": "UINT32",
    "euromap67_24V_voltage": "DOUBLE",
    "euromap67_24V_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "ft_raw_wrench": _V6,
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": _V6,
    "script_control_line": "UINT32",
    "tool_output_mode": "UINT8",
    "tool_digital_output0_mode": "UINT8",
    "tool_digital_output1_mode": "UINT8",
}
for _i in range(48):
    OUTPUT_TYPES[f"output_int_register_{_i}"] = "INT32"
    OUTPUT_TYPES[f"output_double_register_{_i}"] = "DOUBLE"
    OUTPUT_TYPES[f"input_int_register_{_i}"] = "INT32"
    OUTPUT_TYPES[f"input_double_register_{_i}"] = "DOUBLE"
for _i in range(64, 128):
    OUTPUT_TYPES[f"output_bit_register_{_i}"] = "BOOL"
    OUTPUT_TYPES[f"input_bit_register_{_i}"] = "BOOL"

INPUT_TYPES: dict[str, str] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": _V6,
}
for _i in range(48):
    INPUT_TYPES[f"input_int_register_{_i}"] = "INT32"
    INPUT_TYPES[f"input_double_register_{_i}"] = "DOUBLE"
for _i in range(64, 128):
    INPUT_TYPES[f"input_bit_register_{_i}"] = "BOOL"

_REGISTER = re.compile(r"^input_(int|double)_register_(\d+)$")


class ProtocolError(Exception):
    """A peer sent bytes that are not a valid RTDE message."""


def frame(kind: int, payload: bytes = b"") -> bytes:
    """One RTDE message: header plus payload."""
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def recv_exact(sock: socket.socket, n: int) -> bytes:
    """Read exactly ``n`` bytes; ``ConnectionError`` when the peer closes first."""
    chunks = bytearray()
    while len(chunks) < n:
        chunk = sock.recv(n - len(chunks))
        if not chunk:
            raise ConnectionError("peer closed the connection")
        chunks += chunk
    return bytes(chunks)


def read_message(sock: socket.socket) -> tuple[int, bytes]:
    """Read one message; returns (type, payload)."""
    size, kind = HEADER.unpack(recv_exact(sock, HEADER.size))
    if size < HEADER.size:
        raise ProtocolError(f"message size {size} is shorter than the header")
    return kind, recv_exact(sock, size - HEADER.size)


class Recipe:
    """The typed field list of one SETUP_OUTPUTS or SETUP_INPUTS request.

    ``types`` holds the RTDE type per name, or ``NOT_FOUND`` where the table has none.
    """

    def __init__(self, recipe_id: int, names: Sequence[str], table: dict[str, str]) -> None:
        self.recipe_id = recipe_id
        self.names = list(names)
        self.types = [table.get(n, NOT_FOUND) for n in self.names]
        self.valid = NOT_FOUND not in self.types
        self._struct = (
            struct.Struct(">" + "".join(TYPE_FORMATS[t] for t in self.types)) if self.valid else None
        )

    @property
    def unknown(self) -> list[str]:
        return [n for n, t in zip(self.names, self.types, strict=True) if t == NOT_FOUND]

    def answer(self) -> bytes:
        """The controller's reply payload: recipe id and the comma-separated types."""
        return bytes([self.recipe_id]) + ",".join(self.types).encode("ascii")

    def pack(self, values: dict[str, Any]) -> bytes:
        """A DATA_PACKAGE payload (recipe id first) of ``values`` in recipe order."""
        flat: list[Any] = []
        for name, kind in zip(self.names, self.types, strict=True):
            value = values[name]
            if kind.startswith("VECTOR"):
                flat.extend(value)
            else:
                flat.append(value)
        return bytes([self.recipe_id]) + self._struct.pack(*flat)

    def unpack(self, payload: bytes) -> dict[str, Any]:
        """Values of a DATA_PACKAGE payload whose first byte is this recipe's id."""
        if self._struct is None:
            raise ProtocolError(f"recipe {self.recipe_id} has unknown names {self.unknown}")
        if len(payload) - 1 != self._struct.size:
            got, want = len(payload) - 1, self._struct.size
            raise ProtocolError(f"recipe {self.recipe_id}: data package of {got} bytes, expected {want}")
        flat = list(self._struct.unpack(payload[1:]))
        out: dict[str, Any] = {}
        for name, kind in zip(self.names, self.types, strict=True):
            width = int(kind[6]) if kind.startswith("VECTOR") else 1
            out[name] = flat[:width] if width > 1 else flat[0]
            del flat[:width]
        return out


def parse_names(text: bytes) -> list[str]:
    """The variable names of a setup request (comma-separated, trailing comma allowed)."""
    return [n.strip() for n in text.decode("ascii", errors="replace").split(",") if n.strip()]


def register_index(name: str) -> tuple[str, int] | None:
    """``("int", 3)`` for ``input_int_register_3`` and so on; None for other inputs."""
    match = _REGISTER.match(name)
    return (match.group(1), int(match.group(2))) if match else None
