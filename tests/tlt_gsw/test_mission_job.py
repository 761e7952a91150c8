"""The headless mission job (``tlt gsw mission``) over the real CCSDS/UDP ground link.

End to end: a CRS process (``tlt-crs --ground-link``) builds a one-bay tower with stand-in
hardware and ARSs in a process of their own (one part fails inspection and is replaced); the job
starts it, prints progress, ends at tower built and its summary and plot match what the stand-ins
did. The other endings (rejected Start, fault not cleared, timeout, Ctrl-C, no CRS) run against a
``GroundLink`` in this process, the CRS's own link code, on real sockets.
"""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from tlt_common import json_lines
from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason, Severity
from tlt_common.free_port import free_udp_port
from tlt_common.mission.member_states import pack_member_states
from tlt_common.ros.isolation import isolate
from tlt_crs.ground_link import GroundLink
from tlt_gsw import cli, mission_job
from tlt_gsw.archive import query
from tlt_gsw.mission_progress import Progress
from tlt_gsw.summary import load_records, summarize_file

REPO = Path(__file__).resolve().parents[2]
RIG = Path(__file__).with_name("mission_rig_process.py")
FAILING_PART = "bay1/vertical/x0_y1"
# The CRS and stand-in processes get a ROS domain of their own (as in tests/tlt_crs).
PROCESS_ENV = dict(os.environ)
isolate(PROCESS_ENV)


def link_yaml(tmp_path: Path, key_file: Path, crs_port: int, gsw_port: int, name: str = "link.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump({
        "key_file": str(key_file), "key_id": 1,
        "crs": {"bind_host": "127.0.0.1", "bind_port": crs_port, "gsw_host": "127.0.0.1",
                "gsw_port": gsw_port, "replay_state": str(tmp_path / "crs_replay.json")},
        "gsw": {"crs_host": "127.0.0.1", "crs_port": crs_port, "bind_host": "127.0.0.1",
                "bind_port": gsw_port, "archive": str(tmp_path / "archive.sqlite"),
                "command_state": str(tmp_path / "gsw_seq.json"), "ack_timeout_s": 5.0},
    }))  # fmt: skip
    return path


@pytest.fixture
def keys(tmp_path):
    return write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})


