"""Scenario 9 (issue "whole system"): Set Blackboard Value changes a writable mission parameter
at run time, the change shows in telemetry, and the CRS tree uses it.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py).
The parameter is ``cross_frame_ars`` (config/crs/writable_blackboard.yaml): which ARS fetches
and places the cross frame, the mission's ARS X by default. The CRS tree reads it when it sends
AddCrossFrame (tlt_crs.tree, the request's ARS callable). Written to ``ars_y`` from the ground
before Start (acknowledged, and reported by a BLACKBOARD_SET event), the first request of the
build goes to ARS Y: ARS Y's AddCrossFrame server receives the goal and ARS X's none (their goal
status topics in the run's MCAP recording). A write the registry refuses (a value outside the
key's choices) is rejected and not reported as set.
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


def test_set_blackboard_value_changes_the_ars_the_tree_sends_the_cross_frame_to(tmp_path):
    with SystemRun(tmp_path / "run") as run:
        run.start()
        run.wait_ready()

        refused = run.command("set_blackboard_value", {"key": "cross_frame_ars", "value": "ars_z"})
        assert refused.stage is AckStage.REJECTED and "cross_frame_ars" in refused.detail, refused
        mark = len(run.packets)
        ack = run.command("set_blackboard_value", {"key": "cross_frame_ars", "value": "ars_y"})
        assert (ack.stage, ack.reason.name) == (AckStage.COMPLETED, "NONE"), ack
        event = run.wait_kind(
            "event", lambda f: f["code"] == "BLACKBOARD_SET", 20, "the BLACKBOARD_SET event", since=mark
        )
        assert event["text"] == "cross_frame_ars = 'ars_y'", event
        assert len(run.events(code="BLACKBOARD_SET")) == 1, "the refused write was reported as set"

        assert run.start_build().stage is AckStage.COMPLETED
        # The request is sent and accepted: the CRS waits for the part, or ARS Y already failed it
        # (a fault names the ARS the request went to).
        run.wait_kind(
            "mission_step",
            lambda f: f["step"].startswith("Wait For Part bay1/cross_frame") or f["run_state"] == "fault",
            90,
            "AddCrossFrame accepted by an ARS",
        )
        faults = [f["text"] for f in run.events() if f["code"] == "CRS_FAULT"]
        assert all("on ars_y" in text for text in faults if "AddCrossFrame" in text), faults
        run.poll(3.0)  # the recorder subscribes and writes asynchronously: give it the goal's status
        assert run.stop() == 0

    # Each ARS's action server as the recording saw it: the goal went to ARS Y, none to ARS X.
    def goals(ars: str) -> set[bytes]:
        return {
            bytes(entry.goal_info.goal_id.uuid)
            for status in run.recorded(f"/{ars}/add_cross_frame/_action/status")
            for entry in status.status_list
        }

    assert len(goals("ars_y")) == 1, "ARS Y did not receive the AddCrossFrame goal"
    assert goals("ars_x") == set(), "ARS X received an AddCrossFrame goal"
