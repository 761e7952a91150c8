"""Property-based fuzz of the CRS packet parser: it never raises and never acts on a bad packet.

Beyond "never raises", no input may reach the parser's last-resort INTERNAL_ERROR branch: every
bad datagram must be classified by a specific check.
"""

from __future__ import annotations

import os
import random
import socket
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from spacepackets.ccsds import SpacePacketHeader

from tlt_common.ccsds.auth import KeyRing, compute_mac
from tlt_common.ccsds.codec import Packet, Rejection, crc16_ccitt_false, encode_command, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason
from tlt_crs.ground_link import GroundLink

DEFS = load_definitions()
KEY = os.urandom(32)
RING = KeyRing({1: KEY}, {1: bytes(range(32))})
FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

VALID = [
    ("start", {}),
    ("stop", {}),
    ("pause", {}),
    ("resume", {}),
    ("set_blackboard_value", {"key": "speed", "value": 0.5}),
    ("set_blackboard_value", {"key": "note", "value": "hello"}),
    ("set_actuator_state", {"actuator": "camera_mounts", "state": "move", "value": 0.25}),
    ("set_actuator_state", {"actuator": "lifter", "state": "safe"}),
]


@pytest.fixture(scope="module")
def link(tmp_path_factory):
    """A ground link whose valid commands were all accepted once already (so replays too are bad)."""
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    acted: list = []
    crs = GroundLink(
        DEFS,
        RING,
        tmp_path_factory.mktemp("fuzz") / "replay.json",
        gsw_address=sink.getsockname(),
        on_command=acted.append,
        stats_period_s=0,
    )
    raws = []
    for seq, (name, params) in enumerate(VALID, start=1):
        raw = encode_command(DEFS, name, params, key_id=1, key=KEY, security_seq=seq, seq_count=seq)
        assert isinstance(crs.handle_datagram(raw), Packet)
        raws.append(raw)
    assert len(acted) == len(VALID)
    acted.clear()
    crs.valid_raws = raws
    crs.acted = acted
    yield crs
    crs.close()
    sink.close()


@FUZZ
@given(data=st.data())
def test_mutated_valid_commands_are_never_acted_on(link, data):
    raw = bytearray(data.draw(st.sampled_from(link.valid_raws)))
    flips = data.draw(st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(1, 255)), max_size=6))
    for index, mask in flips:
        raw[index] ^= mask
    cut = data.draw(st.integers(0, len(raw)))
    tail = data.draw(st.binary(max_size=8))
    mutated = bytes(raw[:cut]) + tail if data.draw(st.booleans()) else bytes(raw)
    result = link.handle_datagram(mutated)
    assert isinstance(result, Rejection) and result.reason is not Reason.INTERNAL_ERROR, result
    assert link.acted == []


@FUZZ
@given(blob=st.binary(max_size=3000))
def test_random_bytes_never_raise_and_never_act(link, blob):
    result = link.handle_datagram(blob)
    assert isinstance(result, Rejection) and result.reason is not Reason.INTERNAL_ERROR, result
    assert link.acted == []


def _with_crc(body: bytes) -> bytes:
    return body + struct.pack(">H", crc16_ccitt_false(body))


@FUZZ
@given(
    type_bit=st.booleans(),
    apid=st.integers(0, 0x7FF),
    flags=st.integers(0, 3),
    sec=st.booleans(),
    body=st.binary(max_size=200),
)
def test_well_formed_headers_with_random_bodies_never_act(link, type_bit, apid, flags, sec, body):
    length = 6 + len(body) + 2
    header = struct.pack(">HHH", (type_bit << 12) | (sec << 11) | apid, (flags << 14) | 1, max(0, length - 7))
    result = link.handle_datagram(_with_crc(header + body))
    assert isinstance(result, Rejection) and result.reason is not Reason.INTERNAL_ERROR, result
    assert link.acted == []


@FUZZ
@given(command_id=st.integers(0, 255), params=st.binary(max_size=120), seq=st.integers(10**6, 2**64 - 1))
def test_authenticated_random_parameters_never_raise(command_id, params, seq):
    """Even a sender holding the key cannot crash the parser with arbitrary parameter bytes."""
    user = struct.pack(">HQ", 1, seq) + bytes([command_id]) + params
    total = 6 + 7 + len(user) + 32 + 2
    header = struct.pack(">HHH", (1 << 12) | (1 << 11) | DEFS.command_apid, (3 << 14) | 9, total - 7)
    stamp = bytes([0x40, 0x5A, 0x00, 0x01, 0x00, 0x00, 0x00])
    signed = header + stamp + user
    result = parse_datagram(_with_crc(signed + compute_mac(KEY, signed)), DEFS, expect="tc", keyring=RING)
    assert isinstance(result, Packet) or result.reason is not Reason.INTERNAL_ERROR, result
    if isinstance(result, Packet):
        assert result.command_id == command_id and result.kind in DEFS.commands


@FUZZ
@given(apid=st.sampled_from(sorted(DEFS.telemetry_by_apid)), body=st.binary(max_size=300))
def test_gsw_telemetry_parser_never_raises(apid, body):
    header = struct.pack(">HHH", (1 << 11) | apid, (3 << 14) | 5, 6 + 7 + len(body) + 2 - 7)
    stamp = bytes([0x40, 0x5A, 0x00, 0x01, 0x00, 0x00, 0x00])
    raw = _with_crc(header + stamp + body)
    result = parse_datagram(raw, DEFS, expect="tm")
    assert isinstance(result, Packet) or result.reason is not Reason.INTERNAL_ERROR, result
    reference = SpacePacketHeader.unpack(raw)  # the parser's own header read agrees with spacepackets
    assert (result.apid, result.seq_count) == (reference.apid, reference.seq_count)


def test_many_thousands_of_seeded_mutations_are_never_acted_on(link):
    """A seeded random fuzz beside hypothesis's: 20,000 mutations of accepted commands, half of
    them with the CRC recomputed as a forger would, through the CRS's datagram handling."""
    rng = random.Random(66)
    for _ in range(20_000):
        raw = bytearray(rng.choice(link.valid_raws))
        for _ in range(rng.randrange(1, 4)):
            raw[rng.randrange(len(raw))] ^= rng.randrange(1, 256)
        action = rng.randrange(4)
        if action == 1:
            raw = raw[: rng.randrange(len(raw))]
        elif action == 2:
            raw += rng.randbytes(rng.randrange(1, 40))
        if (action == 3 or rng.random() < 0.5) and len(raw) >= 2:
            raw = bytearray(_with_crc(bytes(raw[:-2])))
        result = link.handle_datagram(bytes(raw), ("127.0.0.1", 4000))
        assert isinstance(result, Rejection) and result.reason is not Reason.INTERNAL_ERROR, result
    assert link.acted == []