def _stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> None:
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_job_builds_a_one_bay_tower_through_a_crs_process(tmp_path, keys):
    gsw_port, crs_port = free_udp_port(), free_udp_port()
    link = link_yaml(tmp_path, keys, crs_port, gsw_port)
    crs_yaml = tmp_path / "crs.yaml"
    crs_yaml.write_text(yaml.safe_dump({
        "mission": str(REPO / "missions" / "one_bay.yaml"),
        "state_file": str(tmp_path / "state" / "tower.json"),
        "writable_blackboard": str(REPO / "config" / "crs" / "writable_blackboard.yaml"),
        "tick_rate_hz": 50.0,
        # Generous bounds: on a loaded machine the stand-ins' state topics can stall for a while.
        "timeouts": {"ars_server_s": 20.0, "service_s": 20.0, "forward_s": 2.0, "sensor_max_age_s": 2.0},
    }))  # fmt: skip
    record = tmp_path / "rig.jsonl"
    rig = subprocess.Popen(
        [sys.executable, str(RIG), str(record), "--fail-part", FAILING_PART],
        stdout=(tmp_path / "rig.log").open("w"), stderr=subprocess.STDOUT, env=PROCESS_ENV,
    )  # fmt: skip
    crs_log = (tmp_path / "crs.log").open("w")
    crs = None
    try:
        deadline = time.monotonic() + 30
        while not json_lines.read(record, "ready"):
            assert time.monotonic() < deadline and rig.poll() is None, "the stand-ins did not start"
            time.sleep(0.05)
        crs = subprocess.Popen(
            [sys.executable, "-m", "tlt_crs.node", "--config", str(crs_yaml), "--ground-link", str(link)],
            stdout=crs_log, stderr=subprocess.STDOUT, env=PROCESS_ENV,
        )  # fmt: skip
        # The job is started at once: it repeats Start until the CRS, still starting, answers.
        job = subprocess.run(
            [sys.executable, "-m", "tlt_gsw.mission_job", "--config", str(link), "mission",
             "--timeout", "120", "--fault-timeout", "60", "--start-timeout", "60"],
            capture_output=True, text=True, timeout=200, env=PROCESS_ENV,
        )  # fmt: skip
    finally:
        if crs is not None:
            _stop(crs, signal.SIGINT)
        _stop(rig)
        crs_log.close()
    out = job.stdout
    print(out)  # shown by pytest if an assertion below fails
    assert job.returncode == 0, out + job.stderr + (tmp_path / "crs.log").read_text()[-3000:]
    lines = out.splitlines()
    # Progress: bay and step lines, the failed inspection as it happened, the end.
    assert "start accepted and completed" in lines
    assert any(line.endswith("bay 1 (bays built 0)") for line in lines)
    assert any(f"Send AddMember {FAILING_PART}" in line for line in lines)
    assert any("INSPECTION_FAILED" in line and FAILING_PART in line for line in lines)
    assert "tower built" in lines
    # One line per change of step, not one per packet: as many step lines as the archived
    # mission_step packets have changes of (member, step); none for housekeeping packets.
    archive = tmp_path / "archive.sqlite"
    summary = summarize_file(archive)
    conn = query.open_archive(archive)
    records, totals = load_records(conn, ("mission_step",)), query.counts(conn)
    conn.close()
    changes, previous = 0, None
    for packet in records:
        if packet.kind != "mission_step":
            continue
        step = (packet.fields["member"], packet.fields["step"])
        if step[1] and step != previous:
            changes, previous = changes + 1, step
    step_lines = [line for line in lines if re.match(r"\[sim +[\d.]+ s\]   ", line)]
    assert len(step_lines) == changes > 20
    tree_lines = [line for line in lines if line.startswith("  tree crs")]
    assert 1 <= len(tree_lines) < next(n for d, k, _, n in totals if (d, k) == ("rx", "tree_status"))
    progress = lines[: next(i for i, line in enumerate(lines) if line.startswith("Mission summary"))]
    assert not any("hk_lifter" in line or "hk_grippers" in line for line in progress)

    # The summary matches what the stand-ins did.
    requests = json_lines.read(record, "request")
    added = [r["member"] for r in requests if r["request"] in ("add_member", "add_cross_frame")]
    riveted = [r["member"] for r in requests if r["request"] == "foundation_rivet"]
    assert len(added) == len(set(added)) == 9 and len(riveted) == 4
    assert summary.tower_built and (summary.bays_built, summary.bays_total) == (1, 1)
    assert (summary.members_placed, summary.members_total) == (13, 13)
    assert set(summary.members_by_group["bay 1"]) == set(added)
    assert summary.members_by_group["foundation"] == riveted
    assert summary.inspection_counts() == (9, 1)
    assert [i.target for i in summary.inspections if not i.passed] == [FAILING_PART]
    assert summary.inspection_counts(bay_inspection=True) == (1, 0)
    assert summary.parts_discarded == 1 and not summary.faults
    assert [p.name for p in summary.phases] == ["bay 1", "foundation"]
    assert all(p.complete and p.sim_s > 0 and p.wall_s > 0 for p in summary.phases)
    for line in (
        "  result:           tower built",
        "  bays built:       1/1",
        f"  part inspections: 9 passed, 1 failed ({FAILING_PART})",
        "  parts discarded:  1",
        "  faults:           0",
    ):
        assert line in lines, (line, out)
    plot = tmp_path / "archive_timeline.png"
    assert plot.read_bytes().startswith(b"\x89PNG") and f"  timeline plot:    {plot}" in lines
    # The archive holds the whole run: the Start sent and its acknowledgements, the telemetry.
    assert [c.name for c in summary.commands if c.stage == "completed"] == ["start"]


