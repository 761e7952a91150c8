"""RTDE framing and recipes as the controller side answers them."""

from __future__ import annotations

import socket
import struct

import pytest
from tlt_sim.emulators import rtde_wire as wire


def test_frame_header_is_size_then_type() -> None:
    data = wire.frame(wire.REQUEST_PROTOCOL_VERSION, b"\x00\x02")
    assert data == struct.pack(">HB", 5, ord("V")) + b"\x00\x02"


def test_read_message_over_a_socket_pair() -> None:
    a, b = socket.socketpair()
    with a, b:
        a.sendall(wire.frame(wire.START) + wire.frame(wire.TEXT_MESSAGE, b"hi"))
        assert wire.read_message(b) == (wire.START, b"")
        assert wire.read_message(b) == (wire.TEXT_MESSAGE, b"hi")
        a.close()
        with pytest.raises(ConnectionError):
            wire.read_message(b)


def test_output_recipe_answers_types_and_packs_big_endian() -> None:
    names = wire.parse_names(b"timestamp,actual_q,robot_mode,runtime_state,payload_cog,joint_mode,")
    recipe = wire.Recipe(1, names, wire.OUTPUT_TYPES)
    assert recipe.valid
    assert recipe.answer() == b"\x01DOUBLE,VECTOR6D,INT32,UINT32,VECTOR3D,VECTOR6INT32"
    values = {
        "timestamp": 1.5,
        "actual_q": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
        "robot_mode": 7,
        "runtime_state": 2,
        "payload_cog": [0.0, 0.0, 0.1],
        "joint_mode": [253] * 6,
    }
    packed = recipe.pack(values)
    assert packed[0] == 1
    assert packed[1:] == struct.pack(">d6diI3d6i", 1.5, *values["actual_q"], 7, 2, 0.0, 0.0, 0.1, *[253] * 6)


def test_unknown_name_answers_not_found() -> None:
    recipe = wire.Recipe(1, ["actual_q", "no_such_variable"], wire.OUTPUT_TYPES)
    assert not recipe.valid
    assert recipe.answer() == b"\x01VECTOR6D,NOT_FOUND"
    assert recipe.unknown == ["no_such_variable"]


def test_input_recipe_round_trip_and_register_names() -> None:
    recipe = wire.Recipe(
        3, ["input_int_register_0", "input_double_register_7", "external_force_torque"], wire.INPUT_TYPES
    )
    assert recipe.answer() == b"\x03INT32,DOUBLE,VECTOR6D"
    payload = b"\x03" + struct.pack(">id6d", 11, 0.25, 1, 2, 3, 4, 5, 6)
    assert recipe.unpack(payload) == {
        "input_int_register_0": 11,
        "input_double_register_7": 0.25,
        "external_force_torque": [1, 2, 3, 4, 5, 6],
    }
    with pytest.raises(wire.ProtocolError):
        recipe.unpack(payload[:-1])
    assert wire.register_index("input_int_register_24") == ("int", 24)
    assert wire.register_index("input_double_register_3") == ("double", 3)
    assert wire.register_index("speed_slider_mask") is None
