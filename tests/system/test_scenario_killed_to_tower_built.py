"""Scenarios 5 and 6 (issue "whole system") in one run of the system, each to ``tower_built``.

The run starts late in the bay, so that the build can be finished within CI's time: the twin
scenario has every member of the one-bay mission but the last diagonal standing, riveted, and
the CRS's tower model says so (tests/system/system_run.py). What is left is that diagonal (ARS
Y's AddMember), Test Bay and the four foundation rivets.

Scenario 5: an ARS process is killed mid-action. ARS Y is killed (SIGKILL, no goodbye) while its
arm moves on the last diagonal. The launch set restarts ARS Y (restart: on-failure), and the CRS
notices a new action server that does not know its goal. That is no fault: the restarted ARS knows
from its state file what the request had done, so the CRS sends the request again by itself
(event ARS_REQUEST_RESENT, no CRS_FAULT naming ARS Y, no operator) and the diagonal is placed once.

Scenario 6: the CRS process is killed mid-build and restarted. The CRS is killed while ARS X's arm
moves on the first foundation rivet; the launch set restarts it, it comes back idle with the
tower model it persisted (the bay built), the operator starts it again, and it sends the rivet
in flight again: ARS X's running job is taken over by the new goal, not started afresh (where
ARS X finished it first, the new goal is answered from its state file, not riveted again).

Then the build goes on to ``tower_built``: every member placed and riveted, the diagonal's part at
its place in the twin, one AddMember and one FoundationRivet per foundation joint that succeeded
(the recording's goal statuses), and no second diagonal taken from its dispenser.
"""

from __future__ import annotations

import importlib.util
import os
import re
import signal
from pathlib import Path

import numpy as np
import pytest
from action_msgs.msg import GoalStatus

from tlt_common.ccsds.reasons import AckStage

_spec = importlib.util.spec_from_file_location("system_run", Path(__file__).with_name("system_run.py"))
system_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(system_run)
SystemRun = system_run.SystemRun

pytestmark = [pytest.mark.system, pytest.mark.timeout(1500)]

LAST = "bay1/diagonal/face_y1"  # ARS Y's, from diagonal_dispenser_y after face_x1's part


def _first_goal_succeeded_before_the_next(run, action: str) -> bool:
    """Whether the first goal ``action`` accepted (in flight when the CRS was killed) showed
    SUCCEEDED before the second was accepted (the restarted CRS's), from the recording."""
    accepted: dict[bytes, float] = {}
    succeeded: dict[bytes, float] = {}
    for at, status in run.recorded(f"{action}/_action/status", times=True):
        for entry in status.status_list:
            goal = bytes(entry.goal_info.goal_id.uuid)
            accepted.setdefault(goal, entry.goal_info.stamp.sec + entry.goal_info.stamp.nanosec * 1e-9)
            if entry.status == GoalStatus.STATUS_SUCCEEDED:
                succeeded.setdefault(goal, at)
    order = sorted(accepted, key=accepted.get)
    if len(order) < 2 or order[0] not in succeeded:
        return False
    return succeeded[order[0]] <= accepted[order[1]]