class FakeCrs:
    """The CRS's GroundLink on a real socket, in this process, with a scripted reaction to Start."""

    def __init__(self, tmp_path: Path, key_file: Path, gsw_port: int, on_start=None, validator=None):
        self.link = GroundLink(
            load_definitions(),
            KeyRing.load(key_file),
            tmp_path / "fake_replay.json",
            gsw_address=("127.0.0.1", gsw_port),
            on_command=self._command,
            validator=validator,
        )
        self.on_start = on_start
        self.on_clear = lambda link: None
        self.faulted = threading.Event()
        self.commands: list[str] = []
        self.link.start()

    def _command(self, command) -> None:
        self.commands.append(command.name)
        self.link.complete(command)
        if command.name == "start" and self.on_start is not None:
            threading.Thread(target=self.on_start, args=(self,), daemon=True).start()
        if command.name == "set_blackboard_value" and command.params["key"] == "clear_fault":
            self.on_clear(self.link)

    @property
    def port(self) -> int:
        return self.link.address[1]

    def close(self) -> None:
        self.link.close()


def _job(link: Path, *options: str) -> tuple[int, str]:
    out = io.StringIO()
    code = mission_job.main(["--config", str(link), "mission", "--no-plot", *options], out=out)
    return code, out.getvalue()


def test_start_with_a_wrong_key_exits_1_with_the_reason(tmp_path, keys):
    gsw_port = free_udp_port()
    crs = FakeCrs(tmp_path, keys, gsw_port)
    try:
        # A wrong command key; the telemetry keys are the CRS's, so the GSW can read the rejection.
        tm = KeyRing.load(keys).telemetry
        tm_keys = {k: tm.get(k) for k in tm.key_ids}
        intruder = write_key_file(tmp_path / "keys" / "other.key", {1: os.urandom(32)}, tm_keys)
        link = link_yaml(tmp_path, intruder, crs.port, gsw_port)
        code, out = _job(link, "--start-timeout", "20")
    finally:
        crs.close()
    assert code == 1, out
    assert "start rejected: bad_auth" in out
    assert crs.commands == []  # never acted on
    assert "Mission summary" in out and "tower NOT built" in out


def test_start_refused_by_the_crs_exits_1_with_its_words(tmp_path, keys):
    gsw_port = free_udp_port()
    crs = FakeCrs(tmp_path, keys, gsw_port, validator=lambda command: (Reason.REFUSED, "already started"))
    try:
        code, out = _job(link_yaml(tmp_path, keys, crs.port, gsw_port), "--start-timeout", "20")
    finally:
        crs.close()
    assert code == 1, out
    assert "start rejected: refused (already started)" in out
    assert "    start rejected: refused already started" in out  # and in the summary's command list


def _raise_fault(crs: FakeCrs) -> None:
    time.sleep(0.2)
    crs.link.send_event(Severity.ERROR, "CRS_FAULT", "Wait For AddMember bay1/vertical/x0_y0: part slipped")
    crs.faulted.set()


def test_a_fault_left_standing_ends_the_job_with_exit_1(tmp_path, keys):
    gsw_port = free_udp_port()
    crs = FakeCrs(tmp_path, keys, gsw_port, on_start=_raise_fault)
    try:
        link = link_yaml(tmp_path, keys, crs.port, gsw_port)
        code, out = _job(link, "--fault-timeout", "1", "--timeout", "60")
    finally:
        crs.close()
    assert code == 1, out
    assert "  FAULT raised: Wait For AddMember bay1/vertical/x0_y0: part slipped" in out
    assert "fault not cleared within 1 s: Wait For AddMember bay1/vertical/x0_y0: part slipped" in out
    assert "      NOT cleared" in out  # the summary, from the archive


