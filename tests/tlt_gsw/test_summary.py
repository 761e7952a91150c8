"""The mission summary and timeline of a hand-made archive: real encoded packets, known times."""

from __future__ import annotations

import io
import os

import pytest

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import encode_command, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_gsw import cli
from tlt_gsw.archive import Recorder
from tlt_gsw.summary import format_summary, summarize_file
from tlt_gsw.timeline_plot import category, plot_timeline, timeline_origin

DEFS = load_definitions()
KEY = os.urandom(32)
FAULT = "Wait For AddCrossFrame bay2/cross_frame: AddCrossFrame on ars_x failed: server vanished"


class Archive:
    """Writes real packets into a Recorder with chosen receive times."""

    def __init__(self, path):
        self.rec = Recorder(path)
        self.seq = 0

    def tm(self, wall: float, kind: str, values: dict) -> None:
        self.seq += 1
        raw = encode_telemetry(DEFS, kind, values, seq_count=self.seq, timestamp=wall)
        self.rec.record("rx", raw, parse_datagram(raw, DEFS, expect="tm"), recorded_at=wall)

    def step(self, wall, sim, state, bay, member, step, built, placed, discarded) -> None:
        self.tm(wall, "mission_step", {
            "sim_time": sim, "run_state": state, "bay": bay, "member": member, "step": step,
            "bays_built": built, "members_placed": placed, "parts_discarded": discarded,
        })  # fmt: skip

    def event(self, wall, severity, code, text) -> None:
        values = {"severity": severity, "source": "crs", "code": code, "reason": "none", "text": text}
        self.tm(wall, "event", values)

    def command(self, wall, name, params, security_seq, *stages) -> None:
        self.seq += 1
        raw = encode_command(
            DEFS, name, params, key_id=1, key=KEY, security_seq=security_seq, seq_count=self.seq,
            timestamp=wall,
        )  # fmt: skip
        parsed = parse_datagram(raw, DEFS, expect="tc", keyring=KeyRing({1: KEY}))
        self.rec.record("tx", raw, parsed, recorded_at=wall)
        for i, (stage, reason, detail) in enumerate(stages):
            self.tm(wall + 0.01 * (i + 1), "ack", {
                "command_apid": DEFS.command_apid, "command_seq_count": self.seq,
                "security_seq": security_seq, "command": name, "stage": stage, "reason": reason,
                "detail": detail,
            })  # fmt: skip

    def close(self) -> None:
        self.rec.close()


@pytest.fixture
def two_bay_archive(tmp_path):
    """Two bays of one member each and a foundation rivet; a failed part, a fault the operator clears."""
    path = tmp_path / "run.sqlite"
    a = Archive(path)
    _two_bay_run(a)
    a.close()
    return path


def _two_bay_run(a: Archive) -> None:
    a.command(1000.0, "start", {}, 100, ("accepted", "none", ""), ("completed", "none", ""))
    a.step(1001.0, 50.0, "running", 1, "Index Payload 1", "Move Lifter Raise", 0, 0, 0)
    a.step(1003.0, 60.0, "running", 1, "bay1/cross_frame", "Send AddCrossFrame bay1/cross_frame", 0, 0, 0)
    a.event(1003.5, "warning", "INSPECTION_FAILED", "bay1/cross_frame: part failed inspection: bent tube")
    a.event(1004.0, "info", "INSPECTION_PASSED", "bay1/cross_frame: part passed inspection")
    a.step(1005.0, 70.0, "running", 1, "Test Bay 1", "Inspect Bay 1", 0, 1, 1)
    a.event(1005.5, "info", "BAY_INSPECTION_PASSED", "bay 1 passed inspection")
    a.step(1007.0, 80.0, "running", 2, "bay2/cross_frame", "Send AddCrossFrame bay2/cross_frame", 1, 1, 1)
    a.event(1008.0, "error", "CRS_FAULT", FAULT)
    a.step(1008.1, 85.0, "fault", 2, "", "Wait For Help", 1, 1, 1)
    a.tm(1009.0, "hk_mission", {
        "run_state": "fault", "started": True, "bays_total": 2, "bays_built": 1, "current_bay": 2,
        "members_total": 3, "members_placed": 1, "members_riveted": 0, "current_step": "Wait For Help",
        "fault": FAULT,
    })  # fmt: skip
    a.command(
        1009.5, "set_blackboard_value", {"key": "clear_fault", "value": True}, 101,
        ("accepted", "none", ""), ("completed", "none", ""),
    )  # fmt: skip
    a.command(1010.0, "resume", {}, 102, ("rejected", "refused", "not paused"))  # refused: cleared nothing
    a.event(1010.2, "info", "FAULT_CLEARED", f"operator cleared the fault: {FAULT}")
    a.step(1010.3, 95.0, "running", 2, "bay2/cross_frame", "Send AddCrossFrame bay2/cross_frame", 1, 1, 1)
    a.step(1012.0, 100.0, "running", 2, "foundation/x0_y0", "Send FoundationRivet foundation/x0_y0", 2, 2, 1)
    a.step(1013.0, 104.0, "done", 2, "", "", 2, 3, 1)
    a.tm(1013.1, "hk_mission", {
        "run_state": "done", "started": True, "bays_total": 2, "bays_built": 2, "current_bay": 2,
        "members_total": 3, "members_placed": 3, "members_riveted": 2, "current_step": "", "fault": "",
    })  # fmt: skip
    a.tm(1013.2, "hk_tower", {"member_count": 3, "member_states": bytes([0b11_11_10_00])})


