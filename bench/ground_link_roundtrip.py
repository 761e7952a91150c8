"""Command round trip on loopback: GSW send -> CRS verify (MAC, anti-replay fsync) -> accepted ack.

The CRS end (:class:`GroundLink`) runs in its own process, as in the system; this process is the
GSW (:class:`GswLink`, archive off so only the link is measured). Each command is sent after the
previous one was acknowledged; the time is from just before ``send_command`` (which builds and
signs the packet) to the accepted ack being decoded. Goal (issue 7): p50 <= 5 ms, p99 <= 20 ms.

    .venv/bin/python bench/ground_link_roundtrip.py [--commands 1000]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import AckStage
from tlt_crs.ground_link import GroundLink
from tlt_gsw.link import GswLink


def serve_crs(key_hex: str, tm_key_hex: str, state: str) -> int:
    """The CRS process: print the bound port, serve until standard input closes."""
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


def percentile(sorted_values: list[float], q: float) -> float:
    index = min(len(sorted_values) - 1, max(0, round(q * (len(sorted_values) - 1))))
    return sorted_values[index]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", type=int, default=1000)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument(
        "--serve-crs", nargs=3, metavar=("KEY_HEX", "TM_KEY_HEX", "STATE"), help=argparse.SUPPRESS
    )
    args = parser.parse_args(argv)
    if args.serve_crs:
        return serve_crs(*args.serve_crs)
    defs = load_definitions()
    key, tm_key = os.urandom(32), os.urandom(32)
    with tempfile.TemporaryDirectory() as tmp:
        crs = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--serve-crs",
                key.hex(),
                tm_key.hex(),
                str(Path(tmp) / "replay.json"),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            address = ("127.0.0.1", int(crs.stdout.readline()))
            latencies, lost = [], 0
            with GswLink(defs, KeyRing({1: key}, {1: tm_key}), 1, address) as gsw:
                for i in range(args.warmup + args.commands):
                    start = time.perf_counter()
                    sent = gsw.send_command("pause" if i % 2 else "resume")
                    ack = gsw.wait_ack(sent, timeout=2.0)
                    elapsed = time.perf_counter() - start
                    if ack is None or ack.stage is not AckStage.ACCEPTED:
                        lost += 1
                        continue
                    if i >= args.warmup:
                        latencies.append(elapsed * 1000.0)
        finally:
            crs.stdin.close()
            try:
                crs.wait(10)
            except subprocess.TimeoutExpired:
                crs.kill()
                crs.wait()
            crs.stdout.close()
    latencies.sort()
    p50, p90, p99 = (percentile(latencies, q) for q in (0.5, 0.9, 0.99))
    print(f"commands: {len(latencies)} measured after {args.warmup} warm-up, {lost} without an accepted ack")
    print(f"machine: {os.cpu_count()} CPU(s), 1-min load average {os.getloadavg()[0]:.1f}")
    print(
        f"round trip send -> accepted ack (ms): p50 {p50:.2f}  p90 {p90:.2f}  p99 {p99:.2f}  "
        f"max {latencies[-1]:.2f}  mean {statistics.fmean(latencies):.2f}"
    )
    goal = p50 <= 5.0 and p99 <= 20.0 and lost == 0
    print(f"goal p50 <= 5 ms and p99 <= 20 ms: {'met' if goal else 'NOT met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
