"""The build benchmark's accounting: a hand-made run (a real ground archive, a real MCAP recording
of ExecutedTrajectory records) whose figures are computed by hand."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message
from tlt_interfaces.msg import ExecutedTrajectory

from tlt_common.ccsds.codec import encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.recording.mcap_writer import McapRecordingWriter
from tlt_common.recording.message_definitions import MessageDefinitionSource
from tlt_common.ros.stamps import set_stamp
from tlt_gsw.archive import Recorder

DEFS = load_definitions()
TYPE = "tlt_interfaces/msg/ExecutedTrajectory"
OK, ABORTED = ExecutedTrajectory.OUTCOME_SUCCEEDED, ExecutedTrajectory.OUTCOME_ABORTED
# component, started, ended (sim s), planned s, outcome
MOTIONS = [
    ("ur_x", 5.0, 8.0, 3.0, OK),  # before the first step: start-up, not a bay's
    ("ur_x", 12.0, 20.0, 7.0, OK),
    ("ur_y", 15.0, 22.0, 6.0, OK),  # overlaps ur_x's: both count in the bound, once in "moving"
    ("ur_x", 25.0, 26.0, 3.0, ABORTED),  # lost: not in the bound
    ("lifter", 40.0, 45.0, 5.0, OK),
    ("ur_y", 52.0, 56.0, 4.0, OK),  # the foundation's
]


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("build")


def _archive(path: Path) -> None:
    """Bay 1 from sim 10 s to 50 s (wall 1000-1020), the foundation rivets to 60 s (wall 1025)."""
    rec = Recorder(path)
    steps = [
        (1000.0, 10.0, "running", "bay1/cross_frame", "Send AddCrossFrame bay1/cross_frame", 0),
        (1010.0, 30.0, "running", "bay1/vertical/x0_y1", "Send AddMember bay1/vertical/x0_y1", 0),
        (1020.0, 50.0, "running", "foundation/x0_y0", "Send FoundationRivet foundation/x0_y0", 1),
        (1025.0, 60.0, "done", "", "", 1),
    ]
    for seq, (wall, sim, state, member, step, built) in enumerate(steps, 1):
        raw = encode_telemetry(DEFS, "mission_step", {
            "sim_time": sim, "run_state": state, "bay": 1, "member": member, "step": step,
            "bays_built": built, "members_placed": 0, "parts_discarded": 0,
        }, seq_count=seq, timestamp=wall)  # fmt: skip
        rec.record("rx", raw, parse_datagram(raw, DEFS, expect="tm"), recorded_at=wall)
    raw = encode_telemetry(DEFS, "hk_mission", {
        "run_state": "done", "started": True, "bays_total": 1, "bays_built": 1, "current_bay": 1,
        "members_total": 2, "members_placed": 2, "members_riveted": 2, "current_step": "", "fault": "",
    }, seq_count=9, timestamp=1025.1)  # fmt: skip
    rec.record("rx", raw, parse_datagram(raw, DEFS, expect="tm"), recorded_at=1025.1)
    rec.close()


def _recording(path: Path) -> None:
    writer = McapRecordingWriter(path, compression="none")
    definition = MessageDefinitionSource().full_text(TYPE)
    channels: dict[str, int] = {}
    for component, started, ended, planned, outcome in MOTIONS:
        topic = f"/{component}/executed_trajectories"
        if topic not in channels:
            channels[topic] = writer.add_channel(topic, TYPE, definition, "")
        msg = ExecutedTrajectory(planned_s=planned, outcome=outcome, joint_names=[f"{component}_joint"])
        set_stamp(msg.started, started)
        set_stamp(msg.header.stamp, ended)
        writer.write(channels[topic], serialize_message(msg), int(ended * 1e9), int(ended * 1e9))
    writer.close()


@pytest.fixture
def run_dir(tmp_path) -> Path:
    _archive(tmp_path / "gsw_archive.sqlite")
    _recording(tmp_path / "recording.mcap")
    return tmp_path


def test_overlapping_spans_are_counted_once(bench):
    assert bench.union_length([(0.0, 2.0), (1.0, 3.0), (5.0, 6.0), (5.5, 5.7)]) == pytest.approx(4.0)
    assert bench.union_length([]) == 0.0


def test_each_bay_is_held_against_the_motions_that_started_in_it(bench, run_dir, capsys):
    motions = bench.read_motions(run_dir / "recording.mcap")
    assert [(m.component, m.planned_s, m.succeeded) for m in motions] == [
        (c, p, o == OK) for c, _, _, p, o in MOTIONS
    ]
    assert bench.report(run_dir) == 0
    lines = capsys.readouterr().out.splitlines()
    # bay 1: 40 s of sim time; bound 7 + 6 + 5 = 18 s; moving 12-22, 25-26, 40-45 = 16 s; 3 s lost.
    assert "bay 1           40.0    20.0     18.0   2.22      16.0        4       1     3.0" in lines, lines
    assert "foundation      10.0     5.0      4.0   2.50       4.0        1       0     0.0" in lines, lines
    assert "bay 1: bound by component (s): lifter 5.0, ur_x 7.0, ur_y 6.0" in lines
    assert "sim time per bay / motion lower bound, worst bay: 2.22 (goal <= 1.25: not met)" in lines
    build = "build (first step to the last phase's end): 25 s wall, 50 s sim"
    assert any(line.startswith(build) for line in lines), lines


def test_a_changed_width_command_counts_as_a_move_at_the_joints_configured_speed(bench, tmp_path):
    """ee_x's width (config/hardware/ee_x.yaml: max_velocity 0.015 m/s) is commanded by position,
    with no trajectory record: 0 -> 0.25 m is 16.7 s, a repeated command nothing, back 16.7 s."""
    from std_msgs.msg import Float64MultiArray

    writer = McapRecordingWriter(tmp_path / "recording.mcap", compression="none")
    kind = "std_msgs/msg/Float64MultiArray"
    definition = MessageDefinitionSource().full_text(kind)
    channel = writer.add_channel("/ee_x/position_command", kind, definition, "")
    unknown = writer.add_channel("/nothing/position_command", kind, definition, "")  # no hardware file
    for t, width in ((14.0, 0.25), (15.0, 0.25), (35.0, 0.0)):
        stamp = int(t * 1e9)
        writer.write(channel, serialize_message(Float64MultiArray(data=[width])), stamp, stamp)
        writer.write(unknown, serialize_message(Float64MultiArray(data=[width])), stamp, stamp)
    writer.close()
    motions = bench.read_motions(tmp_path / "recording.mcap")
    move = 0.25 / 0.015
    assert [(m.component, m.started, m.planned_s) for m in motions] == [
        ("ee_x position", 14.0, pytest.approx(move)),
        ("ee_x position", 35.0, pytest.approx(move)),
    ]
    assert all(m.succeeded and m.ended == pytest.approx(m.started + move) for m in motions)


def test_a_run_without_its_recording_is_refused_with_the_file_named(bench, tmp_path, capsys):
    _archive(tmp_path / "gsw_archive.sqlite")
    assert bench.report(tmp_path) == 1
    assert "recording.mcap" in capsys.readouterr().err


def test_each_members_part_is_measured_against_its_place_from_the_twins_ground_truth(bench, run_dir, capsys):
    """one_bay's parts where the twin would put them: each at its member's first joint from the
    tower, the near vertical 23 mm off, one part still in its dispenser (not the member's)."""
    import numpy as np
    from geometry_msgs.msg import TransformStamped
    from tlt_interfaces.msg import TransformArray

    from tlt_common.mission.schema import load_mission

    mission = load_mission(bench.ROOT / "missions" / "one_bay.yaml")
    tower = np.array([0.0, 0.0, 1.8])
    poses = {"tower": tower}
    counts: Counter = Counter()
    for member in mission.members:
        if member.kind == "foundation_rivet":
            continue
        off = np.array([0.02, -0.011, 0.0]) if member.id == "bay1/vertical/x0_y0" else np.zeros(3)
        place = tower + np.asarray(member.joints[0][1])
        poses[f"part/{member.dispenser}/{counts[member.dispenser]}"] = place + off
        counts[member.dispenser] += 1
    poses["part/vertical_dispenser_x/9"] = np.array([-1.3, -0.6, 0.4])  # a spare, far from any place
    msg = TransformArray()
    for name, p in poses.items():
        tf = TransformStamped(child_frame_id=name)
        tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = map(float, p)
        msg.transforms.append(tf)
    recording = run_dir / "truth.mcap"
    writer = McapRecordingWriter(recording, compression="none")
    kind = "tlt_interfaces/msg/TransformArray"
    channel = writer.add_channel("/twin/ground_truth", kind, MessageDefinitionSource().full_text(kind), "")
    writer.write(channel, serialize_message(msg), 1, 1)
    writer.close()

    placements = bench.read_placements(recording, bench.ROOT / "missions" / "one_bay.yaml")
    offs = {member: off for member, _part, off in placements}
    assert len(offs) == sum(counts.values()) == 9
    assert offs.pop("bay1/vertical/x0_y0") == pytest.approx(np.hypot(0.02, 0.011))
    assert max(offs.values()) < 1e-9
    recording.replace(run_dir / "recording.mcap")  # the bay's own records are gone: still reported
    bench.report(run_dir, mission="one_bay")
    out = capsys.readouterr().out
    assert "9 members, median 0.0 mm, worst 22.8 mm (bay1/vertical/x0_y0)" in out, out
    assert "  bay1/vertical/x0_y0: part/vertical_dispenser_x/" in out

    # With the run's tower model, only the members it says stand are measured: a build that
    # faulted early leaves the others' parts in their dispensers, metres from their places.
    from tlt_common.mission.tower_model import TowerModel

    model = TowerModel(mission, run_dir / "tower_model.json")  # nothing placed
    bench.report(run_dir, mission="one_bay")
    out = capsys.readouterr().out
    assert "placement: no member placed in this run" in out and "members, median" not in out, out
    model.place("bay1/cross_frame")
    model.place("bay1/vertical/x0_y0")
    bench.report(run_dir, mission="one_bay")
    assert "2 members, median 22.8 mm, worst 22.8 mm (bay1/vertical/x0_y0)" in capsys.readouterr().out


def test_a_recording_without_ground_truth_says_so(bench, run_dir, capsys):
    assert bench.report(run_dir, mission="one_bay") == 0
    assert "placement: no twin ground truth in the recording" in capsys.readouterr().out
