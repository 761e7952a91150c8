"""Command round trip on loopback, authenticated both ways and not: GSW send -> CRS -> accepted ack.

Authenticated: the CRS end (:class:`GroundLink`) runs in its own process, as in the system; it
verifies the command's MAC, writes its anti-replay state (fsync) and signs the ack with the
telemetry key; this process is the GSW (:class:`GswLink`, archive off so only the link is
measured), which signs the command and verifies the ack's MAC and replay window. The time is from
just before ``send_command`` (which builds and signs the packet) to the accepted ack being decoded.

Unauthenticated, for the ratio: the same exchange with every security step left out, in a second
CRS process: a command packet without security header or MAC, checked by its header and CRC,
answered by an ack in the unsigned form, which this process decodes. Where /dev/shm exists, a
third link is authenticated like the first with its anti-replay state there (memory-backed), so
the figures tell the wait for the disk from the cost of the MACs. The links take turns in blocks
of commands, so all see the same load. Goal (issues 7 and 66): p50 <= 5 ms, p99 <= 20 ms
authenticated, the state on disk as the CRS keeps it.

    .venv/bin/python bench/ground_link_roundtrip.py [--commands 1000]
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import (
    CRC_LEN,
    Packet,
    cds_time,
    crc16_ccitt_false,
    encode_telemetry,
    parse_datagram,
)
from tlt_common.ccsds.definitions import Definitions, load_definitions
from tlt_common.ccsds.reasons import AckStage
from tlt_crs.ground_link import GroundLink
from tlt_gsw.link import GswLink

_WORDS = struct.Struct(">HHH")
_SEQ = struct.Struct(">Q")
BLOCK = 50  # commands in a row on one link before the next link's turn
AUTHENTICATED = "authenticated"
AUTHENTICATED_SHM = "auth, /dev/shm"
UNAUTHENTICATED = "unauthenticated"


def serve_crs(key_hex: str, tm_key_hex: str, state: str) -> int:
    """The authenticated CRS process: print the bound port, serve until standard input closes."""
    link = GroundLink(
        load_definitions(),
        KeyRing({1: bytes.fromhex(key_hex)}, {1: bytes.fromhex(tm_key_hex)}),
        state,
        on_command=lambda command: None,  # the bench has no tree to hand commands to
        stats_period_s=0,
    )
    link.start()
    print(link.address[1], flush=True)
    sys.stdin.read()
    link.close()
    return 0


def plain_command(defs: Definitions, name: str, seq: int, seq_count: int) -> bytes:
    """A command packet with no security header and no MAC: header, time, number, id, CRC."""
    body = cds_time(time.time()) + _SEQ.pack(seq) + bytes([defs.command(name).id])
    total = 6 + len(body) + CRC_LEN
    header = _WORDS.pack(0x1800 | defs.command_apid, 0xC000 | (seq_count & 0x3FFF), total - 7)
    packet = header + body
    return packet + struct.pack(">H", crc16_ccitt_false(packet))


def serve_plain() -> int:
    """The unauthenticated CRS process: header and CRC checks, an unsigned accepted ack."""
    defs = load_definitions()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    print(sock.getsockname()[1], flush=True)
    seq_count = 0
    while True:
        data, source = sock.recvfrom(65535)
        if not data:
            return 0
        word0, word1, length = _WORDS.unpack_from(data)
        if (
            word0 >> 13
            or word0 & 0x7FF != defs.command_apid
            or length + 7 != len(data)
            or struct.unpack_from(">H", data, len(data) - CRC_LEN)[0] != crc16_ccitt_false(data[:-CRC_LEN])
        ):
            continue
        (seq,) = _SEQ.unpack_from(data, 13)
        command = defs.commands_by_id[data[21]].name
        ack = encode_telemetry(defs, "ack", {
            "command_apid": defs.command_apid, "command_seq_count": word1 & 0x3FFF, "security_seq": seq,
            "command": command, "stage": "accepted", "reason": "none", "detail": "",
        }, seq_count=seq_count)  # fmt: skip
        seq_count = (seq_count + 1) & 0x3FFF
        sock.sendto(ack, source)


def percentile(sorted_values: list[float], q: float) -> float:
    index = min(len(sorted_values) - 1, max(0, round(q * (len(sorted_values) - 1))))
    return sorted_values[index]


def start_crs(*args: str) -> tuple[subprocess.Popen, int]:
    proc = subprocess.Popen(
        [sys.executable, __file__, *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    return proc, int(proc.stdout.readline())  # type: ignore[union-attr]


def stop_crs(proc: subprocess.Popen) -> None:
    proc.stdin.close()  # type: ignore[union-attr]
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    proc.stdout.close()  # type: ignore[union-attr]


def authenticated_round_trip(gsw: GswLink, name: str, _seq: int = 0) -> float | None:
    start = time.perf_counter()
    sent = gsw.send_command(name)
    ack = gsw.wait_ack(sent, timeout=2.0)
    elapsed = time.perf_counter() - start
    return elapsed * 1000.0 if ack is not None and ack.stage is AckStage.ACCEPTED else None


def plain_round_trip(defs: Definitions, sock: socket.socket, port: int, name: str, seq: int) -> float | None:
    start = time.perf_counter()
    sock.sendto(plain_command(defs, name, seq, seq), ("127.0.0.1", port))
    deadline = start + 2.0
    while True:
        sock.settimeout(max(1e-4, deadline - time.perf_counter()))
        try:
            data = sock.recv(65535)
        except TimeoutError:
            return None
        ack = parse_datagram(data, defs, expect="tm")
        if (
            isinstance(ack, Packet)
            and ack.fields["security_seq"] == seq
            and ack.fields["stage"] == "accepted"
        ):
            return (time.perf_counter() - start) * 1000.0


def summary(label: str, latencies: list[float], lost: int) -> tuple[float, float]:
    latencies.sort()
    p50, p90, p99 = (percentile(latencies, q) for q in (0.5, 0.9, 0.99))
    print(
        f"{label:16s} n={len(latencies)} lost={lost}  p50 {p50:.2f}  p90 {p90:.2f}  p99 {p99:.2f}  "
        f"max {latencies[-1]:.2f}  mean {statistics.fmean(latencies):.2f}"
    )
    return p50, p99


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", type=int, default=1000, help="commands measured on each link")
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument(
        "--serve-crs", nargs=3, metavar=("KEY_HEX", "TM_KEY_HEX", "STATE"), help=argparse.SUPPRESS
    )
    parser.add_argument("--serve-plain", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve_crs:
        return serve_crs(*args.serve_crs)
    if args.serve_plain:
        return serve_plain()
    defs = load_definitions()
    key, tm_key = os.urandom(32), os.urandom(32)
    keyring = KeyRing({1: key}, {1: tm_key})
    round_trips: dict[str, Callable[[str, int], float | None]] = {}
    with contextlib.ExitStack() as stack:
        folders = {AUTHENTICATED: stack.enter_context(tempfile.TemporaryDirectory())}
        if Path("/dev/shm").is_dir():  # memory-backed: the anti-replay state's fsync waits on no disk
            folders[AUTHENTICATED_SHM] = stack.enter_context(tempfile.TemporaryDirectory(dir="/dev/shm"))
        for link, folder in folders.items():
            proc, port = start_crs("--serve-crs", key.hex(), tm_key.hex(), str(Path(folder) / "replay.json"))
            stack.callback(stop_crs, proc)
            gsw = stack.enter_context(GswLink(defs, keyring, 1, ("127.0.0.1", port)))
            round_trips[link] = functools.partial(authenticated_round_trip, gsw)
        plain_crs, plain_port = start_crs("--serve-plain")
        stack.callback(stop_crs, plain_crs)
        plain_sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        plain_sock.bind(("127.0.0.1", 0))
        stack.callback(plain_sock.sendto, b"", ("127.0.0.1", plain_port))  # ends the plain CRS
        round_trips[UNAUTHENTICATED] = lambda name, seq: plain_round_trip(
            defs, plain_sock, plain_port, name, seq
        )

        links = list(round_trips)
        latencies: dict[str, list[float]] = {link: [] for link in links}
        lost = dict.fromkeys(links, 0)
        sent = 0

        def one(link: str, measured: bool = True) -> None:
            nonlocal sent
            sent += 1
            ms = round_trips[link]("pause" if sent % 2 else "resume", sent)
            if ms is None:
                lost[link] += 1
            elif measured:
                latencies[link].append(ms)

        for _ in range(args.warmup):
            for link in links:
                one(link, measured=False)
        block = 0
        while any(len(latencies[link]) + lost[link] < args.commands for link in links):
            link = links[block % len(links)]
            for _ in range(min(BLOCK, args.commands - len(latencies[link]) - lost[link])):
                one(link)
            block += 1

    print(f"machine: {os.cpu_count()} CPU(s), 1-min load average {os.getloadavg()[0]:.1f}")
    print(f"round trip send -> accepted ack (ms), the links taking turns in blocks of {BLOCK} commands:")
    figures = {link: summary(link, latencies[link], lost[link]) for link in links}
    (p50, p99), (plain_p50, plain_p99) = figures[AUTHENTICATED], figures[UNAUTHENTICATED]
    print(f"ratio authenticated / unauthenticated: p50 {p50 / plain_p50:.1f}  p99 {p99 / plain_p99:.1f}")
    if AUTHENTICATED_SHM in figures:
        shm_p50, shm_p99 = figures[AUTHENTICATED_SHM]
        print(
            f"ratio authenticated (state in /dev/shm) / unauthenticated: p50 {shm_p50 / plain_p50:.1f}"
            f"  p99 {shm_p99 / plain_p99:.1f}"
        )
    goal = p50 <= 5.0 and p99 <= 20.0 and lost[AUTHENTICATED] == 0
    verdict = "met" if goal else "NOT met"
    print(f"goal p50 <= 5 ms and p99 <= 20 ms, both directions authenticated, state on disk: {verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
