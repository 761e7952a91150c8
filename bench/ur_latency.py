"""Command-to-motion latency through ur-rtde and the emulated UR controller.

For moveJ (asynchronous) and servoJ, the time from the ur-rtde call until the RTDE receive
stream first reports ``actual_q`` moving away from where it stood. Both the client calls and the
observation go over loopback TCP to the emulator, which runs in its own process at 500 Hz; the
figure is the stack's latency (client handshake, one or two controller cycles, one RTDE period
on the way back), not a UR10e's.

Run: ``.venv/bin/python bench/ur_latency.py [--samples 40] [--host 127.0.0.2]``. Prints p50/p99.
"""

from __future__ import annotations

import argparse
import statistics
import time

import rtde_control
import rtde_receive
from tlt_sim.emulators.ur_controller_config import URControllerConfig
from tlt_sim.emulators.ur_controller_process import URControllerProcess

STEP = 0.02  # rad per command; motion shows as soon as any joint moves by more than THRESHOLD
THRESHOLD = 1e-6


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    index = min(len(ordered) - 1, max(0, round(q / 100 * (len(ordered) - 1))))
    return ordered[index]


def _wait_motion(receive, q0: list[float], timeout: float = 2.0) -> float:
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        q = receive.getActualQ()
        if max(abs(a - b) for a, b in zip(q, q0, strict=True)) > THRESHOLD:
            return time.perf_counter()
        time.sleep(0.0002)
    raise TimeoutError("the arm did not move")


def _settle(receive, timeout: float = 3.0) -> list[float]:
    """Wait until the joints stop changing; return where they stand."""
    last = receive.getActualQ()
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        time.sleep(0.02)
        q = receive.getActualQ()
        if q == last and all(v == 0.0 for v in receive.getActualQd()):
            return q
        last = q
    return last


def measure(host: str, samples: int) -> dict[str, list[float]]:
    receive = rtde_receive.RTDEReceiveInterface(host)
    control = rtde_control.RTDEControlInterface(host)
    results: dict[str, list[float]] = {"moveJ (async)": [], "servoJ": []}
    try:
        sign = 1.0
        for _ in range(samples):
            q0 = _settle(receive)
            target = list(q0)
            target[0] += sign * STEP
            sign = -sign
            t0 = time.perf_counter()
            control.moveJ(target, 1.0, 4.0, True)
            results["moveJ (async)"].append(_wait_motion(receive, q0) - t0)
        for _ in range(samples):
            q0 = _settle(receive)
            target = list(q0)
            target[1] += sign * STEP
            sign = -sign
            t0 = time.perf_counter()
            control.servoJ(target, 0.0, 0.0, 0.008, 0.03, 2000)
            results["servoJ"].append(_wait_motion(receive, q0) - t0)
            control.servoStop(10.0)
    finally:
        control.stopScript()
        control.disconnect()
        receive.disconnect()
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=40)
    parser.add_argument("--host", default="127.0.0.2")
    args = parser.parse_args(argv)
    with URControllerProcess(URControllerConfig(host=args.host)):
        results = measure(args.host, args.samples)
    print(f"UR command-to-motion latency, ur-rtde 1.6.5 -> emulator at 500 Hz ({args.samples} samples each)")
    print(f"{'command':<16}{'p50 ms':>10}{'p99 ms':>10}{'max ms':>10}")
    for name, values in results.items():
        ms = [v * 1000 for v in values]
        print(f"{name:<16}{statistics.median(ms):>10.2f}{_percentile(ms, 99):>10.2f}{max(ms):>10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
