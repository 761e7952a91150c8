"""Packet codec: round trip of every packet kind, header and trailer bytes, and every rejection."""

from __future__ import annotations

import os
import struct

import pytest
from spacepackets.ccsds import PacketType, SpacePacketHeader
from spacepackets.ccsds.time import CdsShortTimestamp

from tlt_common.ccsds.auth import KeyRing, ReplayStateError
from tlt_common.ccsds.codec import (
    Packet,
    Rejection,
    crc16_ccitt_false,
    encode_command,
    encode_telemetry,
    parse_datagram,
)
from tlt_common.ccsds.definitions import INTEGER_TYPES, FieldDef, load_definitions
from tlt_common.ccsds.fields import FieldError
from tlt_common.ccsds.reasons import Reason

DEFS = load_definitions()
KEY = os.urandom(32)
RING = KeyRing({7: KEY})
T0 = 1_795_000_000.25


def sample(fd: FieldDef, i: int):
    if fd.type in INTEGER_TYPES:
        lo, hi = INTEGER_TYPES[fd.type]
        return (hi - i) if i % 2 else max(lo, 3 - i)
    if fd.type in ("f32", "f64"):
        return 0.5 + i
    if fd.type == "bool":
        return i % 2 == 0
    if fd.type == "enum":
        return fd.enum[i % len(fd.enum)]
    if fd.type == "string":
        return f"text-{fd.name}-é"[: fd.max_length]
    if fd.type == "bytes":
        return bytes(range(i, i + 10))
    raise AssertionError(fd.type)


@pytest.mark.parametrize("kind", list(DEFS.telemetry))
def test_every_telemetry_kind_round_trips(kind):
    pdef = DEFS.packet(kind)
    values = {fd.name: sample(fd, i) for i, fd in enumerate(pdef.fields)}
    raw = encode_telemetry(DEFS, kind, values, seq_count=16383, timestamp=T0)
    packet = parse_datagram(raw, DEFS, expect="tm")
    assert isinstance(packet, Packet), packet
    assert (packet.kind, packet.apid, packet.packet_type, packet.seq_count) == (kind, pdef.apid, "tm", 16383)
    assert packet.time == pytest.approx(T0, abs=1e-3)
    assert packet.fields == pytest.approx(values)


COMMAND_PARAMS = {
    "start": {},
    "stop": {},
    "pause": {},
    "resume": {},
    "set_blackboard_value": [
        {"key": "mission.bay_override", "value": True},
        {"key": "speed", "value": -(2**63)},
        {"key": "gain", "value": 0.125},
        {"key": "note", "value": "résumé"},
    ],
    "set_actuator_state": [
        {"actuator": "lifter", "state": "safe"},
        {"actuator": "camera_mounts", "state": "move", "value": 0.3},
    ],
}
CASES = [(n, p) for n, ps in COMMAND_PARAMS.items() for p in (ps if isinstance(ps, list) else [ps])]


@pytest.mark.parametrize(("name", "params"), CASES)
def test_every_command_round_trips(name, params):
    raw = encode_command(
        DEFS, name, params, key_id=7, key=KEY, security_seq=2**64 - 1, seq_count=5, timestamp=T0
    )
    packet = parse_datagram(raw, DEFS, expect="tc", keyring=RING)
    assert isinstance(packet, Packet), packet
    expected = dict(params)
    if name == "set_actuator_state":
        expected.setdefault("value", None)
    assert dict(packet.fields) == expected
    assert (packet.kind, packet.command_id, packet.key_id, packet.security_seq, packet.seq_count) == (
        name,
        DEFS.commands[name].id,
        7,
        2**64 - 1,
        5,
    )


def test_header_layout_follows_ccsds_133():
    raw = encode_command(DEFS, "start", key_id=7, key=KEY, security_seq=1, seq_count=42, timestamp=T0)
    header = SpacePacketHeader.unpack(raw)
    assert header.ccsds_version == 0
    assert header.packet_type == PacketType.TC
    assert header.sec_header_flag
    assert header.apid == DEFS.command_apid
    assert header.seq_count == 42
    assert header.packet_len == len(raw)
    stamp = CdsShortTimestamp.unpack(raw[6:13])
    assert stamp.as_unix_seconds() == pytest.approx(T0, abs=1e-3)
    # security header, command id, 32-byte MAC, CRC
    assert struct.unpack(">HQ", raw[13:23]) == (7, 1)
    assert raw[23] == 1
    assert len(raw) == 6 + 7 + 10 + 1 + 32 + 2
    assert struct.unpack(">H", raw[-2:])[0] == crc16_ccitt_false(raw[:-2])
    tm = encode_telemetry(
        DEFS,
        "tree_status",
        {
            "agent": "crs",
            "shape_hash": 1,
            "tick": 2,
            "node_count": 3,
            "part_index": 0,
            "part_count": 1,
            "first_node": 0,
            "status": b"\x1b",
        },
        seq_count=0,
    )
    assert SpacePacketHeader.unpack(tm).packet_type == PacketType.TM


