"""bench/system_load.py's accounting: the processes below a launcher, their CPU time, their names."""

from __future__ import annotations

import subprocess
import sys
import time

CHILD = """
import time
t = time.process_time()
while time.process_time() - t < 0.3:
    pass
time.sleep(30)
"""
PARENT = """
import subprocess, sys, time
subprocess.Popen([sys.executable, sys.argv[1]])
time.sleep(30)
"""


def test_a_child_and_its_child_are_found_timed_and_named(load_bench, tmp_path):
    bench = load_bench("system_load")
    (tmp_path / "child.py").write_text(CHILD)
    (tmp_path / "parent.py").write_text(PARENT)
    parent = subprocess.Popen([sys.executable, str(tmp_path / "parent.py"), str(tmp_path / "child.py")])
    try:
        deadline = time.monotonic() + 10
        while len(bench.descendants(parent.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        pids = bench.descendants(parent.pid)
        assert pids[0] == parent.pid and len(pids) == 2
        while bench.cpu_seconds(pids[1]) < 0.3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bench.cpu_seconds(pids[1]) >= 0.3  # the grandchild's busy loop, counted
        assert bench.label(pids[1]) == "child.py"
    finally:
        for pid in bench.descendants(parent.pid)[::-1]:
            subprocess.run(["kill", str(pid)], check=False)
        parent.wait(5)
    assert bench.cpu_seconds(parent.pid) is None  # gone
