"""The twin as a process: /clock advances at the configured real-time factor (never faster), the
links appear under the run folder with the ready file, and everything is withdrawn on the way out.
The whole EDU through the real driver nodes is tested in test_bringup_twin.py."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

LINKS = ("lifter", "top_grippers", "active_grippers", "camera_mounts", "ee_x", "ee_y")


def test_clock_advances_at_the_real_time_factor_and_links_come_and_go(tmp_path):
    run = tmp_path / "run"
    rtf = 0.5
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tlt_sim.twin.main",
            "--rtf",
            str(rtf),
            "--run-dir",
            str(run),
            "--ur-x-host",
            "127.0.78.2",
            "--ur-y-host",
            "127.0.78.3",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ),
    )
    ctx = Context()
    rclpy.init(context=ctx)
    node = Node("clock_probe", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    samples: list[tuple[float, float]] = []
    node.create_subscription(
        Clock,
        "/clock",
        lambda m: samples.append((time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)),
        100,
    )
    try:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not (run / "twin.ready").exists():
            time.sleep(0.1)
        assert (run / "twin.ready").exists(), "the twin never became ready"
        for name in LINKS:
            assert os.path.realpath(run / name).startswith("/dev/pts/"), name
        end = time.monotonic() + 4.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
    finally:
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=30)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    assert proc.returncode == 0, output
    assert len(samples) > 20, output
    sims = [s for _, s in samples]
    assert sims == sorted(sims), "sim time never goes back"
    (w0, s0), (w1, s1) = samples[len(samples) // 5], samples[-1]
    ratio = (s1 - s0) / (w1 - w0)
    # Never faster than asked (the pacer's promise); slower only if this machine cannot keep up.
    assert 0.0 < ratio <= rtf * 1.15, f"sim/wall = {ratio:.3f} at rtf {rtf}"
    assert not (run / "twin.ready").exists()
    assert not any((run / name).is_symlink() for name in LINKS), "links withdrawn on the way out"