def test_summary_of_a_hand_made_archive_is_exact(two_bay_archive):
    s = summarize_file(two_bay_archive)
    assert s.tower_built and s.run_state == "done"
    assert (s.bays_built, s.bays_total) == (2, 2)
    assert (s.members_placed, s.members_total, s.members_riveted) == (3, 3, 2)
    assert s.member_states == {"not placed": 0, "placed": 0, "riveted": 1, "inspected": 2}
    assert s.members_by_group == {
        "bay 1": ["bay1/cross_frame"],
        "bay 2": ["bay2/cross_frame"],
        "foundation": ["foundation/x0_y0"],
    }
    assert s.inspection_counts() == (1, 1)
    assert s.inspection_counts(bay_inspection=True) == (1, 0)
    assert [i.target for i in s.inspections if not i.passed] == ["bay1/cross_frame"]
    assert s.parts_discarded == 1
    (fault,) = s.faults
    assert fault.reason == FAULT
    assert (fault.raised_wall, fault.raised_sim) == (1008.0, 80.0)
    assert (fault.cleared_wall, fault.cleared_sim) == (1010.2, 85.0)
    assert fault.cleared_by == "operator set clear_fault = true (Set Blackboard Value)"
    times = {p.name: (p.sim_s, p.wall_s, p.complete) for p in s.phases}
    assert times == {
        "bay 1": (30.0, 6.0, True),
        "bay 2": (20.0, 5.0, True),
        "foundation": (4.0, 1.0, True),
    }
    assert [p.name for p in s.phases] == ["bay 1", "bay 2", "foundation"]
    assert [(x.step, x.sim_start, x.sim_end) for x in s.steps] == [
        ("Move Lifter Raise", 50.0, 60.0),
        ("Send AddCrossFrame bay1/cross_frame", 60.0, 70.0),
        ("Inspect Bay 1", 70.0, 80.0),
        ("Send AddCrossFrame bay2/cross_frame", 80.0, 85.0),
        ("Wait For Help", 85.0, 95.0),
        ("Send AddCrossFrame bay2/cross_frame", 95.0, 100.0),
        ("Send FoundationRivet foundation/x0_y0", 100.0, 104.0),
    ]
    assert (s.sim_start, s.sim_end, s.wall_start, s.wall_end) == (50.0, 104.0, 1000.0, 1013.2)
    assert [(c.name, c.stage) for c in s.commands] == [
        ("start", "completed"),
        ("set_blackboard_value", "completed"),
        ("resume", "rejected"),
    ]
    text = format_summary(s)
    for line in (
        "  result:           tower built",
        "  bays built:       2/2",
        "  members:          3/3 placed, 2 riveted (last state: riveted 1, inspected 2)",
        "  part inspections: 1 passed, 1 failed (bay1/cross_frame)",
        "  bay inspections:  1 passed, 0 failed",
        "  parts discarded:  1",
        "  faults:           1",
        f"    [sim 80.0 s] {FAULT}",
        "      cleared by: operator set clear_fault = true (Set Blackboard Value) (after 2.2 s wall)",
        "    bay 1            30.0 s      6.0 s",
        "    bay 2            20.0 s      5.0 s",
        "    foundation        4.0 s      1.0 s",
        "    whole run        54.0 s     13.2 s",
        "  commands sent:    3 (1 rejected or failed)",
        "    resume rejected: refused not paused",
    ):
        assert line in text.splitlines(), (line, text)


