"""CPU that one idle UR arm's link costs, by the RTDE rate the driver asks of the controller.

The twin runs sixteen processes on two cores, and every sim second it cannot give them is a
second longer build. One arm's share: the ``tlt-ur`` driver process (ur-rtde's receive and control
interfaces, each with its own RTDE stream, and the node's 125 Hz control cycle) against the
emulated controller in its own process (its 500 Hz cycle packs each stream's data packages in
Python). Measured at rest, for each rate: the two processes' CPU time over a window, as a share of
one core. The twin's launch set asks for 125 Hz (``config/launch/twin.yaml``); the arm's own
configuration keeps an e-Series' 500 Hz.

Run: ``.venv/bin/python bench/ur_stream_load.py [--rates 500 125] [--window 20]``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HOST = "127.0.0.2"


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(rate_hz: float, window_s: float, settle_s: float = 8.0) -> tuple[float, float]:
    """(emulator, driver) CPU as a fraction of one core, the driver asking ``rate_hz``."""
    from tlt_sim.emulators.ur_controller_config import URControllerConfig
    from tlt_sim.emulators.ur_controller_process import URControllerProcess

    from tlt_common.ros.isolation import isolate

    env = dict(os.environ)
    isolate(env)
    emulator = URControllerProcess(URControllerConfig(host=HOST)).start()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            tlt_ur = Path(sys.executable).with_name("tlt-ur")
            driver = subprocess.Popen(
                [
                    str(tlt_ur),
                    "--config",
                    str(ROOT / "config/hardware/ur_x.yaml"),
                    "--host",
                    HOST,
                    "--rtde-frequency-hz",
                    str(rate_hz),
                ],
                env=env,
                cwd=tmp,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            try:
                time.sleep(settle_s)  # connected, script uploaded, streaming
                if driver.poll() is not None:
                    raise RuntimeError(f"tlt-ur exited with {driver.returncode}")
                pids = (emulator.pid, driver.pid)
                before, t0 = [_cpu_s(p) for p in pids], time.monotonic()
                time.sleep(window_s)
                after, t1 = [_cpu_s(p) for p in pids], time.monotonic()
            finally:
                driver.terminate()
                driver.wait(timeout=10)
    finally:
        emulator.close()
    emulator_share, driver_share = ((a - b) / (t1 - t0) for a, b in zip(after, before, strict=True))
    return emulator_share, driver_share


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rates", type=float, nargs="+", default=[500.0, 125.0])
    p.add_argument("--window", type=float, default=20.0, help="seconds measured per rate")
    args = p.parse_args(argv)
    totals = {}
    for rate in args.rates:
        emulator, driver = measure(rate, args.window)
        totals[rate] = emulator + driver
        print(
            f"RTDE {rate:5g} Hz: emulator {emulator * 100:5.1f} %, driver {driver * 100:5.1f} %, "
            f"together {totals[rate] * 100:5.1f} % of a core",
            flush=True,
        )
    first = args.rates[0]
    for rate in args.rates[1:]:
        print(f"{rate:g} Hz / {first:g} Hz: {totals[rate] / totals[first]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
