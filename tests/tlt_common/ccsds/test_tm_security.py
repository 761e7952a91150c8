"""Telemetry authentication: key file lines, signing, the replay window, gaps and key retirement."""

from __future__ import annotations

import os

import pytest

from tlt_common.ccsds.auth import KeyFileError, KeyRing, write_key_file
from tlt_common.ccsds.codec import Packet, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.fields import FieldError
from tlt_common.ccsds.reasons import Reason
from tlt_common.ccsds.tm_security import REPLAY_WINDOW, RESYNC_JUMP, TelemetrySigner, TelemetryVerifier

DEFS = load_definitions()
TOWER = {"member_count": 3, "member_states": b"ab"}


def test_key_file_keeps_command_and_telemetry_keys_apart(tmp_path):
    keys, tm_keys = {1: os.urandom(32)}, {1: os.urandom(32), 2: os.urandom(32)}
    ring = KeyRing.load(write_key_file(tmp_path / "k", keys, tm_keys))
    assert ring.key_ids == [1] and ring.get(1) == keys[1]
    assert ring.telemetry.key_ids == [1, 2] and ring.telemetry.get(2) == tm_keys[2]
    assert KeyRing.load(write_key_file(tmp_path / "old", keys)).telemetry.key_ids == []
    with pytest.raises(KeyFileError, match="no telemetry keys"):
        TelemetrySigner(KeyRing(keys).telemetry, 1)
    with pytest.raises(KeyFileError, match="not in the key file"):
        TelemetrySigner(ring.telemetry, 5)


def test_signed_telemetry_round_trips_and_the_unsigned_form_is_refused():
    ring = KeyRing({1: os.urandom(32)}, {4: os.urandom(32)})
    signer = TelemetrySigner(ring.telemetry, 4, base=1000)
    raw = signer.encode(DEFS, "hk_tower", TOWER, seq_count=9, timestamp=1.8e9)
    packet = parse_datagram(raw, DEFS, keyring=ring.telemetry)
    assert isinstance(packet, Packet)
    assert (packet.kind, packet.key_id, packet.security_seq, dict(packet.fields)) == (
        "hk_tower",
        4,
        1000,
        TOWER,
    )
    plain = encode_telemetry(DEFS, "hk_tower", TOWER, seq_count=9, timestamp=1.8e9)
    assert parse_datagram(plain, DEFS).ok  # the offline form, read without keys
    assert not parse_datagram(plain, DEFS, keyring=ring.telemetry).ok
    # A command key never verifies telemetry, even under the same key id.
    assert parse_datagram(raw, DEFS, keyring=KeyRing({4: ring.get(1) or b""})).reason is Reason.BAD_AUTH


def test_bad_values_use_no_sequence_number():
    signer = TelemetrySigner(KeyRing({1: os.urandom(32)}, {1: os.urandom(32)}).telemetry, 1, base=50)
    with pytest.raises(FieldError):
        signer.encode(DEFS, "hk_tower", {"member_count": -1, "member_states": b""}, seq_count=0)
    raw = signer.encode(DEFS, "hk_tower", TOWER, seq_count=0)
    assert parse_datagram(raw, DEFS, keyring=signer.keyring).security_seq == 50


def test_replay_window_accepts_late_packets_once_and_counts_gaps():
    verifier = TelemetryVerifier(KeyRing({1: os.urandom(32)}))
    assert verifier.accept(1, 100) and not verifier.accept(1, 100)
    assert verifier.accept(1, 104)  # 101..103 missing: one gap of three
    assert (verifier.gaps, verifier.missing) == (1, 3)
    assert verifier.accept(1, 102) and not verifier.accept(1, 102)  # late once, then a replay
    assert (verifier.late, verifier.missing) == (1, 2)
    assert verifier.accept(1, 104 + REPLAY_WINDOW)
    assert not verifier.accept(1, 103)  # fell out of the window: refused, never taken as new
    assert verifier.accept(1, 104 + REPLAY_WINDOW + RESYNC_JUMP + 1)  # a restarted CRS
    assert (verifier.resyncs, verifier.gaps) == (1, 2)
    assert verifier.accept(2, 5) and verifier.last(2) == 5 and verifier.last(1) != 5  # per key id


def test_an_older_key_is_retired_after_the_overlap():
    now = [0.0]
    ring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32), 2: os.urandom(32)})
    verifier = TelemetryVerifier(ring.telemetry, overlap_s=5.0, clock=lambda: now[0])
    assert verifier.accept(1, 10) and verifier.get(1) is not None
    now[0] = 100.0
    assert verifier.accept(2, 11)  # the CRS switched: key 1 has five more seconds
    now[0] = 104.0
    assert verifier.get(1) is not None and not verifier.retired(1)
    now[0] = 105.0
    assert verifier.get(1) is None and verifier.retired(1) and verifier.get(2) is not None
