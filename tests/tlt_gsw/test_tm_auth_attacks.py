"""Attacks on the telemetry downlink, against a real CRS process and a real GSW (`tlt gsw watch`).

The CRS process sends its telemetry through a tap owned by the test (an attacker on the link): the
tap captures every packet and forwards the chosen ones to the GSW process. The attacker then sends
the GSW a packet forged from the public definitions, a replayed capture, captured event and ack
packets altered with their CRC recomputed, and a capture relabelled with another key id. The GSW
must archive each as rejected with its reason (no decoded fields), count them, and still accept
the CRS's genuine telemetry afterwards.
"""

from __future__ import annotations

import os
import socket
import sqlite3
import struct
import subprocess
import sys
import textwrap
import time

import pytest
import yaml

from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.codec import CRC_LEN, crc16_ccitt_false, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_gsw.link import GswLink

DEFS = load_definitions()
SEC = 13  # the security header follows the primary header (6) and the CDS time (7)

CRS = textwrap.dedent(
    """
    import sys
    from tlt_common.ccsds.link_config import load_link_config
    from tlt_crs.ground_link import GroundLink

    def handle(command):
        link.complete(command, detail="done in the CRS process")

    link = GroundLink.from_config(load_link_config(sys.argv[1]), on_command=handle, stats_period_s=0)
    link.start()
    print(link.address[1], flush=True)
    sys.stdin.read()
    link.close()
    """
)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def resign_crc(raw: bytes | bytearray) -> bytes:
    body = bytes(raw[:-CRC_LEN])
    return body + struct.pack(">H", crc16_ccitt_false(body))


