"""The bring-up check passes against the twin: every driver node opens the twin's links, each
mechanism moves in MuJoCo through its real driver, and the state comes back. The twin runs at the
launch set's default real-time factor (1); on a loaded machine it falls behind and waits for late
drivers (tlt_sim.twin.simulation), which test_driver_pace.py tests on its own."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
TLT = Path(sys.executable).with_name("tlt")


def test_bringup_check_passes_against_the_twin(tmp_path):
    env = {
        **os.environ,
        "TLT_RUN_DIR": str(tmp_path / "run"),
        # Away from the addresses a stand-alone emulator run or a developer's twin serves.
        "TLT_UR_X_HOST": "127.0.77.2",
        "TLT_UR_Y_HOST": "127.0.77.3",
    }
    result = subprocess.run(
        [str(TLT), "launch", str(ROOT / "config/launch/bringup_twin.yaml")],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    output = result.stdout + result.stderr
    # The failed checks first, then what their drivers logged: the tail of a long run may not reach
    # back to them.
    lines = output.splitlines()
    failed = [line for line in lines if "FAIL" in line]
    prefixes = {f"[{line.split()[2]}]" for line in failed if line.startswith("[bringup_check]")}
    own = [line for line in lines if line.split(" ", 1)[0] in prefixes]
    assert result.returncode == 0, "\n".join(
        [*failed, "... what the failed components logged:", *own[-80:], "...", output[-6000:]]
    )
    assert "[bringup_check] bring-up check: 27 of 27 checks passed" in output, output[-6000:]
    for component in (
        "lifter",
        "top_grippers",
        "active_grippers",
        "camera_mounts",
        "ee_x",
        "ee_y",
        "ur_x",
        "ur_y",
    ):
        assert f"ok   {component:<16} driver up" in output
    # The rivet gun pulse of each EE reached the model (no rivet loaded: a dry shot).
    assert re.search(r"\[twin\] twin: ars_x rivet gun a fired at [\d.]+ s: dry shot", output)
    assert re.search(r"\[twin\] twin: ars_y rivet gun a fired at [\d.]+ s: dry shot", output)
    # The twin withdrew its links on the way out.
    assert not [p for p in (tmp_path / "run").iterdir() if p.is_symlink()]
    assert not (tmp_path / "run" / "twin.ready").exists()
    assert "[twin] twin: links up" in output
