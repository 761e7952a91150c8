"""MightyZAP packet building and feedback parsing on the driver side, against hand-worked bytes."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tlt_drivers.mightyzap import protocol as mz


def test_goal_position_packet_bytes():
    # Store Data, Goal Position (0x86) = 2048 to id 1: size = 3 factors + 2; checksum = ~0x187 & 0xFF
    assert mz.instruction(1, mz.CMD_STORE_DATA, bytes([0x86, 0x00, 0x08])) == bytes(
        [0xFF, 0xFF, 0xFF, 0x01, 0x05, 0xF3, 0x86, 0x00, 0x08, 0x78]
    )


def test_parse_feedback_with_error_byte_and_data():
    body = bytes([0x02, 0x04, 0x20, 0x34, 0x12])  # id 2, size 4, error overload, data 0x1234
    packet = mz.HEADER + body + bytes([~sum(body) & 0xFF])
    fb = mz.parse_feedback(packet)
    assert (fb.act_id, fb.error, fb.data) == (2, 0x20, b"\x34\x12")
    assert mz.describe_error(fb.error) == "overload"


@pytest.mark.parametrize(
    ("mutate", "words"),
    [
        (lambda p: p[:-1] + bytes([p[-1] ^ 1]), "checksum"),
        (lambda p: p[:4] + bytes([p[4] + 1]) + p[5:], "size byte"),
        (lambda p: b"\x00" + p[1:], "not a feedback packet"),
    ],
)
def test_bad_feedback_rejected(mutate, words):
    body = bytes([0x01, 0x02, 0x00])
    good = mz.HEADER + body + bytes([~sum(body) & 0xFF])
    with pytest.raises(mz.FeedbackError, match=words):
        mz.parse_feedback(mutate(good))


@given(st.integers(0, 253), st.binary(max_size=20))
def test_checksum_makes_the_byte_sum_0xff(act_id, factors):
    packet = mz.instruction(act_id, mz.CMD_STORE_DATA, factors)
    assert sum(packet[3:]) & 0xFF == 0xFF
