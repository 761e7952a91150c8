"""Scenario 3 (issue "whole system"): Stop during the build. The CRS acknowledges the ground's
Stop, the lifter goes to Safe, the arms stop, and the CRS and both ARS processes exit cleanly.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py);
Stop is sent while ARS X's arm moves on the first request of the build (AddCrossFrame). The
lifter's and the arms' own state topics are read back from the run's MCAP recording, which the
recorder keeps writing after the CRS and the ARSs have gone.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tlt_common.ccsds.reasons import AckStage

# The harness next to this file (tests are collected in importlib mode: no package to import from).
_spec = importlib.util.spec_from_file_location("system_run", Path(__file__).with_name("system_run.py"))
system_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(system_run)
SystemRun = system_run.SystemRun

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

STILL_RAD_S = 1e-3


def test_stop_during_the_build_makes_everything_safe_and_exits_cleanly(tmp_path):
    with SystemRun(tmp_path / "run") as run:
        run.start()
        run.wait_ready()
        assert run.start_build().stage is AckStage.COMPLETED
        run.wait_kind("hk_mission", lambda f: f["run_state"] == "running", 30, "the build running")
        run.wait_build_moves_arm("ars_x", 150)

        mark = len(run.packets)
        ack = run.command("stop", timeout=60)
        assert (ack.stage, ack.reason.name) == (AckStage.COMPLETED, "NONE"), ack
        assert run.events(since=mark, code="STOPPING"), run.events(since=mark)
        run.wait_kind("hk_mission", lambda f: f["run_state"] == "stopped" and not f["started"], 10,
                      "run state stopped", since=mark)
        # The stopping CRS sends its devices' last states home before it exits: the operator
        # sees the lifter in Safe.
        run.wait_kind("hk_lifter", lambda f: f["state"] in ("safe", 3), 30, "the lifter in Safe (ground)",
                      since=mark)
        lifter_after = [f["state"] for f in run.of_kind("hk_lifter", since=mark)]

        for name in ("crs", "ars_x", "ars_y"):
            run.wait_output(f"[launch] {name} exited with exit code 0", 60)
        output = run.launch_output()
        for name in ("crs", "ars_x", "ars_y"):
            assert f"[launch] {name} exited with exit code 0 during start-up" not in output
            assert f"restarting {name}" not in output
        assert run.stop() == 0

    # The recorder wrote the drivers' topics until the launcher stopped it, after the CRS and the
    # ARSs had exited: their last messages are where Stop left the machine.
    lifter = run.recorded("/lifter/state")
    assert lifter, "no /lifter/state in the recording"
    assert lifter[-1].state == 3, f"lifter state {lifter[-1].state} (3 is Safe); hk_lifter: {lifter_after}"
    for ars in ("ur_x", "ur_y"):
        joints = run.recorded(f"/{ars}/joint_states")
        assert joints, f"no /{ars}/joint_states in the recording"
        assert max(abs(v) for v in joints[-1].velocity) < STILL_RAD_S, joints[-1]
    # ARS X was moving when Stop came: the recording shows it, so the arm did stop.
    moving = [m for m in run.recorded("/ur_x/joint_states") if max(abs(v) for v in m.velocity) > 0.01]
    assert moving, "ARS X's arm never moved: Stop was not sent during a motion"