def test_a_job_summarizes_its_own_run_of_an_archive_kept_across_runs(tmp_path, two_bay_archive):
    path = tmp_path / "kept.sqlite"
    a = Archive(path)
    a.command(500.0, "start", {}, 90, ("accepted", "none", ""), ("completed", "none", ""))
    a.step(501.0, 10.0, "running", 1, "bay1/cross_frame", "Send AddCrossFrame bay1/cross_frame", 0, 0, 0)
    a.event(502.0, "warning", "INSPECTION_FAILED", "bay1/vertical/x0_y0: part failed inspection: bent tube")
    earlier = a.seq  # one packet each: the id of the earlier run's last
    _two_bay_run(a)
    a.close()
    whole, own = summarize_file(path), summarize_file(path, after=earlier)
    alone = summarize_file(two_bay_archive)
    assert whole.wall_start == 500.0 and whole.inspection_counts() == (1, 2)
    assert own.wall_start == alone.wall_start == 1000.0
    assert own.inspection_counts() == alone.inspection_counts() == (1, 1)
    assert [p.wall_s for p in own.phases] == [p.wall_s for p in alone.phases]
    assert own.packets == alone.packets


def test_a_fault_cleared_by_a_restart_and_one_that_stands(tmp_path):
    path = tmp_path / "faults.sqlite"
    a = Archive(path)
    a.step(2000.0, 10.0, "running", 1, "bay1/cross_frame", "Wait For AddCrossFrame bay1/cross_frame", 0, 0, 0)
    a.event(2001.0, "error", "CRS_FAULT", "first fault")
    a.command(2003.0, "resume", {}, 200, ("rejected", "refused", "not paused"))  # did not clear it
    a.event(2005.0, "info", "CRS_UP", "mission 'one_bay': 0/1 bay(s) built")
    a.step(2006.0, 20.0, "running", 1, "bay1/cross_frame", "Send AddCrossFrame bay1/cross_frame", 0, 0, 0)
    a.event(2007.0, "error", "CRS_FAULT", "second fault")
    a.step(2007.1, 21.0, "fault", 1, "", "Wait For Help", 0, 0, 0)
    a.close()
    s = summarize_file(path)
    first, second = s.faults
    assert (first.reason, first.cleared_by, first.cleared_wall) == ("first fault", "CRS restarted", 2005.0)
    assert second.standing and s.standing_fault is second and not s.tower_built
    assert s.phases[0].name == "bay 1" and not s.phases[0].complete
    text = format_summary(s)
    assert "  result:           tower NOT built (run state fault)" in text
    assert "      NOT cleared" in text and "(not finished)" in text


def test_a_fault_that_clears_itself_is_not_credited_to_the_operator(tmp_path):
    path = tmp_path / "link.sqlite"
    a = Archive(path)
    a.step(3000.0, 10.0, "running", 1, "bay1/cross_frame", "Wait For AddCrossFrame bay1/cross_frame", 0, 0, 0)
    link = "lifter link down (no answer): its watchdog stops the motors; the build is held"
    a.event(3001.0, "error", "CRS_FAULT", link)
    a.command(
        3002.0,
        "set_blackboard_value",
        {"key": "clear_fault", "value": True},
        201,
        ("rejected", "refused", "the lifter link fault clears itself when the link is back"),
    )
    a.event(3009.0, "info", "FAULT_CLEARED", f"lifter link back, the build goes on (was: {link})")
    a.close()
    (fault,) = summarize_file(path).faults
    assert (fault.reason, fault.cleared_by, fault.cleared_wall) == (
        link,
        "lifter link back, the build goes on",
        3009.0,
    )


def test_summary_command_prints_and_plots(two_bay_archive, tmp_path):
    out = io.StringIO()
    png = tmp_path / "plots" / "timeline.png"
    assert cli.main(["summary", "--archive", str(two_bay_archive), "--plot", str(png)], out=out) == 0
    text = out.getvalue()
    assert "  parts discarded:  1" in text and f"  timeline plot:    {png}" in text
    data = png.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 10_000


