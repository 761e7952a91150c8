"""Stand-ins for the several-hosts system test, one part per emulated host, from the CRS tests' rig
(tests/tlt_crs/conftest.py): ``several_hosts_rig.py PART RECORD [--hold-first-s S]``.

PART ``drivers``: the driver and vision stand-ins of the CRS Jetson (lifter, Top and Active Grippers,
camera mounts, part and bay inspection). PART ``ars_x`` or ``ars_y``: that ARS's action servers and
ground-command service; its first request is held ``--hold-first-s`` seconds (the test cuts the
host's link meanwhile), every later one is answered at once. Each request is appended to RECORD as a
JSON line; ``{"kind": "ready"}`` when the part is up. Runs until SIGINT or SIGTERM.
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
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor

from tlt_common.json_lines import JsonLinesWriter

CRS_RIG = Path(__file__).resolve().parents[1] / "tlt_crs" / "conftest.py"


def load_rig():
    spec = importlib.util.spec_from_file_location("crs_rig", CRS_RIG)
    module = importlib.util.module_from_spec(spec)
    sys.modules["crs_rig"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("part", choices=["drivers", "ars_x", "ars_y"])
    parser.add_argument("record", type=Path)
    parser.add_argument("--hold-first-s", type=float, default=0.0)
    args = parser.parse_args()
    rig_module = load_rig()
    record = JsonLinesWriter(args.record)

    def write(entry: dict) -> None:
        record.append({**entry, "wall": time.time()})

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    rclpy.init()
    if args.part == "drivers":
        rig = rig_module.Rig(with_drivers=True, with_ars=False)
        write({"kind": "ready", "part": args.part})
        stop.wait()
        rig.close()
    else:
        node = rclpy.create_node(f"{args.part}_stand_in")
        recorder = rig_module.Recorder()
        ars = rig_module.ArsStandIn(node, args.part, recorder, ReentrantCallbackGroup())
        ars.hold_s = args.hold_first_s
        original_add = rig_module.Recorder.add

        def add(self, request):
            # Read by the stand-in right after this call: only the first request is held.
            ars.hold_s = args.hold_first_s if not self.requests else 0.0
            write(
                {
                    "kind": "request",
                    "ars": request.ars,
                    "request": request.request,
                    "member": request.member_id,
                }
            )
            return original_add(self, request)

        rig_module.Recorder.add = add
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        thread = threading.Thread(target=executor.spin, daemon=True)
        thread.start()
        write({"kind": "ready", "part": args.part})
        stop.wait()
        rig_module.CLOSING.set()
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
