"""Protocol 2.0 framing against packets worked out by hand from the ROBOTIS e-manual examples."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from tlt_sim.emulators import dynamixel_protocol as proto

# (id, instruction, params, expected bytes): the e-manual's PING, READ and WRITE examples and the
# status packet answering the PING (model 1030, firmware 38).
KNOWN = [
    (1, proto.PING, b"", "ff ff fd 00 01 03 00 01 19 4e"),
    (1, proto.READ, bytes([0x84, 0x00, 0x04, 0x00]), "ff ff fd 00 01 07 00 02 84 00 04 00 1d 15"),
    (
        1,
        proto.WRITE,
        bytes([0x74, 0x00, 0x00, 0x02, 0x00, 0x00]),
        "ff ff fd 00 01 09 00 03 74 00 00 02 00 00 ca 89",
    ),
    (1, proto.STATUS, bytes([0x00, 0x06, 0x04, 0x26]), "ff ff fd 00 01 07 00 55 00 06 04 26 65 5d"),
]


@pytest.mark.parametrize(("dxl_id", "ins", "params", "expected"), KNOWN)
def test_build_matches_known_packets(dxl_id, ins, params, expected):
    assert proto.build_packet(dxl_id, ins, params) == bytes.fromhex(expected)


def test_crc_of_ping_example():
    assert proto.crc16(bytes.fromhex("ff ff fd 00 01 03 00 01")) == 0x4E19


def test_stuffing_inserts_fd_after_ff_ff_fd_and_length_counts_it():
    params = bytes([0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x00])
    packet = proto.build_packet(1, proto.WRITE, params)
    body = packet[7:-2]
    assert body == bytes([0x03, 0x74, 0x00, 0xFF, 0xFF, 0xFD, 0xFD, 0x00])
    assert packet[5] == len(body) + 2
    assert proto.crc16(packet[:-2]) == int.from_bytes(packet[-2:], "little")
    assert proto.unstuff(body) == bytes([0x03]) + params


def test_parser_round_trip_with_stuffing_noise_and_split_delivery():
    parser = proto.PacketParser()
    params = bytes([0xFF, 0xFF, 0xFD, 0x01, 0xFF, 0xFF, 0xFD])
    wire = b"\x00\x12" + proto.build_packet(7, proto.WRITE, params) + proto.build_packet(3, proto.PING)
    got = []
    for i in range(0, len(wire), 3):
        got += parser.feed(wire[i : i + 3])
    assert [(p.dxl_id, p.instruction, p.params, p.crc_ok) for p in got] == [
        (7, proto.WRITE, params, True),
        (3, proto.PING, b"", True),
    ]


def test_parser_flags_bad_crc():
    packet = bytearray(proto.build_packet(2, proto.PING))
    packet[-1] ^= 0xFF
    (got,) = proto.PacketParser().feed(bytes(packet))
    assert got.dxl_id == 2 and not got.crc_ok


@given(st.binary(max_size=64).map(lambda b: b + b"\xff\xff\xfd" if len(b) % 2 else b))
def test_stuffing_round_trip_and_no_header_inside(body):
    stuffed = proto.stuff(body)
    assert proto.unstuff(stuffed) == body
    # After stuffing, FF FF FD is always followed by FD, so no header can appear inside a packet.
    for i in range(len(stuffed) - 2):
        if stuffed[i : i + 3] == b"\xff\xff\xfd":
            assert stuffed[i + 3 : i + 4] == b"\xfd"


@given(st.integers(0, 252), st.integers(0, 255), st.binary(max_size=40))
def test_parser_recovers_any_packet(dxl_id, ins, params):
    (packet,) = proto.PacketParser().feed(proto.build_packet(dxl_id, ins, params))
    assert (packet.dxl_id, packet.instruction, packet.params, packet.crc_ok) == (dxl_id, ins, params, True)


@given(st.binary(min_size=1, max_size=80))
def test_crc_agrees_with_dynamixel_sdk(data):
    from dynamixel_sdk import PacketHandler

    assert proto.crc16(data) == PacketHandler(2.0).updateCRC(0, list(data), len(data))


def test_sdk_built_packet_with_stuffing_is_parsed():
    from dynamixel_sdk import PacketHandler

    ph = PacketHandler(2.0)
    params = [0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x00]
    tx = [0, 0, 0, 0, 5, len(params) + 3, 0, proto.WRITE, *params, 0, 0]
    # addStuffing returns a new list when it inserts bytes (the SDK's own txPacket drops that return value).
    tx = ph.addStuffing(tx)
    assert tx[5] == len(params) + 4  # one stuffing byte counted in the length
    length = tx[5] | tx[6] << 8
    tx[0:4] = [0xFF, 0xFF, 0xFD, 0x00]
    crc = ph.updateCRC(0, tx, length + 5)
    wire = bytes(tx[: length + 5]) + crc.to_bytes(2, "little")
    (packet,) = proto.PacketParser().feed(wire)
    assert packet.crc_ok and packet.params == bytes(params) and packet.dxl_id == 5
