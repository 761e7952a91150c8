"""The CRS process tests' stand-ins (``tests/tlt_crs/conftest.py``) in a process of their own, for
the mission job's end-to-end test: stand-in lifter, grippers, cameras, vision and both ARSs.

``mission_rig_process.py RECORD [--fail-part MEMBER]``: every ARS request is appended to RECORD as
a JSON line (``{"kind": "request", "ars", "request", "member"}``); with ``--fail-part`` the first
part presented for MEMBER fails inspection (the ARS discards it and presents another, which
passes). Writes ``{"kind": "ready"}`` once serving; runs until SIGTERM.
"""

from __future__ import annotations

import argparse
import importlib.util
import signal
import sys
import threading
from pathlib import Path

import rclpy

from tlt_common.json_lines import JsonLinesWriter

CRS_RIG = Path(__file__).resolve().parents[1] / "tlt_crs" / "conftest.py"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("record", type=Path)
    parser.add_argument("--fail-part", action="append", default=[])
    args = parser.parse_args()
    spec = importlib.util.spec_from_file_location("crs_rig", CRS_RIG)
    rig_module = importlib.util.module_from_spec(spec)
    sys.modules["crs_rig"] = rig_module  # dataclasses look their module up there
    spec.loader.exec_module(rig_module)
    write = JsonLinesWriter(args.record).append

    original_add = rig_module.Recorder.add

    def add(self, request):
        entry = {"ars": request.ars, "request": request.request, "member": request.member_id}
        write({"kind": "request", **entry})
        return original_add(self, request)

    rig_module.Recorder.add = add
    rclpy.init()
    rig = rig_module.Rig()
    for member in args.fail_part:
        rig.vision.part_verdicts[member] = [False]
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    write({"kind": "ready"})
    stop.wait()
    rig.close()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
