"""Keys, MAC verification and the persisted anti-replay state."""

from __future__ import annotations

import json
import os

import pytest

from tlt_common.ccsds.auth import (
    CommandSequencer,
    KeyFileError,
    KeyRing,
    ReplayGuard,
    ReplayStateError,
    compute_mac,
    verify_mac,
    write_key_file,
)
from tlt_common.ccsds.codec import encode_command, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason

DEFS = load_definitions()


def test_key_file_round_trip_and_env(tmp_path, monkeypatch):
    keys = {1: os.urandom(32), 300: os.urandom(16)}
    path = write_key_file(tmp_path / "keys", keys)
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    ring = KeyRing.load(path)
    assert ring.key_ids == [1, 300] and ring.get(300) == keys[300] and ring.get(2) is None
    monkeypatch.setenv("TLT_GROUND_KEY_FILE", str(path))
    assert KeyRing.load().get(1) == keys[1]


@pytest.mark.parametrize(
    ("content", "mode", "words"),
    [
        ("1 00112233445566778899aabbccddeeff\n", 0o644, "chmod 600"),
        ("1 0011\n", 0o600, "at least 16"),
        ("1 zz\n", 0o600, "line 1"),
        ("# only a comment\n", 0o600, "no keys"),
        ("1 00112233445566778899aabbccddeeff\n1 00112233445566778899aabbccddeeff\n", 0o600, "twice"),
    ],
)
def test_bad_key_files_are_refused_clearly(tmp_path, content, mode, words):
    path = tmp_path / "keys"
    path.write_text(content)
    path.chmod(mode)
    with pytest.raises(KeyFileError, match=words):
        KeyRing.load(path)


def test_missing_key_file(tmp_path, monkeypatch):
    monkeypatch.delenv("TLT_GROUND_KEY_FILE", raising=False)
    with pytest.raises(KeyFileError, match="no key file"):
        KeyRing.load()
    with pytest.raises(KeyFileError, match="cannot read"):
        KeyRing.load(tmp_path / "nope")


def test_mac_detects_any_change():
    key = os.urandom(32)
    data = b"header and payload"
    mac = compute_mac(key, data)
    assert len(mac) == 32 and verify_mac(key, data, mac)
    assert not verify_mac(key, data + b"!", mac)
    assert not verify_mac(os.urandom(32), data, mac)
    assert not verify_mac(key, data, mac[:-1] + bytes([mac[-1] ^ 1]))


def test_replay_guard_persists_atomically(tmp_path):
    state = tmp_path / "state" / "replay.json"
    guard = ReplayGuard(state)
    assert guard.is_fresh(1, 0)
    assert guard.accept(1, 10)
    assert not guard.accept(1, 10) and not guard.accept(1, 9)
    assert guard.accept(2, 1)  # independent per key
    assert json.loads(state.read_text())["last_accepted"] == {"1": 10, "2": 1}
    assert [p.name for p in state.parent.iterdir()] == ["replay.json"]  # no temporary file left
    again = ReplayGuard(state)
    assert again.last(1) == 10 and not again.is_fresh(1, 10) and again.is_fresh(1, 11)


def test_corrupt_replay_state_refuses_to_start(tmp_path):
    state = tmp_path / "replay.json"
    state.write_text("{not json")
    with pytest.raises(ReplayStateError, match="refusing to start"):
        ReplayGuard(state)


def test_replayed_command_is_refused_after_restart(tmp_path):
    key = os.urandom(32)
    ring = KeyRing({1: key})
    raw = encode_command(DEFS, "start", key_id=1, key=key, security_seq=500, seq_count=0)
    older = encode_command(DEFS, "pause", key_id=1, key=key, security_seq=499, seq_count=1)
    first = ReplayGuard(tmp_path / "r.json")
    assert parse_datagram(raw, DEFS, expect="tc", keyring=ring, replay=first).ok
    assert parse_datagram(raw, DEFS, expect="tc", keyring=ring, replay=first).reason is Reason.REPLAY
    restarted = ReplayGuard(tmp_path / "r.json")
    for datagram in (raw, older):
        result = parse_datagram(datagram, DEFS, expect="tc", keyring=ring, replay=restarted)
        assert result.reason is Reason.REPLAY
    # a forged datagram never advances the state
    forged = encode_command(DEFS, "start", key_id=1, key=os.urandom(32), security_seq=10**15, seq_count=2)
    assert parse_datagram(forged, DEFS, expect="tc", keyring=ring, replay=restarted).reason is Reason.BAD_AUTH
    assert restarted.last(1) == 500


def test_command_sequencer_increases_across_restarts(tmp_path):
    first = CommandSequencer(tmp_path / "seq.json")
    numbers = [first.next() for _ in range(50)]
    assert numbers == sorted(set(numbers))
    second = CommandSequencer(tmp_path / "seq.json")
    assert second.next() > numbers[-1]
    (tmp_path / "bad.json").write_text("[]")
    with pytest.raises(ReplayStateError):
        CommandSequencer(tmp_path / "bad.json")
