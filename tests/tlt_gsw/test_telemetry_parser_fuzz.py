"""Property-based fuzz of the GSW's telemetry receive path: no byte string is accepted unless the
CRS signed it, and none reaches the parser's last-resort ``internal_error`` or raises.

Each datagram goes through :meth:`GswLink._handle`, what :meth:`GswLink.poll` does with every
datagram it reads (source check, authentication with the telemetry keys and replay window, field
decoding, statistics), without the socket in between so thousands of cases run in seconds.
"""

from __future__ import annotations

import itertools
import os
import random
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tlt_common.ccsds.auth import KeyRing, compute_mac
from tlt_common.ccsds.codec import Packet, Rejection, crc16_ccitt_false
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_gsw.link import GswLink

DEFS = load_definitions()
TM_KEY = os.urandom(32)
RING = KeyRing({1: os.urandom(32)}, {1: TM_KEY})
CRS = ("127.0.0.1", 52001)
FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
STAMP = bytes([0x40, 0x5A, 0x00, 0x01, 0x00, 0x00, 0x00])
SEQUENCE = itertools.count(10**15)  # security sequence numbers above every capture's


@pytest.fixture(scope="module")
def gsw():
    """A GSW link that has accepted a few genuine packets already (so their replays are bad)."""
    link = GswLink(DEFS, RING, 1, ("127.0.0.1", 9))
    signer = TelemetrySigner(RING.telemetry, 1, base=1000)
    captures = [
        signer.encode(
            DEFS,
            "event",
            {
                "severity": "warning",
                "source": "crs",
                "code": "C",
                "reason": "refused",
                "text": "t" * n,
            },
            seq_count=n,
        )
        for n in range(3)
    ]
    captures.append(
        signer.encode(
            DEFS,
            "ack",
            {
                "command_apid": DEFS.command_apid,
                "command_seq_count": 3,
                "security_seq": 77,
                "command": "stop",
                "stage": "completed",
                "reason": "none",
                "detail": "",
            },
            seq_count=0,
        )
    )
    for raw in captures:
        assert isinstance(link._handle(raw, CRS), Packet)
    link.captures = captures
    yield link
    link.close()


def refused(link: GswLink, data: bytes) -> Rejection:
    accepted_before = link.stats.packets_rx - link.stats.rejections
    result = link._handle(data, CRS)
    assert isinstance(result, Rejection), result
    assert result.reason is not Reason.INTERNAL_ERROR, result
    assert link.stats.packets_rx - link.stats.rejections == accepted_before
    return result


def with_crc(body: bytes) -> bytes:
    return body + struct.pack(">H", crc16_ccitt_false(body))


@FUZZ
@given(blob=st.binary(max_size=3000))
def test_random_bytes_are_refused_for_a_reason(gsw, blob):
    refused(gsw, blob)


@FUZZ
@given(data=st.data())
def test_altered_genuine_telemetry_is_never_accepted(gsw, data):
    raw = bytearray(data.draw(st.sampled_from(gsw.captures)))
    flips = data.draw(st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(1, 255)), max_size=6))
    for index, mask in flips:
        raw[index] ^= mask
    if data.draw(st.booleans()):
        raw = raw[: data.draw(st.integers(0, len(raw)))] + data.draw(st.binary(max_size=8))
    if data.draw(st.booleans()):  # the forger recomputes the CRC
        raw = bytearray(with_crc(bytes(raw[:-2]))) if len(raw) >= 2 else raw
    refused(gsw, bytes(raw))  # unaltered, it is a replay


@FUZZ
@given(
    type_bit=st.booleans(),
    apid=st.one_of(st.sampled_from(sorted(DEFS.telemetry_by_apid)), st.integers(0, 0x7FF)),
    flags=st.integers(0, 3),
    key_id=st.one_of(st.just(1), st.integers(0, 0xFFFF)),
    seq=st.integers(0, 2**64 - 1),
    body=st.binary(max_size=300),
)
def test_well_formed_headers_over_random_bodies_are_refused(gsw, type_bit, apid, flags, key_id, seq, body):
    user = struct.pack(">HQ", key_id, seq) + body
    header = struct.pack(
        ">HHH", (type_bit << 12) | (1 << 11) | apid, (flags << 14) | 1, 6 + 7 + len(user) + 2 - 7
    )
    refused(gsw, with_crc(header + STAMP + user))


@FUZZ
@given(apid=st.sampled_from(sorted(DEFS.telemetry_by_apid)), body=st.binary(max_size=400))
def test_fields_of_any_bytes_signed_with_the_key_never_reach_internal_error(gsw, apid, body):
    """Even a sender holding the telemetry key cannot crash the field decoder."""
    user = struct.pack(">HQ", 1, next(SEQUENCE)) + body
    header = struct.pack(">HHH", (1 << 11) | apid, (3 << 14) | 5, 6 + 7 + len(user) + DEFS.mac_bytes + 2 - 7)
    signed = header + STAMP + user
    result = gsw._handle(with_crc(signed + compute_mac(TM_KEY, signed, DEFS.mac_bytes)), CRS)
    if isinstance(result, Packet):
        assert result.kind == DEFS.telemetry_by_apid[apid].name
        assert set(result.fields) == {f.name for f in DEFS.telemetry_by_apid[apid].fields}
    else:
        assert result.reason in (Reason.MALFORMED, Reason.TRUNCATED, Reason.BAD_PARAMETER_TYPE,
                                 Reason.BAD_PARAMETER_RANGE), result  # fmt: skip


def test_many_thousands_of_seeded_mutations_are_refused(gsw):
    """A seeded random fuzz beside hypothesis's: 20,000 mutations of genuine telemetry."""
    rng = random.Random(66)
    for _ in range(20_000):
        raw = bytearray(rng.choice(gsw.captures))
        for _ in range(rng.randrange(1, 4)):
            raw[rng.randrange(len(raw))] ^= rng.randrange(1, 256)
        action = rng.randrange(4)
        if action == 1:
            raw = raw[: rng.randrange(len(raw))]
        elif action == 2:
            raw += rng.randbytes(rng.randrange(1, 40))
        if action == 3 or rng.random() < 0.5:
            raw = bytearray(with_crc(bytes(raw[:-2]))) if len(raw) >= 2 else raw
        refused(gsw, bytes(raw))