def test_crc_is_ccitt_false():
    assert crc16_ccitt_false(b"123456789") == 0x29B1


def _resign_crc(raw: bytes) -> bytes:
    return raw[:-2] + struct.pack(">H", crc16_ccitt_false(raw[:-2]))


def _lifter(**override):
    values = {
        "state": "safe",
        "position_0": 0.1,
        "position_1": 0.1,
        "position_2": 0.1,
        "position_3": 0.1,
        "velocity": 0,
        "limit_switches": 0,
        "watchdog_tripped": False,
        "link_ok": True,
    }
    values.update(override)
    return encode_telemetry(DEFS, "hk_lifter", values, seq_count=1)


def test_telemetry_rejections_have_reasons():
    good = _lifter()
    cases = {
        Reason.OVERSIZED: good + bytes(DEFS.max_packet_bytes),
        Reason.TRUNCATED: good[:10],
        Reason.BAD_CRC: good[:-1] + bytes([good[-1] ^ 1]),
        Reason.MALFORMED: good + b"\x00",
        Reason.UNKNOWN_APID: _resign_crc(bytes([good[0] & 0xF8, 0x7E]) + good[2:]),
        Reason.WRONG_PACKET_TYPE: encode_command(
            DEFS, "start", key_id=7, key=KEY, security_seq=1, seq_count=0
        ),
        Reason.BAD_VERSION: _resign_crc(bytes([good[0] | 0x20]) + good[1:]),
    }
    for reason, raw in cases.items():
        result = parse_datagram(raw, DEFS, expect="tm")
        assert isinstance(result, Rejection) and result.reason is reason, (reason, result)
    # header says the packet is longer than the datagram
    truncated = good[:-4]
    assert parse_datagram(truncated, DEFS).reason is Reason.TRUNCATED
    # enum index outside the list, with a valid CRC
    bad_enum = _resign_crc(good[:13] + b"\x09" + good[14:])
    assert parse_datagram(bad_enum, DEFS).reason is Reason.BAD_PARAMETER_RANGE
    # the time code's P-field is not CDS
    bad_time = _resign_crc(good[:6] + b"\x10" + good[7:])
    assert parse_datagram(bad_time, DEFS).reason is Reason.MALFORMED
    # secondary-header flag cleared
    no_sec = _resign_crc(bytes([good[0] & ~0x08]) + good[1:])
    assert parse_datagram(no_sec, DEFS).reason is Reason.MALFORMED


def _command(name="start", params=None, **kw):
    args = {"key_id": 7, "key": KEY, "security_seq": 10, "seq_count": 0}
    args.update(kw)
    return encode_command(DEFS, name, params or {}, **args)


def test_command_rejections_have_reasons():
    assert parse_datagram(_command(key_id=8), DEFS, expect="tc", keyring=RING).reason is Reason.UNKNOWN_KEY
    wrong_key = _command(key=os.urandom(32))
    assert parse_datagram(wrong_key, DEFS, expect="tc", keyring=RING).reason is Reason.BAD_AUTH
    assert parse_datagram(_lifter(), DEFS, expect="tc", keyring=RING).reason is Reason.WRONG_PACKET_TYPE
    short = _resign_crc(_command()[:20] + b"\x00\x00")
    fixed_len = bytearray(short)
    struct.pack_into(">H", fixed_len, 4, len(short) - 7)
    assert (
        parse_datagram(_resign_crc(bytes(fixed_len)), DEFS, expect="tc", keyring=RING).reason
        is Reason.TRUNCATED
    )
    # any changed byte under the MAC fails authentication even with a fixed-up CRC
    raw = bytearray(_command("set_blackboard_value", {"key": "a", "value": 1}))
    raw[25] ^= 0x01
    assert parse_datagram(_resign_crc(bytes(raw)), DEFS, expect="tc", keyring=RING).reason is Reason.BAD_AUTH


