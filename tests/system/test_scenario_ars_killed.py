"""Scenario 5 (issue "whole system"): an ARS process is killed mid-action. The CRS raises a fault
and waits for help, the launcher restarts the ARS, the operator clears the fault from the GSW, and
the build goes on with no member placed twice.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py).
ARS X is killed (SIGKILL, no goodbye) while its arm moves on the build's first request, the cross
frame's AddCrossFrame. The CRS must notice the action server gone and fault with that reason
(CRS_FAULT); the launch set restarts ARS X (restart: on-failure); the fault stays until the ground
clears it, after the ARS is back; then the CRS sends the request again and the cross frame is
placed once: one placement in the mission telemetry, one AddCrossFrame that succeeded in the
recording, one cross frame taken from its dispenser in the persisted tower model.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
from pathlib import Path

import pytest

from tlt_common.ccsds.reasons import AckStage
from tlt_common.mission.schema import load_mission

_spec = importlib.util.spec_from_file_location("system_run", Path(__file__).with_name("system_run.py"))
system_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(system_run)
SystemRun = system_run.SystemRun

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]

SUCCEEDED = 4  # action_msgs/GoalStatus


def test_an_ars_killed_mid_action_faults_restarts_and_the_build_goes_on_once(tmp_path):
    with SystemRun(tmp_path / "run") as run:
        run.start()
        run.wait_ready()
        assert run.start_build().stage is AckStage.COMPLETED
        cleared = run.wait_build_moves_arm("ars_x", 150)

        mark = len(run.packets)
        os.kill(run.pid("ars_x"), signal.SIGKILL)
        fault = run.wait_kind("event", lambda f: f["code"] == "CRS_FAULT", 90, "the CRS's fault", since=mark)
        assert "ARS 'ars_x' gone while running AddCrossFrame" in fault["text"], fault
        run.wait_output("restarting ars_x", 30)
        back = len(run.packets)
        run.wait_kind("tree_status", lambda f: f["agent"] == "ars_x", 120, "the restarted ARS X ticking",
                      since=back)
        run.poll(2.0)
        # Waiting for help: the ARS is back, but nothing clears the fault but the operator.
        assert run.last("hk_mission")["run_state"] == "fault", run.last("hk_mission")

        ack = run.command("set_blackboard_value", {"key": "clear_fault", "value": True})
        assert ack.stage is AckStage.COMPLETED, ack
        done, more = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["members_placed"] >= 1, 400,
            "the cross frame placed", since=len(run.packets))
        assert done.fields["members_placed"] == 1, done.fields
        run.poll(2.0)
        assert run.stop() == 0

    succeeded = set()
    for status in run.recorded("/ars_x/add_cross_frame/_action/status"):
        for entry in status.status_list:
            if entry.status == SUCCEEDED:
                succeeded.add(bytes(entry.goal_info.goal_id.uuid))
    assert len(succeeded) == 1, f"{len(succeeded)} AddCrossFrame goals succeeded; cleared {cleared}, {more}"
    mission = load_mission(system_run.ROOT / "missions" / "one_bay.yaml")
    dispenser = mission.member("bay1/cross_frame").dispenser
    model = json.loads((run.run_dir / "tower_model.json").read_text())
    taken = mission.dispensers[dispenser].count - model["dispensers"][dispenser]["remaining"]
    assert taken == 1 + model["dispensers"][dispenser]["discarded"], model["dispensers"]