def test_an_ars_and_then_the_crs_killed_late_in_the_bay_and_the_tower_is_built_once(tmp_path):
    mission = system_run.load_mission(system_run.ROOT / "missions" / "one_bay.yaml")
    scenario = system_run.late_bay_scenario(mission, LAST)
    built = scenario["built"]
    with SystemRun(tmp_path / "run", scenario=scenario, rtf=0) as run:
        run.start()
        run.wait_ready()
        assert run.last("hk_mission")["members_placed"] == len(built)
        assert run.start_build().stage is AckStage.COMPLETED
        cleared = run.wait_build_moves_arm("ars_y", 150)

        # Scenario 5.
        mark = len(run.packets)
        os.kill(run.pid("ars_y"), signal.SIGKILL)
        run.wait_output("restarting ars_y", 30)
        resent = run.wait_kind(
            "event", lambda f: f["code"] == "ARS_REQUEST_RESENT", 180, "the request sent again", since=mark
        )
        assert f"AddMember for '{LAST}' on ars_y" in resent["text"], resent
        placed, more = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["members_placed"] > len(built),
            400,
            f"{LAST} placed",
            since=mark,
        )
        assert placed.fields["members_placed"] == len(built) + 1, placed.fields
        # No operator: the kill raised no fault.
        gone = [e["text"] for e in run.events(since=mark, code="CRS_FAULT") if "ars_y" in e["text"]]
        assert gone == [], gone

        # Scenario 6, once ARS X works on the first foundation rivet.
        step, later = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["member"].startswith("foundation/"),
            400,
            "the foundation rivets begun",
        )
        rivet = step.fields["member"]
        assert mission.member(rivet).add_ars == "ars_x", rivet
        run.wait_arm_moving("ars_x", 120, start=run.arm_q("ars_x")[-1], since=len(run.packets))
        os.kill(run.pid("crs"), signal.SIGKILL)
        run.wait_output("restarting crs", 30)
        mark = len(run.packets)
        again = run.wait_kind(
            "hk_mission", lambda f: not f["started"], 120, "the restarted CRS's telemetry", since=mark
        )
        assert again["members_placed"] == len(built) + 1 and again["bays_built"] == 1, again
        assert run.start_build().stage is AckStage.COMPLETED  # the operator starts it again

        done, rest = run.wait_through_faults(
            lambda p: p.kind == "hk_mission" and p.fields["run_state"] == "done",
            900,
            "the mission done",
            since=mark,
        )
        hk = done.fields
        members = len(mission.members)
        assert hk["members_placed"] == hk["members_riveted"] == hk["members_total"] == members, hk
        run.poll(3.0)  # the recorder writes asynchronously: give it the last goal statuses
        assert run.stop() == 0

    faults = cleared + more + later + rest
    # Each request succeeded once at its ARS: the diagonal and each foundation rivet. Where ARS X
    # finished the rivet in flight before the restarted CRS sent it again (a fast machine, the twin
    # uncapped), that goal succeeded and the new one was answered from ARS X's state file: one more.
    assert run.goals_succeeded("/ars_y/add_member") == 1, faults
    for ars in ("ars_x", "ars_y"):
        rivets = sum(m.kind == "foundation_rivet" and m.add_ars == ars for m in mission.members)
        again = ars == "ars_x" and _first_goal_succeeded_before_the_next(run, "/ars_x/foundation_rivet")
        assert run.goals_succeeded(f"/{ars}/foundation_rivet") == rivets + again, (ars, again, faults)
    # ... and each foundation joint was riveted once (the twin joins a rivet to a pad when it fires).
    joined = re.findall(r"rivet gun \w fired at [\d.]+ s: joined (foundation/\d+)/", run.launch_output())
    pads = sum(m.kind == "foundation_rivet" for m in mission.members)
    assert len(joined) == len(set(joined)) == pads, joined
    # The dispenser gave the diagonal once (and any part discarded after a failed inspection).
    dispenser = mission.member(LAST).dispenser
    model = run.tower_model()["dispensers"][dispenser]
    earlier = sum(mission.member(m).dispenser == dispenser for m in built)
    assert mission.dispensers[dispenser].count - model["remaining"] == earlier + 1 + model["discarded"], model
    # In the twin, a part taken after the built ones stands at the diagonal's place (a part's body
    # frame sits at one of its ends).
    last = run.last_ground_truth()
    ends = [last["tower"] + np.asarray(p) for _, p in mission.member(LAST).joints]
    taken = range(earlier, mission.dispensers[dispenser].count - model["remaining"])
    off = {i: min(float(np.linalg.norm(last[f"part/{dispenser}/{i}"] - e)) for e in ends) for i in taken}
    assert min(off.values()) < 0.01, off