@pytest.mark.parametrize(
    ("name", "params", "reason"),
    [
        ("set_actuator_state", {"actuator": "lifter", "state": "fly"}, Reason.BAD_PARAMETER_RANGE),
        ("set_actuator_state", {"actuator": "warp_drive", "state": "on"}, Reason.BAD_PARAMETER_RANGE),
        (
            "set_actuator_state",
            {"actuator": "lifter", "state": "safe", "value": 9.0},
            Reason.BAD_PARAMETER_RANGE,
        ),
        (
            "set_actuator_state",
            {"actuator": "top_grippers", "state": "engage", "value": 0.0},
            Reason.BAD_PARAMETER_RANGE,
        ),
        (
            "set_actuator_state",
            {"actuator": "lifter", "state": "safe", "value": float("nan")},
            Reason.BAD_PARAMETER_RANGE,
        ),
        # the table's value states: move needs its value, the other states of the mounts take none
        ("set_actuator_state", {"actuator": "camera_mounts", "state": "move"}, Reason.BAD_PARAMETER_RANGE),
        (
            "set_actuator_state",
            {"actuator": "camera_mounts", "state": "stow", "value": 0.2},
            Reason.BAD_PARAMETER_RANGE,
        ),
        (
            "set_actuator_state",
            {"actuator": "camera_mounts", "state": "move", "value": 4.0},
            Reason.BAD_PARAMETER_RANGE,
        ),
        ("set_blackboard_value", {"key": "9 not a key", "value": 1}, Reason.BAD_PARAMETER_RANGE),
        ("set_blackboard_value", {"key": "k", "value": float("inf")}, Reason.BAD_PARAMETER_RANGE),
    ],
)
def test_bad_parameters_are_refused_at_both_ends(name, params, reason):
    with pytest.raises(FieldError) as info:
        _command(name, params)
    assert info.value.reason is reason
    raw = _command(name, params, check=False)
    result = parse_datagram(raw, DEFS, expect="tc", keyring=RING)
    assert isinstance(result, Rejection) and result.reason is reason and result.authenticated


def test_wrong_parameter_type_on_the_wire_is_refused():
    raw = bytearray(_command("set_blackboard_value", {"key": "k", "value": True}, check=False))
    tag_at = 6 + 7 + 10 + 1 + 1 + 1  # after key length byte and the 1-byte key
    raw[tag_at] = 9
    body = bytes(raw[: -2 - 32])
    from tlt_common.ccsds.auth import compute_mac

    resigned = _resign_crc(body + compute_mac(KEY, body) + b"\x00\x00")
    result = parse_datagram(resigned, DEFS, expect="tc", keyring=RING)
    assert result.reason is Reason.BAD_PARAMETER_TYPE


def test_encoder_refuses_wrong_types_and_sizes():
    with pytest.raises(FieldError, match="expected a number"):
        _lifter(position_0="x")
    with pytest.raises(FieldError, match="unknown field"):
        _lifter(colour="red")
    with pytest.raises(FieldError, match="does not fit"):
        _lifter(limit_switches=256)
    with pytest.raises(KeyError, match="unknown command"):
        _command("self_destruct")
    with pytest.raises(FieldError, match="longer than"):
        encode_telemetry(
            DEFS,
            "tree_status",
            {
                "agent": "crs",
                "shape_hash": 1,
                "tick": 2,
                "node_count": 3,
                "part_index": 0,
                "part_count": 1,
                "first_node": 0,
                "status": bytes(2000),
            },
            seq_count=0,
        )


def test_parser_survives_non_bytes_and_a_failing_replay_store(tmp_path):
    assert parse_datagram(None, DEFS).reason is Reason.MALFORMED
    assert parse_datagram(12, DEFS).reason is Reason.MALFORMED
    assert parse_datagram(memoryview(_lifter()), DEFS).ok

    class BrokenStore:
        def accept(self, key_id, seq):
            raise ReplayStateError("disk gone")

        def last(self, key_id):
            return None

    result = parse_datagram(_command(), DEFS, expect="tc", keyring=RING, replay=BrokenStore())
    assert result.reason is Reason.INTERNAL_ERROR and "disk gone" in result.detail