def test_summary_of_a_file_that_is_no_archive_is_a_usage_error(tmp_path, capsys):
    bad = tmp_path / "not.sqlite"
    bad.write_bytes(b"not a database" * 100)
    assert cli.main(["summary", "--archive", str(bad)], out=io.StringIO()) == 2
    assert str(bad) in capsys.readouterr().err
    assert cli.main(["summary", "--archive", str(tmp_path / "missing.sqlite")], out=io.StringIO()) == 2


def test_plot_of_the_timeline_rows_and_categories(two_bay_archive, tmp_path):
    assert category("Send AddMember bay1/vertical/x0_y1")[0] == "send request"
    assert category("Inspect Part bay1/vertical/x0_y1")[0] == "inspection"
    assert category("Wait For AddMember bay1/vertical/x0_y1")[0] == "wait for ARS"
    assert category("Move Lifter Raise")[0] == "lifter"
    assert category("Wait For Help")[0] == "fault: waiting for help"
    path = plot_timeline(summarize_file(two_bay_archive), tmp_path / "t.png", title="two bays")
    assert path.read_bytes().startswith(b"\x89PNG")


def test_the_timeline_starts_at_the_first_step_not_when_the_crs_came_up(tmp_path):
    """A CRS reports its mission step from the moment it is up, with no step running while a job's
    Start is refused as not ready: the plot's axis starts at the first step, the whole run still at
    the first packet."""
    path = tmp_path / "run.sqlite"
    a = Archive(path)
    for k in range(5):
        a.step(990.0 + k, 10.0 * k, "idle", 0, "", "", 0, 0, 0)
    _two_bay_run(a)
    a.close()
    summary = summarize_file(path)
    assert summary.sim_start == 0.0 and summary.steps[0].sim_start == 50.0
    assert timeline_origin(summary) == 50.0
    assert "whole run       104.0 s" in format_summary(summary)
    assert plot_timeline(summary, tmp_path / "t.png").read_bytes().startswith(b"\x89PNG")


def test_like_refusals_in_a_row_are_one_line_with_their_count(tmp_path):
    a = Archive(tmp_path / "run.sqlite")
    refusals = ("not ready: lifter: no state yet", "not ready: vision not up", "not ready: vision not up")
    for i, why in enumerate(refusals):
        a.command(100.0 + i, "start", {}, 10 + i, ("rejected", "refused", why))
    a.command(104.0, "start", {}, 14, ("accepted", "none", ""), ("completed", "none", ""))
    a.command(105.0, "pause", {}, 15, ("rejected", "refused", "not started"))
    a.close()
    text = format_summary(summarize_file(tmp_path / "run.sqlite"))
    assert "  commands sent:    5 (4 rejected or failed)" in text
    assert "    start rejected 3 times: refused last: not ready: vision not up" in text
    assert "    pause rejected: refused not started" in text


def test_rejected_replays_are_not_counted_against_the_original_command(tmp_path):
    a = Archive(tmp_path / "run.sqlite")
    for i in range(10):
        a.command(100.0 + i, "start", {}, 10 + i, ("accepted", "none", ""), ("completed", "none", ""))
    for i in range(10):  # each captured Start replayed to the CRS, which rejects the copy
        a.tm(120.0 + i, "ack", {
            "command_apid": DEFS.command_apid, "command_seq_count": 0, "security_seq": 10 + i,
            "command": "start", "stage": "rejected", "reason": "replay", "detail": "not above the last",
        })  # fmt: skip
    # A command whose own first answer is a replay rejection (the GSW reused a number) was refused.
    a.command(130.0, "pause", {}, 5, ("rejected", "replay", "sequence 5 is not above the last accepted 19"))
    a.close()
    summary = summarize_file(tmp_path / "run.sqlite")
    assert [c.stage for c in summary.commands] == ["completed"] * 10 + ["rejected"]
    text = format_summary(summary)
    assert "  commands sent:    11 (1 rejected or failed)" in text
    assert "start rejected" not in text and "    pause rejected: replay" in text
    assert "  replayed copies:  10 rejected by the CRS as replays (start 10)" in text


