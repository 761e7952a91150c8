"""Benchmark of the lifter link: the real driver (pyserial) against the firmware emulator process.

Prints, side by side in one run:
* the command loop: achieved rate and period jitter (|actual period - nominal|, p50/p99/max) of
  read + write cycles at the configured rate (50 Hz; goal: p99 jitter under 5 ms);
* the firmware watchdog: delay from the last velocity command to the first telemetry that shows
  the trip, against the configured bound of twice the command period.

The emulator runs as its own process (``tlt_sim.emulators.lifter_main``), as in a launch set, so
the driver's timing is not shared with the emulator's thread. Figures only; nothing is asserted.

    .venv/bin/python bench/lifter_link.py [--seconds 10] [--trips 20]
"""

from __future__ import annotations

import argparse
import itertools
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tlt_sim.emulators.lifter_firmware import load_firmware_config
from tlt_sim.emulators.lifter_main import DEFAULT_CONFIG as FIRMWARE_CONFIG

from tlt_drivers.lifter.config import load_lifter_config
from tlt_drivers.lifter.protocol import FirmwareState, Mode
from tlt_drivers.lifter.serial_interface import LifterSerialInterface


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q / 100.0 * len(ordered)))]


def command_loop(hw: LifterSerialInterface, seconds: float) -> None:
    period = hw.config.command_period_s
    hw.set_velocity_command([500, 500, 500, 500])
    starts: list[float] = []
    cycle_costs: list[float] = []
    start = time.monotonic()
    next_t = start
    while next_t - start < seconds:
        delay = next_t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        t = time.monotonic()
        starts.append(t)
        hw.read(t)
        hw.write(t)
        cycle_costs.append(time.monotonic() - t)
        next_t += period
    elapsed = starts[-1] - starts[0]
    periods = [b - a for a, b in itertools.pairwise(starts)]
    jitter_ms = [abs(p - period) * 1e3 for p in periods]
    rate = (len(starts) - 1) / elapsed
    print(f"command loop  nominal {1 / period:.1f} Hz over {elapsed:.1f} s: achieved {rate:.2f} Hz")
    print(
        f"  period jitter  p50 {percentile(jitter_ms, 50):.3f} ms  p99 {percentile(jitter_ms, 99):.3f} ms  "
        f"max {max(jitter_ms):.3f} ms  (goal: p99 < 5 ms)"
    )
    costs_ms = [c * 1e3 for c in cycle_costs]
    print(f"  read+write cost  p50 {percentile(costs_ms, 50):.3f} ms  p99 {percentile(costs_ms, 99):.3f} ms")
    print(f"  link: state {hw.state.name}, CRC errors {hw.crc_errors}, telemetry {hw.telemetry.state.name}")


def watchdog_trips(hw: LifterSerialInterface, trips: int, bound_s: float) -> None:
    delays: list[float] = []
    for _ in range(trips):
        hw.set_velocity_command([500, 500, 500, 500])
        t_cmd = time.monotonic()
        hw.write(t_cmd)
        deadline = t_cmd + 10 * bound_s
        armed = False  # until the reply to this command (trip cleared) is in, old replies may show a trip
        while time.monotonic() < deadline and not armed:
            time.sleep(0.0002)
            hw.read(time.monotonic())
            armed = not hw.telemetry.watchdog_tripped
        while time.monotonic() < deadline:
            hw.poll()  # state requests do not feed the watchdog
            time.sleep(0.0005)
            hw.read(time.monotonic())
            if hw.telemetry.watchdog_tripped:
                delays.append(time.monotonic() - t_cmd)
                break
        time.sleep(0.01)
    delays_ms = [d * 1e3 for d in delays]
    print(
        f"watchdog trip  configured bound 2 x {bound_s / 2 * 1e3:.1f} ms = {bound_s * 1e3:.1f} ms, "
        f"{len(delays)}/{trips} trips seen"
    )
    if delays_ms:
        print(
            f"  last command -> trip seen  min {min(delays_ms):.2f} ms  "
            f"median {statistics.median(delays_ms):.2f} ms  max {max(delays_ms):.2f} ms"
            "  (includes the 1 ms firmware tick and the 0.5 ms poll)"
        )
        print(f"  max excess over the bound {max(delays_ms) - bound_s * 1e3:.2f} ms")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--trips", type=int, default=20)
    args = parser.parse_args(argv)
    fw_config, _ = load_firmware_config(FIRMWARE_CONFIG)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"machine: {os.cpu_count()} CPUs, load average {load} (jitter grows with load)")
    with tempfile.TemporaryDirectory() as tmp:
        link = Path(tmp) / "lifter"
        emulator = subprocess.Popen(
            [sys.executable, "-m", "tlt_sim.emulators.lifter_main", "--link", str(link)],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            emulator.stdout.readline()
            hw = LifterSerialInterface(load_lifter_config().with_port(str(link)))
            if not (hw.configure() and hw.activate()):
                print(f"driver did not come up: {hw.fault}", file=sys.stderr)
                return 1
            # keep the link alive while the firmware initializes
            deadline = time.monotonic() + fw_config.init_duration_s + 2.0
            while time.monotonic() < deadline and hw.firmware_state != FirmwareState.HARDWARE_CONTROL:
                hw.read(time.monotonic())
                hw.write(time.monotonic())
                time.sleep(hw.config.command_period_s)
            accepted, reason, _ = hw.request_mode(Mode.CRS_CONTROL)
            if not accepted:
                print(f"CRS Control refused: {reason}", file=sys.stderr)
                return 1
            command_loop(hw, args.seconds)
            watchdog_trips(hw, args.trips, fw_config.watchdog_timeout_s)
            hw.shutdown()
        finally:
            emulator.send_signal(signal.SIGTERM)
            try:
                emulator.wait(timeout=10)
            except subprocess.TimeoutExpired:
                emulator.kill()
                emulator.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
