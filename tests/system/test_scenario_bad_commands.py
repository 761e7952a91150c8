"""Scenario 8 (issue "whole system"): a ground command that is unauthenticated, replayed or out
of range is rejected and reported, and the build is unaffected.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py).
While ARS X works on the first request of the build, the ground sends
- a Pause signed with a key the CRS does not hold, from a socket of its own;
- an out-of-range Set Blackboard Value (``inspection_attempts`` = 9, the registry allows 1-5);
- a Pause that was accepted and answered by a Resume, sent again byte for byte (a replay).
Each is acknowledged REJECTED with its reason at the ground station's telemetry address and
reported as a COMMAND_REJECTED event; none is acted on: the run state never turns paused after
the genuine Resume, the CRS tree keeps ticking and the CRS process keeps running.
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


def _rejection_ack(run: SystemRun, security_seq: int, since: int):
    return run.wait_kind("ack", lambda f: f["security_seq"] == security_seq and f["stage"] == "rejected",
                         20, f"the rejection ack of security sequence {security_seq}", since=since)


def test_bad_ground_commands_are_rejected_reported_and_change_nothing(tmp_path):
    with SystemRun(tmp_path / "run") as run:
        run.start()
        run.wait_ready()
        assert run.start_build().stage is AckStage.COMPLETED
        run.wait_kind("hk_mission", lambda f: f["run_state"] == "running", 30, "the build running")
        run.wait_build_moves_arm("ars_x", 150)

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
        event = run.wait_kind("event", lambda f: f["code"] == "COMMAND_REJECTED" and where in f["text"],
                              20, "the event reporting the forged command", since=mark)
        assert (event["severity"], event["reason"]) == ("warning", "bad_auth"), event

        # 2. Out of range: rejected with the registry's reason, never written.
        mark = len(run.packets)
        ack = run.command("set_blackboard_value", {"key": "inspection_attempts", "value": 9})
        assert ack.stage is AckStage.REJECTED and "inspection_attempts" in ack.detail, ack
        assert ack.reason in (Reason.REFUSED, Reason.BAD_PARAMETER_RANGE), ack
        event = run.wait_kind("event", lambda f: f["code"] == "COMMAND_REJECTED"
                              and "inspection_attempts" in f["text"], 20,
                              "the event reporting the out-of-range value", since=mark)
        assert event["reason"] == ack.reason.name.lower(), event

        # 3. Replay: a Pause that was carried out, answered by a Resume, then sent again.
        pause = run.send("pause")
        assert run.link.wait_ack(pause, final=True, timeout=30).stage is AckStage.COMPLETED
        run.wait_kind("hk_mission", lambda f: f["run_state"] == "paused", 20, "paused")
        assert run.command("resume", timeout=30).stage is AckStage.COMPLETED
        run.wait_kind("hk_mission", lambda f: f["run_state"] != "paused", 20, "running again")
        mark = len(run.packets)
        run.link.send_raw(pause.raw)
        ack = _rejection_ack(run, pause.security_seq, mark)
        assert ack["reason"] == "replay", ack
        event = run.wait_kind("event", lambda f: f["code"] == "COMMAND_REJECTED" and f["reason"] == "replay",
                              20, "the event reporting the replay", since=mark)
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
