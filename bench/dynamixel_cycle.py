"""Dynamixel control-cycle figures: the real driver against the emulated chain over a pty, at 100 Hz.

One cycle is what the driver node does each timer tick: ``read`` (one SYNC_READ of Moving ..
Present Position from four MX-106(2.0) servos, with the status error bytes checked) and ``write``
(one SYNC_WRITE of Goal Position), plus a sinusoidal command so the servos move. Cycles are
scheduled on absolute deadlines, as a ROS timer does; a cycle that overruns its deadline starts
the next one at once.

Prints the achieved rate, cycle time p50/p99/max, the number of overruns and communication
retries. Goal (issue 3): 100 Hz held, p99 cycle time under 10 ms. The emulated chain runs in its
own process, as the servos are on the far side of a real link (in one process the SDK's polling
receive loop and the emulator thread would share one interpreter lock, measuring that instead).
A real U2D2 link adds wire time: about 0.3 ms for these packets at 1 Mbps.

    .venv/bin/python bench/dynamixel_cycle.py [--rate 100] [--seconds 5] [--servos 4]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import statistics
import time

from tlt_sim.emulators.dynamixel_chain import DynamixelChain

from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
from tlt_drivers.dynamixel.config import validate_chain


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, math.ceil(q * len(ordered)) - 1)]


def serve_chain(servos: int, conn, stop) -> None:
    """Child process: serve the emulated chain on a pty until ``stop`` is set."""
    chain = DynamixelChain(range(1, servos + 1))
    conn.send(chain.start())
    stop.wait()
    chain.stop()


def run(rate: float, seconds: float, servos: int) -> dict[str, float]:
    parent, child = multiprocessing.Pipe()
    stop = multiprocessing.Event()
    device = multiprocessing.Process(target=serve_chain, args=(servos, child, stop), daemon=True)
    device.start()
    if not parent.poll(10.0):
        raise SystemExit("the emulated chain did not start")
    port = parent.recv()
    joints = [
        {
            "name": f"j{i}",
            "id": i,
            "mode": "position",
            "controller": "trajectory",
            "unit": "rad",
            "lower": -1.5,
            "upper": 1.5,
            "max_velocity": 3.0,
        }
        for i in range(1, servos + 1)
    ]
    hw = DynamixelChainInterface(validate_chain({"component": "bench", "port": port, "joints": joints}))
    try:
        if not (hw.configure() and hw.activate()):
            raise SystemExit(f"bring-up failed: {hw.fault}")
        period = 1.0 / rate
        cycles = int(seconds * rate)
        durations: list[float] = []
        overruns = 0
        hw.retries = 0
        start = time.perf_counter()
        deadline = start
        for k in range(cycles):
            t0 = time.perf_counter()
            if not hw.read(t0):
                raise SystemExit(f"read failed: {hw.fault}")
            for i, name in enumerate(hw.joint_names):
                hw.command[name] = 0.5 * math.sin(2 * math.pi * 0.5 * k * period + i)
            if not hw.write(t0):
                raise SystemExit(f"write failed: {hw.fault}")
            durations.append(time.perf_counter() - t0)
            deadline += period
            slack = deadline - time.perf_counter()
            if slack > 0:
                time.sleep(slack)
            else:
                overruns += 1
                deadline = time.perf_counter()
        elapsed = time.perf_counter() - start
        return {
            "cycles": cycles,
            "rate_hz": cycles / elapsed,
            "p50_ms": statistics.median(durations) * 1e3,
            "p99_ms": percentile(durations, 0.99) * 1e3,
            "max_ms": max(durations) * 1e3,
            "overruns": overruns,
            "retries": hw.retries,
        }
    finally:
        hw.shutdown()
        stop.set()
        device.join(timeout=5.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--servos", type=int, default=4)
    args = parser.parse_args(argv)
    r = run(args.rate, args.seconds, args.servos)
    print(
        f"dynamixel cycle: sync read of {args.servos} servos + sync write, target {args.rate:.0f} Hz, "
        f"{r['cycles']} cycles"
    )
    print(f"  achieved rate   {r['rate_hz']:8.2f} Hz   (goal: {args.rate:.0f} Hz held)")
    print(f"  cycle time p50  {r['p50_ms']:8.3f} ms")
    print(f"  cycle time p99  {r['p99_ms']:8.3f} ms   (goal: < 10 ms)")
    print(f"  cycle time max  {r['max_ms']:8.3f} ms")
    print(f"  overruns        {r['overruns']:8d}")
    print(f"  retries         {r['retries']:8d}")
    held = r["rate_hz"] >= 0.99 * args.rate and r["p99_ms"] < 10.0
    print(f"  goal {'met' if held else 'NOT met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
