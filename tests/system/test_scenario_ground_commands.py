"""Scenarios 2, 8 and 3 (issue "whole system") in one run of the system, one after the other, as
an operator would meet them (a start of the whole system costs about half a minute, and CI's time
is short). They act while ARS X's arm moves on the first request of the build (AddCrossFrame of
the cross frame).

Scenario 2, as far as it can be judged before a tower is built: Pause while an ARS works on a
member holds the arm where it stands; Resume continues the same request, and nothing is sent
again. Paused, the run state is ``paused`` and the arm stands still (``hk_arm_joints``); resumed,
the arm moves on from there, the CRS does not send the request again (no second "Send
AddCrossFrame" step in ``mission_step``) and ARS X's action server saw exactly one goal (its goal
status topic in the run's MCAP recording). Should the build fault before the arm first moves (an
end-effector servo missing a read on this loaded machine), the harness clears the fault from the
ground and the tree sends the request again: that goal is counted as the retry it is.

Scenario 8: a ground command that is unauthenticated, replayed or out of range is rejected and
reported, and the build is unaffected. The ground sends
- a Pause signed with a key the CRS does not hold, from a socket of its own;
- an out-of-range Set Blackboard Value (``inspection_attempts`` = 9, the registry allows 1-5);
- scenario 2's Pause, accepted and answered by a Resume, sent again byte for byte (a replay).
Each is acknowledged REJECTED with its reason at the ground station's telemetry address and
reported as a COMMAND_REJECTED event; none is acted on: the run state never turns paused after
the genuine Resume, the CRS tree keeps ticking and the CRS process keeps running.

Scenario 3: Stop while the build goes on. The CRS acknowledges it, the lifter goes to Safe, the
arms stop, and the CRS and both ARS processes exit cleanly. The lifter's and the arms' own state
topics are read back from the recording, which the recorder keeps writing after the CRS and the
ARSs have gone.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py).
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_gsw.link import GswLink

# The harness next to this file (tests are collected in importlib mode: no package to import from).
_spec = importlib.util.spec_from_file_location("system_run", Path(__file__).with_name("system_run.py"))
system_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(system_run)
SystemRun = system_run.SystemRun

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

STILL_RAD_S = 1e-3


def _rejection_ack(run: SystemRun, security_seq: int, since: int):
    return run.wait_kind(
        "ack",
        lambda f: f["security_seq"] == security_seq and f["stage"] == "rejected",
        20,
        f"the rejection ack of security sequence {security_seq}",
        since=since,
    )


def test_pause_and_resume_then_bad_commands_then_stop(tmp_path):
    with SystemRun(tmp_path / "run") as run:
        run.start()
        run.wait_ready()
        assert run.start_build().stage is AckStage.COMPLETED
        run.wait_kind("hk_mission", lambda f: f["run_state"] == "running", 30, "the build running")
        cleared = run.wait_build_moves_arm("ars_x", 150)

        # Scenario 2: Pause, then Resume.
        pause = run.send("pause")  # kept: scenario 8 sends it again
        assert run.link.wait_ack(pause, final=True, timeout=30).stage is AckStage.COMPLETED
        run.wait_kind("hk_mission", lambda f: f["run_state"] == "paused", 20, "paused")
        held = run.wait_arm_still("ars_x", 30)
        # Held: a few more seconds of telemetry find the arm where it stopped.
        since = len(run.packets)
        run.poll(3.0)
        later = run.arm_q("ars_x", since=since)
        assert later and all(max(abs(a - b) for a, b in zip(q, held, strict=True)) < 2e-3 for q in later)

        mark = len(run.packets)
        assert run.command("resume", timeout=30).stage is AckStage.COMPLETED
        run.wait_arm_moving("ars_x", 60, start=held, tolerance=2e-3, since=mark)
        steps = [f["step"] for f in run.of_kind("mission_step", since=mark)]
        assert not [s for s in steps if s.startswith("Send AddCrossFrame")], steps

        # Scenario 8: bad commands, while the build goes on.
        # 1. Unauthenticated: the right key id, the wrong key. The sender hears nothing; the
        # ground station (the CRS's telemetry address) gets the rejection and the event.
        mark = len(run.packets)
        intruder = GswLink(run.defs, KeyRing({1: os.urandom(32)}), 1, ("127.0.0.1", run.crs_port))
        where = f"{intruder.address[0]}:{intruder.address[1]}"
        try:
            forged = intruder.send_command("pause")
            ack = _rejection_ack(run, forged.security_seq, mark)
            assert ack["reason"] == "bad_auth", ack
            intruder_heard = intruder.poll(1.0)
        finally:
            intruder.close()
        assert intruder_heard == [], "the CRS answered an unauthenticated sender"
        event = run.wait_kind(
            "event",
            lambda f: f["code"] == "COMMAND_REJECTED" and where in f["text"],
            20,
            "the event reporting the forged command",
            since=mark,
        )
        assert (event["severity"], event["reason"]) == ("warning", "bad_auth"), event

        # 2. Out of range: rejected with the registry's reason, never written.
        mark = len(run.packets)
        ack = run.command("set_blackboard_value", {"key": "inspection_attempts", "value": 9})
        assert ack.stage is AckStage.REJECTED and "inspection_attempts" in ack.detail, ack
        assert ack.reason in (Reason.REFUSED, Reason.BAD_PARAMETER_RANGE), ack
        event = run.wait_kind(
            "event",
            lambda f: f["code"] == "COMMAND_REJECTED" and "inspection_attempts" in f["text"],
            20,
            "the event reporting the out-of-range value",
            since=mark,
        )
        assert event["reason"] == ack.reason.name.lower(), event

        # 3. Replay: scenario 2's Pause, carried out and answered by a Resume, sent again.
        mark = len(run.packets)
        run.link.send_raw(pause.raw)
        ack = _rejection_ack(run, pause.security_seq, mark)
        assert ack["reason"] == "replay", ack
        event = run.wait_kind(
            "event",
            lambda f: f["code"] == "COMMAND_REJECTED" and f["reason"] == "replay",
            20,
            "the event reporting the replay",
            since=mark,
        )
        assert event["severity"] == "warning"

        # The build is unaffected: a few more seconds of telemetry show no pause, no stop, no
        # blackboard write, the CRS tree still ticking and the CRS process still there.
        ticks_before = max(f["tick"] for f in run.of_kind("tree_status") if f["agent"] == "crs")
        run.poll(5.0)
        states = [f["run_state"] for f in run.of_kind("hk_mission", since=mark)]
        assert states and "paused" not in states and "stopped" not in states, states
        codes = {f["code"] for f in run.events(since=mark)}
        assert not codes & {"PAUSED", "STOPPING", "BLACKBOARD_SET"}, codes
        ticks_after = max(f["tick"] for f in run.of_kind("tree_status") if f["agent"] == "crs")
        assert ticks_after > ticks_before
        stats = run.last("link_stats")
        assert stats is not None and stats["rejections"] >= 3, stats
        assert "[launch] crs exited" not in run.launch_output()

        # Scenario 3: Stop while the build goes on.
        mark = len(run.packets)
        ack = run.command("stop", timeout=60)
        assert (ack.stage, ack.reason.name) == (AckStage.COMPLETED, "NONE"), ack
        assert run.events(since=mark, code="STOPPING"), run.events(since=mark)
        run.wait_kind(
            "hk_mission",
            lambda f: f["run_state"] == "stopped" and not f["started"],
            10,
            "run state stopped",
            since=mark,
        )
        # The stopping CRS sends its devices' last states home before it exits: the operator
        # sees the lifter in Safe.
        run.wait_kind(
            "hk_lifter", lambda f: f["state"] in ("safe", 3), 30, "the lifter in Safe (ground)", since=mark
        )
        lifter_after = [f["state"] for f in run.of_kind("hk_lifter", since=mark)]
        for name in ("crs", "ars_x", "ars_y"):
            run.wait_output(f"[launch] {name} exited with exit code 0", 60)
        output = run.launch_output()
        for name in ("crs", "ars_x", "ars_y"):
            assert f"[launch] {name} exited with exit code 0 during start-up" not in output
            assert f"restarting {name}" not in output
        assert run.stop() == 0

    # Scenario 2 in the recording: one goal, and one more for each fault cleared before the arm
    # first moved (the tree sends the failed request again): none for the pause.
    goals = set()
    for status in run.recorded("/ars_x/add_cross_frame/_action/status"):
        for entry in status.status_list:
            goals.add(bytes(entry.goal_info.goal_id.uuid))
    assert len(goals) == 1 + len(cleared), f"ARS X received {len(goals)} AddCrossFrame goals; {cleared}"

    # Scenario 3: the recorder wrote the drivers' topics until the launcher stopped it, after the
    # CRS and the ARSs had exited: their last messages are where Stop left the machine.
    lifter = run.recorded("/lifter/state")
    assert lifter, "no /lifter/state in the recording"
    assert lifter[-1].state == 3, f"lifter state {lifter[-1].state} (3 is Safe); hk_lifter: {lifter_after}"
    for ars in ("ur_x", "ur_y"):
        joints = run.recorded(f"/{ars}/joint_states")
        assert joints, f"no /{ars}/joint_states in the recording"
        assert max(abs(v) for v in joints[-1].velocity) < STILL_RAD_S, joints[-1]
    # ARS X moved in the build: the recording shows it, so the arm did stop.
    moving = [m for m in run.recorded("/ur_x/joint_states") if max(abs(v) for v in m.velocity) > 0.01]
    assert moving, "ARS X's arm never moved: Stop was not sent during a motion"