def test_replayed_commands_over_a_real_link_leave_the_summary_right(tmp_path):
    import socket
    import time

    from tlt_common.ccsds.codec import Packet
    from tlt_common.ccsds.reasons import AckStage, Reason
    from tlt_crs.ground_link import GroundLink
    from tlt_gsw.link import GswLink

    ring = KeyRing({1: KEY}, {1: os.urandom(32)})
    crs = GroundLink(DEFS, ring, tmp_path / "replay.json", stats_period_s=0)
    crs.on_command = lambda command: crs.complete(command)
    crs.start()
    archive = tmp_path / "live.sqlite"
    attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        with GswLink(DEFS, ring, 1, crs.address, recorder=Recorder(archive), close_recorder=True) as gsw:
            sent = [gsw.send_command("start") for _ in range(10)]
            for command in sent:
                ack = gsw.wait_ack(command, final=True, timeout=5.0)
                assert ack is not None and ack.stage is AckStage.COMPLETED
            for command in sent:  # the captured Starts, replayed by someone else
                attacker.sendto(command.raw, crs.address)
            # Every rejection the CRS sends must be archived before the summary is read.
            rejections = 0
            deadline = time.monotonic() + 10.0
            while rejections < 10 and time.monotonic() < deadline:
                rejections += sum(
                    isinstance(r, Packet) and r.kind == "ack" and r.fields["reason"] == Reason.REPLAY.label
                    for r in gsw.poll(0.05)
                )
            assert crs.stats.by_reason["replay"] == 10 and rejections == 10
            assert all(command.final.stage is AckStage.COMPLETED for command in sent)
            assert all(len(command.acks) == 2 for command in sent)  # the rejections are not theirs
    finally:
        attacker.close()
        crs.close()
    text = format_summary(summarize_file(archive))
    assert "  commands sent:    10 (0 rejected or failed)" in text
    assert "start rejected" not in text
    assert "  replayed copies:  10 rejected by the CRS as replays (start 10)" in text


def test_every_stay_outside_limits_is_listed_with_its_value_limit_and_end(tmp_path):
    """`tlt gsw summary` lists each time a limited field left its limits: worst level, value and
    limit, the first crossing when it got worse, and when it came back or that it did not."""
    path = tmp_path / "limits.sqlite"
    a = Archive(path)
    a.step(1000.0, 10.0, "running", 1, "Index Payload 1", "Move Lifter Raise", 0, 0, 0)

    def lifter(wall: float, position_3: float) -> None:
        a.tm(wall, "hk_lifter", {
            "state": "crs_control", "position_0": 0.5, "position_1": 0.5, "position_2": 0.5,
            "position_3": position_3, "velocity": 10, "limit_switches": 0, "watchdog_tripped": False,
            "link_ok": True,
        })  # fmt: skip

    def end_effector(wall: float, ars: str, load: float) -> None:
        a.tm(wall, "hk_ee", {
            "ars": ars, "grasp_left": 0.1, "grasp_right": 0.1, "width": 0.05, "max_load": load,
            "calibrated": True, "part_grasped": False, "rivet_guns": 0, "fault": False,
        })  # fmt: skip

    lifter(1001.0, 0.5)
    lifter(1002.0, 1.95)  # yellow
    lifter(1002.5, 2.05)  # red
    lifter(1003.0, 1.0)  # back
    end_effector(1004.0, "ars_x", 0.2)
    end_effector(1004.0, "ars_y", 0.75)  # yellow, and stays so
    end_effector(1005.0, "ars_x", 0.3)
    end_effector(1005.0, "ars_y", 0.8)
    a.close()
    out = io.StringIO()
    assert cli.main(["summary", "--archive", str(path)], out=out) == 0
    lines = out.getvalue().splitlines()
    start = lines.index("  limits crossed:   2 (1 red), 1 still out of limits at the end")
    assert lines[start + 1 : start + 3] == [
        "    [+2.0 s] hk_lifter.position_3: RED 2.05 m outside [-0.01, 2] "
        "(first yellow 1.95 m outside [0, 1.9]); back within limits after 1.0 s",
        "    [+4.0 s] hk_ee.max_load (ars_y): YELLOW 0.75 stall fraction outside [-0.7, 0.7]; "
        "still out of limits at the end",
    ]
    quiet = tmp_path / "quiet.sqlite"
    b = Archive(quiet)
    b.step(1000.0, 10.0, "running", 1, "Index Payload 1", "Move Lifter Raise", 0, 0, 0)
    b.close()
    assert "  limits crossed:   none" in format_summary(summarize_file(quiet)).splitlines()
