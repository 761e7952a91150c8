"""The lifter protocol codec: frame layout, CRC, typed messages, and resynchronisation."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tlt_drivers.lifter.protocol import (
    MAX_PAYLOAD,
    SYNC,
    FirmwareState,
    Frame,
    FrameDecoder,
    ModeReply,
    ModeRequest,
    ModeResult,
    MsgType,
    ProtocolError,
    StateRequest,
    StateTelemetry,
    VelocityCommand,
    crc16_ccitt,
    decode_message,
    encode_frame,
)


def _telemetry(**kw) -> StateTelemetry:
    base = dict(
        state=FirmwareState.CRS_CONTROL,
        positions=(1, -2, 2**31 - 1, -(2**31)),
        velocities=(100, -100, 0, 5),
        limit_switches=(True, False, False, True, False, True, False, False),
        watchdog_tripped=True,
        buttons_pressed=False,
        ack_seq=9,
    )
    base.update(kw)
    return StateTelemetry(**base)


def test_crc_is_ccitt_false() -> None:
    assert crc16_ccitt(b"123456789") == 0x29B1


def test_frame_layout_byte_by_byte() -> None:
    frame = VelocityCommand((1, -1, 256, 0)).encode(seq=7)
    assert frame[:2] == SYNC
    assert frame[2] == MsgType.VELOCITY_COMMAND
    assert frame[3] == 7
    assert frame[4] == 16
    assert frame[5:21] == struct.pack("<4i", 1, -1, 256, 0)
    assert frame[21:] == struct.pack(">H", crc16_ccitt(frame[2:21]))
    assert len(frame) == 23


@pytest.mark.parametrize(
    "message",
    [
        VelocityCommand((0, 1, -1, 2**31 - 1)),
        ModeRequest(2),
        StateRequest(),
        ModeReply(2, ModeResult.REFUSED_BUTTON_PRESSED, FirmwareState.HARDWARE_CONTROL),
        _telemetry(),
        _telemetry(watchdog_tripped=False, buttons_pressed=True, limit_switches=(False,) * 8),
    ],
)
def test_messages_round_trip(message) -> None:
    frames = FrameDecoder().feed(message.encode(seq=200))
    assert len(frames) == 1
    assert frames[0].seq == 200
    assert decode_message(frames[0]) == message


def test_bad_values_are_refused() -> None:
    with pytest.raises(ProtocolError, match="int32"):
        VelocityCommand((2**31, 0, 0, 0))
    with pytest.raises(ProtocolError, match="expected 4"):
        VelocityCommand((1, 2, 3))
    with pytest.raises(ProtocolError, match="exceeds the maximum"):
        encode_frame(MsgType.STATE, 0, bytes(MAX_PAYLOAD + 1))
    with pytest.raises(ProtocolError, match="unknown message type 0x7F"):
        decode_message(Frame(0x7F, 0, b""))
    with pytest.raises(ProtocolError, match="must be 16 bytes"):
        decode_message(Frame(MsgType.VELOCITY_COMMAND, 0, b"\x00" * 15))
    with pytest.raises(ProtocolError, match="not a FirmwareState"):
        decode_message(Frame(MsgType.MODE_REPLY, 0, bytes((1, 0, 9))))


def test_split_across_reads_byte_by_byte() -> None:
    data = _telemetry().encode(1) + ModeRequest(3).encode(2)
    decoder = FrameDecoder()
    frames = []
    for b in data:
        frames += decoder.feed(bytes([b]))
    assert [f.seq for f in frames] == [1, 2]
    assert decoder.stats.bytes_discarded == 0


def test_garbage_before_and_between_frames_is_skipped() -> None:
    good = ModeRequest(1).encode(5)
    decoder = FrameDecoder()
    frames = decoder.feed(b"\x00\xff\xa5garbage\xa5" + good + b"\x5a\x5a\x01" + good)
    assert [decode_message(f) for f in frames] == [ModeRequest(1), ModeRequest(1)]
    assert decoder.stats.bytes_discarded > 0
    assert decoder.stats.crc_errors == 0


def test_corrupted_frame_is_counted_and_the_next_one_decodes() -> None:
    bad = bytearray(_telemetry().encode(1))
    bad[10] ^= 0x40
    decoder = FrameDecoder()
    frames = decoder.feed(bytes(bad) + StateRequest().encode(2))
    assert [f.seq for f in frames] == [2]
    assert decoder.stats.crc_errors == 1


def test_truncated_frame_followed_by_a_whole_one_resyncs() -> None:
    # a frame cut short (link glitch): its length field swallows the next frame's bytes, so the
    # CRC fails and the decoder must find the real frame inside what it had taken as payload
    cut = _telemetry().encode(1)[:12]
    good = VelocityCommand((5, 6, 7, 8)).encode(3)
    decoder = FrameDecoder()
    frames = decoder.feed(cut + good + good)
    assert [f.seq for f in frames][-2:] == [3, 3]
    assert decoder.stats.crc_errors >= 1


def test_impossible_length_is_dropped() -> None:
    decoder = FrameDecoder()
    frames = decoder.feed(SYNC + bytes((0x81, 0, 200)) + StateRequest().encode(4))
    assert [f.seq for f in frames] == [4]
    assert decoder.stats.bad_lengths == 1


@settings(max_examples=100, deadline=None)
@given(
    garbage=st.lists(st.binary(max_size=40), min_size=3, max_size=3),
    velocities=st.lists(st.integers(-(2**31), 2**31 - 1), min_size=4, max_size=4),
    cuts=st.lists(st.integers(1, 30), max_size=5),
)
def test_any_garbage_between_frames_never_loses_a_clean_frame(garbage, velocities, cuts) -> None:
    """Property: frames separated by arbitrary bytes all come out, however the stream is split.

    Garbage may contain a sync pattern and a plausible header, so it can swallow bytes of the
    following frame only if its CRC also matches, which CRC-16 makes a 1-in-65536 event; the
    property holds for every frame whose preceding garbage does not end in a partial sync."""
    msg = VelocityCommand(tuple(velocities))
    frames_bytes = [msg.encode(seq) for seq in (10, 11, 12)]
    # a sync byte right before a frame starts a false frame that eats it; separate with 0x00
    stream = b"".join(g + b"\x00" * (MAX_PAYLOAD + 8) + f for g, f in zip(garbage, frames_bytes, strict=True))
    decoder = FrameDecoder()
    out: list[Frame] = []
    pos = 0
    for cut in cuts:
        out += decoder.feed(stream[pos : pos + cut])
        pos += cut
    out += decoder.feed(stream[pos:])
    decoded = [(f.seq, decode_message(f)) for f in out if f.type == MsgType.VELOCITY_COMMAND and f.seq >= 10]
    assert decoded == [(10, msg), (11, msg), (12, msg)]


def test_documented_example_frame() -> None:
    """The example in docs/lifter-protocol.md, byte for byte."""
    expected = bytes.fromhex("A55A010710 01000000 FFFFFFFF 00010000 00000000 F62F")
    assert VelocityCommand((1, -1, 256, 0)).encode(7) == expected