@pytest.fixture
def link_processes(tmp_path):
    key_file = write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    tap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tap.bind(("127.0.0.1", 0))
    gsw_port = free_udp_port()
    config = tmp_path / "link.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "key_file": str(key_file),
                "key_id": 1,
                "tm_key_id": 1,
                "crs": {
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "gsw_host": "127.0.0.1",
                    "gsw_port": tap.getsockname()[1],  # the CRS's telemetry goes through the tap
                    "replay_state": str(tmp_path / "crs" / "replay.json"),
                },
                "gsw": {
                    "crs_host": "127.0.0.1",
                    "crs_port": 1,
                    "bind_host": "127.0.0.1",
                    "bind_port": gsw_port,
                    "archive": str(tmp_path / "archive.sqlite"),
                    "command_state": str(tmp_path / "seq.json"),
                    # The attacker relays from the CRS's host (a spoofed source address passes a
                    # source check): here only authentication tells the CRS's word from a forgery.
                    "accept_from": ["127.0.0.1"],
                },
            }
        )
    )
    crs = subprocess.Popen(
        [sys.executable, "-c", CRS, str(config)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        crs_port = int(crs.stdout.readline())
        yield {
            "config": str(config),
            "key_file": key_file,
            "tap": tap,
            "crs_port": crs_port,
            "gsw": ("127.0.0.1", gsw_port),
            "archive": tmp_path / "archive.sqlite",
            "start_watch": lambda count: subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "tlt_gsw.cli",
                    "--config",
                    str(config),
                    "watch",
                    "--count",
                    str(count),
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            ),
        }
    finally:
        crs.stdin.close()
        try:
            crs.wait(10)
        except subprocess.TimeoutExpired:
            crs.kill()
            crs.wait()
        crs.stdout.close()
        tap.close()


def capture(tap: socket.socket, count: int, timeout: float = 10.0) -> list[bytes]:
    """What the CRS sent through the tap: ``count`` datagrams."""
    got: list[bytes] = []
    deadline = time.monotonic() + timeout
    while len(got) < count and time.monotonic() < deadline:
        tap.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            got.append(tap.recv(65535))
        except TimeoutError:
            break
    return got


def command_the_crs(setup, name: str) -> list[bytes]:
    """An operator's authenticated command; returns the CRS's ack (accepted, completed) captured."""
    keyring = KeyRing.load(setup["key_file"])
    with GswLink(DEFS, keyring, 1, ("127.0.0.1", setup["crs_port"])) as operator:
        sent = operator.send_command(name)
        assert operator.wait_ack(sent, final=True, timeout=10.0) is not None
    return capture(setup["tap"], 2)


def test_forged_replayed_altered_and_rekeyed_telemetry_is_archived_as_rejected(link_processes):
    setup = link_processes
    tap: socket.socket = setup["tap"]
    genuine = command_the_crs(setup, "stop")
    tm_ring = KeyRing.load(setup["key_file"]).telemetry
    kinds = [parse_datagram(raw, DEFS, keyring=tm_ring).kind for raw in genuine]
    assert kinds == ["ack", "ack"]
    accepted_ack, completed_ack = genuine

    forged_plain = encode_telemetry(  # a "Stop completed" from the public definitions
        DEFS,
        "ack",
        {
            "command_apid": DEFS.command_apid,
            "command_seq_count": 0,
            "security_seq": 1,
            "command": "stop",
            "stage": "completed",
            "reason": "none",
            "detail": "stop completed by the CRS, all motion halted",  # long enough to hold a header
        },
        seq_count=5,
    )
    # The same with a security header under the CRS's key id and a MAC made with a guessed key.
    forged_signed = TelemetrySigner(KeyRing({1: os.urandom(32)}, {1: os.urandom(32)}).telemetry, 1).encode(
        DEFS,
        "event",
        {"severity": "info", "source": "crs", "code": "C", "reason": "none", "text": "ok"},
        seq_count=6,
    )
    altered_ack = bytearray(accepted_ack)
    stage_at = len(altered_ack) - CRC_LEN - DEFS.mac_bytes - 3  # stage, reason, an empty detail
    assert altered_ack[stage_at] == 0  # accepted
    altered_ack[stage_at] = 2  # completed
    # An event captured: the CRS reports a datagram it refused.
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.sendto(b"junk", ("127.0.0.1", setup["crs_port"]))
    event = capture(tap, 1)[0]
    assert parse_datagram(event, DEFS, keyring=tm_ring).kind == "event"
    altered_event = bytearray(event)
    altered_event[-CRC_LEN - DEFS.mac_bytes - 1] ^= 0x20  # one character of the text
    rekeyed = bytearray(event)
    rekeyed[SEC : SEC + 2] = struct.pack(">H", 7)
    wrong_key = KeyRing({1: os.urandom(32)}, {9: os.urandom(32)})
    under_key_9 = TelemetrySigner(wrong_key.telemetry, 9).encode(
        DEFS,
        "event",
        {"severity": "info", "source": "crs", "code": "C", "reason": "none", "text": "ok"},
        seq_count=7,
    )
    attacks = [
        (forged_plain, "unknown_key"),  # no header: its first field bytes read as an unknown key id
        (forged_signed, "bad_auth"),
        (completed_ack, "replay"),  # captured, and the GSW already took it
        (resign_crc(altered_ack), "bad_auth"),
        (resign_crc(altered_event), "bad_auth"),
        (resign_crc(rekeyed), "unknown_key"),
        (under_key_9, "unknown_key"),
    ]
    later_good = command_the_crs(setup, "resume")  # genuine telemetry after the attacks

    total = 2 + len(attacks) + len(later_good)
    watch = setup["start_watch"](total)
    try:
        listening = watch.stdout.readline()
        assert "listening" in listening, watch.stderr.read() if watch.poll() is not None else listening
        for raw in [accepted_ack, completed_ack, *(raw for raw, _ in attacks), *later_good]:
            sender.sendto(raw, setup["gsw"])
            time.sleep(0.02)
        out, err = watch.communicate(timeout=30)
    finally:
        if watch.poll() is None:
            watch.kill()
        sender.close()
    assert watch.returncode == 0, err
    lines = out.splitlines()
    assert sum(line.startswith("REJECTED") for line in lines) == len(attacks), out
    assert f"rejected {len(attacks)} (failed authentication {len(attacks)}, " in lines[-1]
    assert "telemetry rejected" in err  # the GSW's log line

    conn = sqlite3.connect(setup["archive"])
    rows = conn.execute(
        "SELECT id, kind, status, raw FROM packets WHERE direction = 'rx' ORDER BY id"
    ).fetchall()
    assert [(kind, status) for _, kind, status, _ in rows] == (
        [("ack", "ok")] * 2 + [(None, reason) for _, reason in attacks] + [("ack", "ok")] * 2
    )
    rejected_ids = [packet_id for packet_id, kind, _, _ in rows if kind is None]
    marks = ",".join("?" * len(rejected_ids))
    assert conn.execute(
        f"SELECT COUNT(*) FROM fields WHERE packet_id IN ({marks})", rejected_ids
    ).fetchone() == (0,)
    assert [raw for _, _, _, raw in rows[2:-2]] == [raw for raw, _ in attacks]  # kept as evidence
    conn.close()
