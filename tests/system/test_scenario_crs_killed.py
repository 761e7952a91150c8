"""Scenario 6 (issue "whole system"): the CRS process is killed mid-bay and restarted; it resumes
from its persisted model.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py).
Once the cross frame is placed and an ARS is fetching the first vertical, the CRS is killed
(SIGKILL: no goodbye, its in-flight goal orphaned on the ARS). The launch set restarts it
(restart: on-failure); it comes back idle with the tower model it persisted (the cross frame
placed), and the operator starts it again from the ground. Then:
- the cross frame is not requested again (one AddCrossFrame goal in the recording);
- the vertical that was in flight is requested again, and the ARS's running job is taken over by
  the new goal instead of being refused as busy or started afresh: it is placed once, and the
  orphaned goal ends superseded;
- no part is discarded (a part shown to the CRS while it was down is kept and shown again).
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

SUCCEEDED, ABORTED = 4, 6  # action_msgs/GoalStatus
FETCHING_VERTICAL = "Wait For Part bay1/vertical/"  # the CRS's step while an ARS fetches a vertical


def _final_statuses(run: SystemRun, topic: str) -> dict[bytes, int]:
    last: dict[bytes, int] = {}
    for status in run.recorded(topic):
        for entry in status.status_list:
            last[bytes(entry.goal_info.goal_id.uuid)] = entry.status
    return last


def test_the_crs_killed_mid_bay_restarts_and_resumes_from_its_persisted_model(tmp_path):
    with SystemRun(tmp_path / "run") as run:
        run.start()
        run.wait_ready()
        assert run.start_build().stage is AckStage.COMPLETED
        _, cleared = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["members_placed"] >= 1, 300,
            "the cross frame placed", clear_faults=2)
        fetching, _ = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["step"].startswith(FETCHING_VERTICAL),
            120, "a vertical requested", clear_faults=2)
        member = fetching.fields["member"]

        os.kill(run.pid("crs"), signal.SIGKILL)
        run.wait_output("restarting crs", 30)
        mark = len(run.packets)
        back = run.wait_kind("hk_mission", lambda f: not f["started"], 120, "the restarted CRS's telemetry",
                             since=mark)
        assert back["members_placed"] == 1, back  # what it persisted: the cross frame stands
        assert run.start_build().stage is AckStage.COMPLETED  # the operator starts it again
        done, more = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["members_placed"] >= 2, 400,
            f"{member} placed after the restart", since=mark)
        assert done.fields["parts_discarded"] == 0, done.fields
        run.poll(2.0)
        assert run.stop() == 0

    faults = cleared + more
    cross_frame = _final_statuses(run, "/ars_x/add_cross_frame/_action/status")
    assert len(cross_frame) == 1 + len(cleared), (cross_frame, faults)  # not requested again
    spec = load_mission(system_run.ROOT / "missions" / "one_bay.yaml").member(member)
    model = json.loads((run.run_dir / "tower_model.json").read_text())
    assert model["members"][member] in ("PLACED", "RIVETED", "INSPECTED"), model["members"]
    statuses = _final_statuses(run, f"/{spec.add_ars}/add_member/_action/status")
    succeeded = [s for s in statuses.values() if s == SUCCEEDED]
    # The orphaned goal was superseded (aborted) by the new CRS's, which succeeded: placed once.
    assert ABORTED in statuses.values() and len(succeeded) >= 1, (statuses, faults)
    assert model["dispensers"][spec.dispenser]["discarded"] == 0, model["dispensers"]