def test_a_fault_the_operator_clears_is_in_the_summary_with_what_cleared_it(tmp_path, keys):
    """The job keeps following the build while the operator clears the fault from another
    ``tlt gsw send``; the summary names the clearing command, read from the shared archive."""
    gsw_port = free_udp_port()
    fault = "Wait For AddMember bay1/vertical/x0_y0: part slipped"
    crs = FakeCrs(tmp_path, keys, gsw_port, on_start=_raise_fault)

    def on_clear(link: GroundLink) -> None:
        link.send_event(Severity.INFO, "FAULT_CLEARED", f"operator cleared the fault: {fault}")
        _done(link)

    crs.on_clear = on_clear
    link = link_yaml(tmp_path, keys, crs.port, gsw_port)
    sent: list[int] = []

    def operator() -> None:
        deadline = time.monotonic() + 30
        while not crs.faulted.is_set() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        argv = ["--config", str(link), "send", "set_blackboard_value", "key=clear_fault", "value=true"]
        sent.append(cli.main([*argv, "--wait-ack"], out=io.StringIO()))

    helper = threading.Thread(target=operator)
    helper.start()
    try:
        code, out = _job(link, "--fault-timeout", "30", "--timeout", "60")
    finally:
        helper.join(timeout=30)
        crs.close()
    assert sent == [0] and code == 0, out
    assert f"  FAULT raised: {fault}" in out and "tower built" in out
    assert "      cleared by: operator set clear_fault = true (Set Blackboard Value)" in out
    (record,) = summarize_file(tmp_path / "archive.sqlite").faults
    assert record.reason == fault and not record.standing


def _done(link: GroundLink) -> None:
    link.send_telemetry("mission_step", {
        "sim_time": 30.0, "run_state": "done", "bay": 1, "member": "", "step": "", "bays_built": 1,
        "members_placed": 13, "parts_discarded": 0,
    })  # fmt: skip


def test_a_crs_that_restarts_mid_build_gets_start_again(tmp_path, keys):
    gsw_port = free_udp_port()

    def restart_then_finish(crs: FakeCrs) -> None:
        time.sleep(0.3)
        if crs.commands.count("start") == 1:  # the CRS restarted: it announces itself, idle
            crs.link.send_event(Severity.INFO, "CRS_UP", "mission 'one_bay': 0/1 bay(s) built")
        else:
            _done(crs.link)

    crs = FakeCrs(tmp_path, keys, gsw_port, on_start=restart_then_finish)
    try:
        code, out = _job(link_yaml(tmp_path, keys, crs.port, gsw_port), "--timeout", "60")
    finally:
        crs.close()
    assert code == 0, out
    assert "the CRS restarted: sending Start again" in out and crs.commands == ["start", "start"]
    assert "tower built" in out


def test_the_summary_has_the_tower_model_reported_after_done(tmp_path, keys):
    """The last member's state can change after the tower model's last report before "done": the
    job waits for the next report (hk_tower) before it ends, so the summary's states are final."""
    gsw_port = free_udp_port()

    def tower(states: list[int]) -> dict:
        return {"member_count": len(states), "member_states": pack_member_states(states)}

    def finish(crs: FakeCrs) -> None:
        time.sleep(0.3)
        crs.link.send_telemetry("hk_tower", tower([2, 0]))  # the foundation rivet not yet reported
        _done(crs.link)
        time.sleep(1.0)  # hk_tower goes out every 2 s, and with the next progress report
        crs.link.send_telemetry("hk_tower", tower([2, 2]))

    crs = FakeCrs(tmp_path, keys, gsw_port, on_start=finish)
    try:
        code, out = _job(link_yaml(tmp_path, keys, crs.port, gsw_port), "--timeout", "60")
    finally:
        crs.close()
    assert code == 0, out
    states = summarize_file(tmp_path / "archive.sqlite").member_states
    assert states == {"not placed": 0, "placed": 0, "riveted": 2, "inspected": 0}, out


def test_timeout_ends_the_job_with_exit_3(tmp_path, keys):
    gsw_port = free_udp_port()
    crs = FakeCrs(tmp_path, keys, gsw_port)
    try:
        code, out = _job(link_yaml(tmp_path, keys, crs.port, gsw_port), "--timeout", "0.5")
    finally:
        crs.close()
    assert code == 3, out
    assert "timeout: the tower was not built within 0.5 s" in out and crs.commands == ["start"]
    assert "Mission summary" in out


