"""The header stamp read from raw CDR bytes equals the one rclpy serialized."""

from __future__ import annotations

import struct

from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from tlt_common.recording.header_stamp import header_stamp_ns


def joint_state_bytes(sec: int, nanosec: int) -> bytes:
    msg = JointState()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    msg.name = ["a"]
    return serialize_message(msg)


def test_stamp_of_a_real_message():
    assert header_stamp_ns(joint_state_bytes(1_700_000_000, 123_456_789)) == 1_700_000_000_123_456_789


def test_unset_stamp_means_none_so_the_receive_time_is_used():
    assert header_stamp_ns(joint_state_bytes(0, 0)) is None


def test_big_endian_cdr_is_read_in_its_byte_order():
    data = b"\x00\x00\x00\x00" + struct.pack(">iI", 7, 5) + b"\x00" * 8
    assert header_stamp_ns(data) == 7_000_000_005


def test_short_or_foreign_encodings_give_none():
    assert header_stamp_ns(b"\x00\x01\x00\x00\x01") is None
    assert header_stamp_ns(b"\x00\x02\x00\x00" + struct.pack("<iI", 7, 5)) is None  # PL_CDR
    assert header_stamp_ns(b"\x00\x01\x00\x00" + struct.pack("<iI", 7, 2_000_000_000)) is None
    assert header_stamp_ns(b"\x00\x01\x00\x00" + struct.pack("<iI", -3, 0)) is None
