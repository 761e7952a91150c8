"""Run the stand-ins of ``conftest.py`` in a process of their own, for the CRS process tests.

``rig_process.py RECORD [--hold-s S] [--clock-after S]``: every request an ARS stand-in gets,
and every ``/crs/tree_status`` heard, is appended to RECORD as a JSON line; ``--clock-after``
publishes ``/clock`` from t = 1000 s after S seconds (for ``use_sim_time``). Runs until SIGTERM.
Keeping the stand-ins out of the pytest process keeps these tests independent of the in-process
tests' ROS contexts.
"""

from __future__ import annotations

import argparse
import importlib.util
import signal
import sys
import threading
import time
from pathlib import Path

import rclpy

from tlt_common.json_lines import JsonLinesWriter


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("record", type=Path)
    parser.add_argument("--hold-s", type=float, default=0.0)
    parser.add_argument("--clock-after", type=float, default=None)
    args = parser.parse_args()
    spec = importlib.util.spec_from_file_location("crs_rig", Path(__file__).with_name("conftest.py"))
    rig_module = importlib.util.module_from_spec(spec)
    sys.modules["crs_rig"] = rig_module  # dataclasses look their module up there
    spec.loader.exec_module(rig_module)
    write = JsonLinesWriter(args.record).append

    original_add = rig_module.Recorder.add

    def add(self, request):
        write(
            {"kind": "request", "ars": request.ars, "request": request.request, "member": request.member_id}
        )
        return original_add(self, request)

    rig_module.Recorder.add = add
    rclpy.init()
    rig = rig_module.Rig()
    for ars in rig.ars.values():
        ars.hold_s = args.hold_s
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    from tlt_interfaces.msg import TreeStatus

    rig.node.create_subscription(
        TreeStatus,
        "/crs/tree_status",
        lambda msg: write({"kind": "tree_status", "sec": msg.header.stamp.sec, "wall": time.time()}),
        10,
    )
    clock_pub = rig.node.create_publisher(Clock, "/clock", 10)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    write({"kind": "ready"})
    started = time.monotonic()
    sim = 1000.0
    while not stop.is_set():
        if args.clock_after is not None and time.monotonic() - started >= args.clock_after:
            if sim == 1000.0:
                write({"kind": "clock_started", "wall": time.time()})
            sim += 0.02
            clock_pub.publish(Clock(clock=Time(sec=int(sim), nanosec=int((sim % 1) * 1e9))))
        stop.wait(0.01)
    rig.close()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
