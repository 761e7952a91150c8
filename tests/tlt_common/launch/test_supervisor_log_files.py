"""The launcher's log files: each process's output, and the launcher's lines about it, in
``<log folder>/<name>.log`` as well as on the console; a restart appends, a new run starts afresh."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from tlt_common.launch.launch_set import load_launch_set
from tlt_common.launch.supervisor import Supervisor, default_log_dir

TLT = Path(sys.executable).with_name("tlt")

# Fails on its first run and prints to stdout; its restart succeeds.
ONCE = """
import pathlib, sys
mark = pathlib.Path(sys.argv[1])
first = not mark.exists()
mark.touch()
print("run", "first" if first else "second", flush=True)
sys.exit(3 if first else 0)
"""


def test_each_process_writes_its_own_log_file_beside_the_console(tmp_path):
    path = tmp_path / "set.yaml"
    path.write_text(
        textwrap.dedent(
            f"""
            processes:
              - name: flaky
                executable: python
                args: ["-c", {json.dumps(ONCE)}, "{tmp_path / "mark"}"]
                restart: on-failure
                restart_delay_s: 0.1
              - name: quiet
                executable: python
                args: ["-c", "import sys; print('to stderr', file=sys.stderr)"]
            """
        )
    )
    logs = tmp_path / "run" / "logs"
    logs.mkdir(parents=True)
    (logs / "flaky.log").write_text("a line of an earlier run\n")
    console = io.StringIO()
    assert Supervisor(load_launch_set(path), out=console, log_dir=logs).run() == 0

    flaky = (logs / "flaky.log").read_text().splitlines()
    assert [line for line in flaky if not line.startswith("[launch] started flaky (pid ")] == [
        "run first",
        "[launch] flaky exited with exit code 3 during start-up",
        "[launch] restarting flaky (1 of 5)",
        "run second",
        "[launch] flaky exited with exit code 0 during start-up",
    ]
    assert sum(line.startswith("[launch] started flaky (pid ") for line in flaky) == 2
    assert (logs / "quiet.log").read_text().splitlines()[1:] == [
        "to stderr",
        "[launch] quiet exited with exit code 0 during start-up",
    ]
    out = console.getvalue().splitlines()
    assert "[flaky] run first" in out and "[flaky] run second" in out and "[quiet] to stderr" in out
    assert f"[launch] each process's output also goes to {logs}/<name>.log" in out


def test_without_a_log_folder_no_file_is_written(tmp_path):
    path = tmp_path / "set.yaml"
    path.write_text("processes:\n  - {name: a, executable: python, args: [-c, \"print('hi')\"]}\n")
    console = io.StringIO()
    assert Supervisor(load_launch_set(path), out=console).run() == 0
    assert "[a] hi" in console.getvalue().splitlines()
    assert "output also goes to" not in console.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["set.yaml"]


def test_the_default_folder_is_the_run_folders_logs():
    assert default_log_dir({"TLT_RUN_DIR": "/data/run7"}) == Path("/data/run7/logs")
    assert default_log_dir({}) == Path("/tmp/tlt-run/logs")


def test_tlt_launch_writes_to_the_run_folder_and_refuses_a_bad_log_level(tmp_path):
    path = tmp_path / "set.yaml"
    path.write_text("processes:\n  - {name: a, executable: python, args: [-c, \"print('hi')\"]}\n")
    env = {**os.environ, "TLT_RUN_DIR": str(tmp_path / "run")}
    env.pop("TLT_LOG_LEVEL", None)
    result = subprocess.run(
        [str(TLT), "launch", str(path)], env=env, capture_output=True, text=True, timeout=30
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "hi" in (tmp_path / "run" / "logs" / "a.log").read_text().splitlines()

    env["TLT_LOG_LEVEL"] = "loud"
    result = subprocess.run(
        [str(TLT), "launch", str(path)], env=env, capture_output=True, text=True, timeout=30
    )
    assert result.returncode == 2
    assert "tlt launch: TLT_LOG_LEVEL='loud' is no log level" in result.stderr
    assert "[launch] started" not in result.stdout
