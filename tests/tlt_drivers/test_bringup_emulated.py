"""Every driver runs as a ROS node against its emulated device from a launch set, and each
mechanism moves through its driver's ROS interfaces: the bring-up check passes end to end."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TLT = Path(sys.executable).with_name("tlt")


def test_bringup_check_passes_against_every_emulated_device(tmp_path):
    env = {**os.environ, "TLT_RUN_DIR": str(tmp_path / "run")}
    result = subprocess.run(
        [str(TLT), "launch", str(ROOT / "config/launch/bringup_emulated.yaml")],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    output = result.stdout + result.stderr
    # The failed checks first: the tail of a long run may not reach back to them.
    failed = "\n".join(line for line in output.splitlines() if "FAIL" in line)
    assert result.returncode == 0, f"{failed}\n...\n{output[-6000:]}"
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
    # The emulators published their links in the run's own folder and removed them on the way out.
    assert not list((tmp_path / "run").glob("lifter*"))
