"""The GSW link: gap and CRC accounting on received telemetry, recording, ack timeouts."""

from __future__ import annotations

import os
import socket
import time

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_gsw.archive import Recorder
from tlt_gsw.archive import query as q
from tlt_gsw.link import GswLink

DEFS = load_definitions()
RING = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
SIGNER = TelemetrySigner(RING.telemetry, 1)


def tower(seq: int) -> bytes:
    return SIGNER.encode(DEFS, "hk_tower", {"member_count": seq, "member_states": b""}, seq_count=seq)


def drain(link: GswLink, expected: int, timeout: float = 5.0) -> list:
    got: list = []
    deadline = time.monotonic() + timeout
    while len(got) < expected and time.monotonic() < deadline:
        got += link.poll(0.05)
    return got


def test_gaps_crc_errors_and_recording(tmp_path):
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    recorder = Recorder(tmp_path / "a.sqlite")
    link = GswLink(DEFS, RING, 1, silent.getsockname(), recorder=recorder)
    try:
        sent = link.send_command("start")
        seqs = [16381, 16382, 1, 2, 6]  # 16383 and 0 lost across the wrap, then 3, 4, 5
        for seq in seqs:
            sender.sendto(tower(seq), link.address)
        corrupted = bytearray(tower(7))
        corrupted[-3] ^= 0x40
        sender.sendto(bytes(corrupted), link.address)
        results = drain(link, len(seqs) + 1)
        assert len(results) == len(seqs) + 1
        assert (link.stats.gaps, link.stats.missing, link.stats.crc_errors) == (2, 5, 1)
        assert link.wait_ack(sent, timeout=0.2) is None  # nobody answers: bounded wait, no ack
    finally:
        link.close()
        sender.close()
        silent.close()
    recorder.close()
    conn = q.open_archive(tmp_path / "a.sqlite")
    rows = q.packets(conn, limit=100, newest_first=False)
    assert [(r.direction, r.kind, r.status) for r in rows] == [("tx", "start", "ok")] + [
        ("rx", "hk_tower", "ok")
    ] * 5 + [("rx", None, "bad_crc")]
    assert q.packet_fields(conn, rows[0].id) == {}  # start has no parameters
    assert rows[0].raw == sent.raw


def test_a_restarted_gsw_refuses_telemetry_its_archive_already_holds(tmp_path):
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    captured = [tower(seq) for seq in range(3)]
    try:
        with GswLink(
            DEFS, RING, 1, silent.getsockname(), recorder=Recorder(tmp_path / "a.sqlite"), close_recorder=True
        ) as link:
            for raw in captured:
                sender.sendto(raw, link.address)
            assert [r.ok for r in drain(link, 3)] == [True] * 3
        # The GSW restarts on the same archive; someone replays the capture, then the CRS goes on.
        with GswLink(
            DEFS, RING, 1, silent.getsockname(), recorder=Recorder(tmp_path / "a.sqlite"), close_recorder=True
        ) as link:
            for raw in [*captured, tower(3)]:
                sender.sendto(raw, link.address)
            results = drain(link, 4)
    finally:
        sender.close()
        silent.close()
    assert [getattr(r, "reason", None) for r in results[:3]] == [Reason.REPLAY] * 3
    assert results[3].ok and results[3].fields["member_count"] == 3
