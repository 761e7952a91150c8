"""What the whole system costs while it waits: CPU seconds per simulated second, per process.

Starts ``config/launch/system_twin.yaml`` (the twin, the eight driver nodes, the CRS, both ARSs,
vision and the recorder; no ground station, so no Start: nothing builds) in a private ROS domain
and run folder, lets it settle, then measures over ``--seconds`` of wall time how far the sim
clock moved and how much CPU each process took. It prints:

* the real-time factor the idle system ran at (with ``--rtf 0``, as fast as the machine allows);
* the CPU seconds the whole system takes per simulated second, and per process;
* the most real-time factor the cores could give the idle system (cores / CPU per sim second):
  the ceiling of a build's wall time, before any motion planning, vision or tree work.

The wall-time goal of a two-bay build (10 minutes for about 1400 s of motions alone) needs the
twin at 2.3 times real time at least (docs/system.md, Benchmarks); this says how far the system's
own overhead leaves it from that.

Usage: python bench/system_load.py [--rtf 0] [--settle 60] [--seconds 60] [--mission one_bay]
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_SET = ROOT / "config/launch/system_twin.yaml"
TLT = Path(sys.executable).with_name("tlt")
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def descendants(pid: int) -> list[int]:
    """``pid`` and every process below it."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                todo.extend(int(c) for c in (task / "children").read_text().split())
            except OSError:
                continue
    return out


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU time of ``pid``, or None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def label(pid: int) -> str:
    """The process's command, short: the executable's name and its first arguments."""
    try:
        argv = [a.decode() for a in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0") if a]
    except OSError:
        return "?"
    words = [os.path.basename(a) if i < 2 else a for i, a in enumerate(argv)]
    if len(words) > 1 and words[0].startswith("python"):
        words = words[1:]
    if "spawn_main" in " ".join(words):
        return "(a twin UR controller)"
    return " ".join(words)[:60]


def ros_domain(pids: list[int]) -> str:
    for pid in pids:
        try:
            for entry in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0"):
                if entry.startswith(b"ROS_DOMAIN_ID="):
                    return entry.split(b"=", 1)[1].decode()
        except OSError:
            continue
    raise RuntimeError("no process of the launch set has a ROS_DOMAIN_ID")


class SimClock:
    """The latest ``/clock`` of the run's ROS domain, on a thread of its own."""

    def __init__(self, domain: str) -> None:
        os.environ["ROS_DOMAIN_ID"] = domain  # before rclpy reads it
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rosgraph_msgs.msg import Clock

        self.now: float | None = None
        rclpy.init()
        self.node = rclpy.create_node("system_load_bench")
        self.node.create_subscription(Clock, "/clock", self._on_clock, 10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _on_clock(self, msg) -> None:
        self.now = msg.clock.sec + msg.clock.nanosec * 1e-9


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rtf", type=float, default=0.0, help="the twin's real-time factor (0: no limit)")
    parser.add_argument("--settle", type=float, default=60.0, help="wall seconds after the twin is up")
    parser.add_argument("--seconds", type=float, default=60.0, help="wall seconds measured")
    parser.add_argument("--mission", default="one_bay")
    args = parser.parse_args(argv)
    run_dir = Path(tempfile.mkdtemp(prefix="tlt-system-load-"))
    env = {**os.environ, "TLT_RUN_DIR": str(run_dir), "TLT_TWIN_RTF": str(args.rtf),
           "TLT_MISSION": args.mission, "TLT_UR_X_HOST": "127.0.84.2", "TLT_UR_Y_HOST": "127.0.84.3",
           "TLT_GROUND_CRS_PORT": "52181", "TLT_GROUND_GSW_PORT": "52182"}  # fmt: skip
    log = (run_dir / "launch.log").open("wb")
    launcher = subprocess.Popen(
        [str(TLT), "launch", "--isolated", str(LAUNCH_SET)],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
        cwd=ROOT,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 180
        while not (run_dir / "twin.ready").exists():
            if launcher.poll() is not None or time.monotonic() > deadline:
                print(f"the launch set did not bring the twin up; see {run_dir / 'launch.log'}")
                return 1
            time.sleep(0.5)
        print(f"twin up; settling {args.settle:g} s", flush=True)
        time.sleep(args.settle)
        clock = SimClock(ros_domain(descendants(launcher.pid)))
        while clock.now is None:
            time.sleep(0.1)
        pids = descendants(launcher.pid)
        names = {p: label(p) for p in pids}
        cpu0 = {p: cpu_seconds(p) for p in pids}
        sim0, wall0 = clock.now, time.monotonic()
        print(f"measuring {args.seconds:g} s", flush=True)
        time.sleep(args.seconds)
        cpu1 = {p: cpu_seconds(p) for p in pids}
        sim, wall = clock.now - sim0, time.monotonic() - wall0
    finally:
        os.killpg(launcher.pid, signal.SIGINT)
        try:
            launcher.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(launcher.pid, signal.SIGKILL)
        log.close()
    if sim <= 0:
        print(f"the sim clock did not move; see {run_dir / 'launch.log'}")
        return 1
    shutil.rmtree(run_dir, ignore_errors=True)
    used = sorted(
        ((cpu1[p] - cpu0[p], names[p]) for p in pids if cpu0[p] is not None and cpu1[p] is not None),
        reverse=True,
    )
    total = sum(c for c, _ in used)
    cores = os.cpu_count() or 1
    print(
        f"idle system, --rtf {args.rtf:g}: {sim:.1f} s of sim time in {wall:.1f} s of wall time, "
        f"{sim / wall:.2f} x real time"
    )
    print(
        f"CPU per simulated second: {total / sim:.3f} s (all processes); on {cores} cores the idle "
        f"system can run at most {cores / (total / sim):.2f} x real time"
    )
    for seconds, name in used:
        if seconds / sim >= 0.005:
            print(f"  {seconds / sim:6.3f}  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