def test_no_crs_answering_exits_3(tmp_path, keys):
    silent = free_udp_port()  # nothing listens there
    code, out = _job(link_yaml(tmp_path, keys, silent, free_udp_port()), "--start-timeout", "1")
    assert code == 3 and "no acknowledgement of start within 1 s" in out


def test_ctrl_c_exits_130_and_prints_the_summary(tmp_path, keys):
    gsw_port = free_udp_port()
    crs = FakeCrs(tmp_path, keys, gsw_port)
    try:
        link = link_yaml(tmp_path, keys, crs.port, gsw_port)
        # Started as a script's background job is (SIGINT ignored), which CI's runner may do.
        proc = subprocess.Popen(
            [sys.executable, "-m", "tlt_gsw.mission_job", "--config", str(link), "mission", "--no-plot"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while crs.commands != ["start"]:
            if proc.poll() is not None:
                pytest.fail(f"the job exited {proc.returncode} before sending Start: {proc.stdout.read()}")
            assert time.monotonic() < deadline, "the job never sent Start"
            time.sleep(0.05)
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        crs.close()
    assert proc.returncode == 130, out
    assert "interrupted" in out and "Mission summary" in out
    # The archive is complete and readable: the Start and its acknowledgements are in it.
    summary = summarize_file(tmp_path / "archive.sqlite")
    assert [(c.name, c.stage) for c in summary.commands] == [("start", "completed")]


def test_mission_and_summary_are_tlt_gsw_subcommands(tmp_path, keys, capsys):
    silent = free_udp_port()
    link = link_yaml(tmp_path, keys, silent, free_udp_port())
    out = io.StringIO()
    assert cli.main(["--config", str(link), "mission", "--start-timeout", "0.5", "--no-plot"], out=out) == 3
    assert cli.main(["--config", str(link), "summary"], out=out) == 0  # the archive link.yaml names
    assert "Mission summary" in out.getvalue()
    assert cli.main(["--config", str(link), "mission", "--key-id", "7"], out=out) == 2
    assert "key id 7 is not in the key file" in capsys.readouterr().err
    missing = tmp_path / "no_tree.json"
    assert cli.main(["--config", str(link), "mission", "--tree", str(missing)], out=out) == 2
    assert str(missing) in capsys.readouterr().err


def _tree_packets(shape, tick: int) -> list:
    from tlt_common.bt.status_codec import encode
    from tlt_common.ccsds.codec import encode_telemetry, parse_datagram

    defs = load_definitions()
    packets = []
    for part in encode(shape, agent="crs", tick_count=tick, max_status_bytes=1):  # several parts
        raw = encode_telemetry(defs, "tree_status", {
            "agent": "crs", "shape_hash": part.shape_hash, "tick": part.tick_count,
            "node_count": part.node_count, "part_index": part.part_index, "part_count": part.part_count,
            "first_node": part.first_node, "status": part.status,
        }, seq_count=tick)  # fmt: skip
        packets.append(parse_datagram(raw, defs, expect="tm"))
    return packets


def test_progress_names_the_running_node_with_a_tree_definition_and_counts_without(tmp_path):
    import py_trees
    from py_trees.common import Status

    from tlt_common.bt.status_codec import TreeShape
    from tlt_gsw.gui.tree_definitions import load_tree_definition, write_tree_definition

    names = ("Send AddMember x", "Wait For AddMember x", "Affix x")  # 5 nodes: two status parts
    steps = [py_trees.behaviours.Running(name) for name in names]
    bay = py_trees.composites.Sequence("Construct Bay 1", memory=True, children=steps)
    root = py_trees.composites.Sequence("CRS", memory=False, children=[bay])
    shape = TreeShape.of(root)
    definition = load_tree_definition(write_tree_definition(shape, tmp_path / "crs.json", "crs"))
    out = io.StringIO()
    named = Progress(out, definition)
    counted = Progress(io.StringIO(), None, tree_every_s=10.0)
    for tick, running in ((1, 0), (2, 0), (3, 1)):
        root.status = bay.status = Status.RUNNING
        steps[0].status = Status.RUNNING if running == 0 else Status.SUCCESS
        steps[1].status = Status.RUNNING if running == 1 else Status.INVALID
        for packet in _tree_packets(TreeShape.of(root), tick):
            named.packet(packet, now=float(tick))
            counted.packet(packet, now=float(tick))
    # One line per change of the running node, not per packet or tick.
    assert out.getvalue().splitlines() == [
        "  tree crs tick 1: CRS > Construct Bay 1 > Send AddMember x",
        "  tree crs tick 3: CRS > Construct Bay 1 > Wait For AddMember x",
    ]
    # Without a definition: the status counts of a whole tick, at most once per tree_every_s.
    lines = counted.out.getvalue().splitlines()
    assert lines == ["  tree crs tick 1: running 3, success 0, failure 0 of 5 nodes"]
    first, second = _tree_packets(TreeShape.of(root), 20)
    counted.packet(first, now=20.0)
    assert len(counted.out.getvalue().splitlines()) == 1  # one part of two: not yet
    counted.packet(second, now=20.0)
    last = counted.out.getvalue().splitlines()[-1]
    assert last == "  tree crs tick 20: running 3, success 1, failure 0 of 5 nodes"
    other = TreeShape.of(py_trees.composites.Sequence("Other", memory=False, children=[]))
    stranger = Progress(io.StringIO(), other)
    for packet in _tree_packets(shape, 4) + _tree_packets(shape, 5):
        stranger.packet(packet, now=5.0)
    (line,) = stranger.out.getvalue().splitlines()  # said once
    assert line.startswith("  tree: cannot decode (status of agent 'crs' is for tree shape")


def test_progress_times_are_from_the_first_step_and_say_where_that_is_on_the_crs_clock():
    """A progress line's sim time can be found in a recording: the job says its origin once."""
    from tlt_common.ccsds.codec import encode_telemetry, parse_datagram

    defs = load_definitions()

    def step(sim: float, bay: int, name: str):
        raw = encode_telemetry(defs, "mission_step", {
            "sim_time": sim, "run_state": "running", "bay": bay, "member": name, "step": name,
            "bays_built": bay - 1, "members_placed": 0, "parts_discarded": 0,
        }, seq_count=1)  # fmt: skip
        return parse_datagram(raw, defs, expect="tm")

    progress = mission_job.Progress(io.StringIO())
    for packet in (step(19.5, 1, "Add Cross Frame"), step(30.0, 1, "Index Payload 2")):
        progress.packet(packet, now=0.0)
    assert progress.out.getvalue().splitlines() == [
        "sim times below are from the CRS's ROS time 19.50 s",
        "[sim     0.00 s] bay 1 (bays built 0)",
        "[sim     0.00 s]   running Add Cross Frame  (placed 0, discarded 0)",
        "[sim    10.50 s]   running Index Payload 2  (placed 0, discarded 0)",
    ]


def test_progress_says_the_time_left_from_the_members_placed_so_far():
    from tlt_common.ccsds.codec import encode_telemetry, parse_datagram

    defs = load_definitions()

    def step(name: str, placed: int):
        raw = encode_telemetry(defs, "mission_step", {
            "sim_time": 10.0 * placed, "run_state": "running", "bay": 1, "member": name, "step": name,
            "bays_built": 0, "members_placed": placed, "parts_discarded": 0,
        }, seq_count=1)  # fmt: skip
        return parse_datagram(raw, defs, expect="tm")

    progress = mission_job.Progress(io.StringIO())
    progress.packet(step("Add Cross Frame", 0), now=100.0)
    progress.last_mission = {"members_total": 13}  # as an hk_mission packet leaves it
    progress.packet(step("Add Vertical 1", 1), now=160.0)  # 60 s for one member, 12 to go
    progress.packet(step("Add Vertical 2", 12), now=220.0)  # 10 s each, one to go
    lines = progress.out.getvalue().splitlines()
    assert lines[-3].endswith("(placed 0, discarded 0)")
    assert lines[-2].endswith("(placed 1, discarded 0, about 12 min left)")
    assert lines[-1].endswith("(placed 12, discarded 0, about 10 s left)")
