"""GswLink receiving: a quiet poll still commits the archive; a larger socket buffer on request."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.link import GswLink

DEFS = load_definitions()


def test_a_quiet_poll_commits_what_was_buffered(tmp_path):
    recorder = Recorder(tmp_path / "a.sqlite", flush_interval_s=0.2)
    keyring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
    with GswLink(DEFS, keyring, 1, ("127.0.0.1", 9), recorder=recorder, close_recorder=True) as link:
        raw = TelemetrySigner(keyring.telemetry, 1).encode(DEFS, "event", {
            "severity": "info", "source": "t", "code": "C", "reason": "none", "text": "x",
        }, seq_count=0)  # fmt: skip
        link._sock.sendto(raw, link.address)
        deadline = time.monotonic() + 5
        while not link.poll(0.05) and time.monotonic() < deadline:
            pass
        assert recorder.pending == 1 and recorder.committed == 0  # younger than the flush interval
        time.sleep(0.25)
        assert link.poll(0.01) == []  # nothing arrives, yet the buffered packet is committed
        assert recorder.pending == 0 and recorder.committed == 1


def test_a_larger_receive_buffer_is_requested():
    keyring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
    wanted = 1 << 20
    cap = (
        int(Path("/proc/sys/net/core/rmem_max").read_text())
        if Path("/proc/sys/net/core/rmem_max").exists()
        else wanted
    )
    with GswLink(DEFS, keyring, 1, ("127.0.0.1", 9)) as plain:
        default = plain._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    with GswLink(DEFS, keyring, 1, ("127.0.0.1", 9), recv_buffer_bytes=wanted) as big:
        got = big._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    assert got >= min(wanted, cap) and (got > default or cap <= default)
