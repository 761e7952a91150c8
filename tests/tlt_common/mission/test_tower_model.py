"""Tower model: legal transitions only, persistence on every change, crash safety and resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tlt_common.mission.generate import build
from tlt_common.mission.schema import load_mission, parse_mission
from tlt_common.mission.tower_model import (
    INSPECTED,
    NOT_PLACED,
    PLACED,
    RIVETED,
    TowerModel,
    TowerModelError,
    TransitionRefused,
)

MISSIONS = Path(__file__).resolve().parents[3] / "missions"


@pytest.fixture
def mission():
    return load_mission(MISSIONS / "one_bay.yaml")


def test_fresh_model(mission, tmp_path):
    model = TowerModel(mission, tmp_path / "tower.json")
    assert all(state == NOT_PLACED for state in model.states.values())
    assert model.remaining["cross_frame_dispenser"] == 3
    assert model.next_member().id == "bay1/cross_frame"
    assert (tmp_path / "tower.json").exists()
    assert not model.tower_built and model.bays_built() == 0


def test_forward_transitions(mission):
    model = TowerModel(mission)
    model.place("bay1/cross_frame")
    model.place("bay1/vertical/x0_y1")
    assert model.state("bay1/vertical/x0_y1") == PLACED
    model.rivet("bay1/vertical/x0_y1")
    model.inspect("bay1/vertical/x0_y1")
    assert model.state("bay1/vertical/x0_y1") == INSPECTED
    model.rivet("foundation/x0_y0")  # a foundation rivet is riveted without being placed
    assert model.state("foundation/x0_y0") == RIVETED
    model.inspect("bay1/cross_frame")
    assert model.state("bay1/cross_frame") == INSPECTED


@pytest.mark.parametrize(
    ("steps", "refused", "reason"),
    [
        ([("place", "bay1/cross_frame")], ("place", "bay1/cross_frame"), "already PLACED"),
        ([], ("rivet", "bay1/vertical/x0_y1"), "must be PLACED first"),
        ([], ("inspect", "bay1/diagonal/face_x0"), "must be RIVETED first"),
        ([], ("rivet", "bay1/cross_frame"), "cross frame is never RIVETED"),
        ([], ("place", "foundation/x0_y0"), "foundation rivet is never PLACED"),
        ([], ("place", "bay7/vertical/x0_y1"), "unknown member"),
        (
            [("place", "bay1/vertical/x0_y0"), ("rivet", "bay1/vertical/x0_y0")],
            ("place", "bay1/vertical/x0_y0"),
            "already RIVETED",
        ),
    ],
)
def test_illegal_transitions_refused_and_change_nothing(mission, tmp_path, steps, refused, reason):
    path = tmp_path / "tower.json"
    model = TowerModel(mission, path)
    for op, member in steps:
        getattr(model, op)(member)
    before = (dict(model.states), model.revision, path.read_bytes())
    op, member = refused
    with pytest.raises(TransitionRefused, match=reason):
        getattr(model, op)(member)
    assert (dict(model.states), model.revision, path.read_bytes()) == before


def test_dispensers(mission):
    model = TowerModel(mission)
    model.take_part("cross_frame_dispenser", 2)
    model.discard_part("cross_frame_dispenser")
    assert (model.remaining["cross_frame_dispenser"], model.discarded["cross_frame_dispenser"]) == (1, 1)
    with pytest.raises(TransitionRefused, match="holds 1 part"):
        model.take_part("cross_frame_dispenser", 2)
    model.take_part("cross_frame_dispenser")
    with pytest.raises(TransitionRefused, match="holds 0 part"):
        model.take_part("cross_frame_dispenser")
    with pytest.raises(TransitionRefused, match="cannot discard 3"):
        model.discard_part("cross_frame_dispenser", 3)
    with pytest.raises(TransitionRefused, match="unknown dispenser"):
        model.take_part("candy")


def test_build_whole_mission_then_tower_built(mission):
    model = TowerModel(mission)
    while (member := model.next_member()) is not None:
        if member.kind != "foundation_rivet":
            model.take_part(member.dispenser)
            model.place(member.id)
        if member.kind != "cross_frame":
            model.rivet(member.id)
    assert model.tower_built and model.bays_built() == 1
    assert model.remaining["vertical_dispenser_x"] == 2  # 3 used of 5


def test_persisted_on_every_change_and_resumed(mission, tmp_path):
    path = tmp_path / "tower.json"
    model = TowerModel(mission, path)
    model.take_part("vertical_dispenser_x")
    model.place("bay1/vertical/x0_y1")
    on_disk = json.loads(path.read_text())
    assert on_disk["members"]["bay1/vertical/x0_y1"] == "PLACED"
    assert on_disk["revision"] == 2
    resumed = TowerModel.open(mission, path)
    assert resumed.states == model.states and resumed.remaining == model.remaining
    with pytest.raises(TransitionRefused, match="already PLACED"):
        resumed.place("bay1/vertical/x0_y1")  # a restarted CRS never adds it twice
    resumed.rivet("bay1/vertical/x0_y1")
    assert TowerModel.load(mission, path).state("bay1/vertical/x0_y1") == RIVETED


def test_open_creates_when_absent(mission, tmp_path):
    model = TowerModel.open(mission, tmp_path / "new.json")
    assert model.revision == 0 and (tmp_path / "new.json").exists()


def test_refuses_another_missions_file(mission, tmp_path):
    path = tmp_path / "tower.json"
    TowerModel(mission, path)
    other = parse_mission(build("one_bay", 1, height=0.8), "other.yaml")
    with pytest.raises(TowerModelError, match="belongs to mission 'one_bay'"):
        TowerModel.load(other, path)


def test_refuses_corrupt_files(mission, tmp_path):
    path = tmp_path / "tower.json"
    TowerModel(mission, path).place("bay1/cross_frame")
    good = path.read_text()
    path.write_text(good[: len(good) // 2])
    with pytest.raises(TowerModelError, match="not valid JSON"):
        TowerModel.load(mission, path)
    path.write_text(good.replace('"PLACED"', '"NOT_PLACED"', 1))
    with pytest.raises(TowerModelError, match="checksum"):
        TowerModel.load(mission, path)
    path.write_text("[]")
    with pytest.raises(TowerModelError, match="no checksum"):
        TowerModel.load(mission, path)
    with pytest.raises(TowerModelError, match="cannot read"):
        TowerModel.load(mission, tmp_path / "absent.json")


def test_progress_message(mission):
    from tlt_interfaces.msg import MemberState, MissionProgress

    model = TowerModel(mission)
    model.place("bay1/cross_frame")
    msg = model.fill_progress(MissionProgress())
    assert msg.mission == "one_bay" and msg.bays_total == 1 and msg.bays_built == 0
    assert len(msg.members) == len(mission.members)
    assert msg.members[0].member_id == "bay1/cross_frame" and msg.members[0].state == MemberState.STATE_PLACED
    assert msg.members[0].kind == MemberState.KIND_CROSS_FRAME
    assert msg.members[-1].kind == MemberState.KIND_FOUNDATION_RIVET
    assert {d.name: d.remaining for d in msg.dispensers}["cross_frame_dispenser"] == 3


WRITER = """
import sys
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import NOT_PLACED, PLACED, TowerModel
mission = load_mission(sys.argv[1])
model = TowerModel.open(mission, sys.argv[2])
print("ready", flush=True)
while True:
    # Invariant written with every change: the cross frame is PLACED exactly when the revision is odd.
    model.override("bay1/cross_frame", PLACED if model.revision % 2 == 0 else NOT_PLACED)
"""


def test_file_survives_kill_mid_write(mission, tmp_path):
    """SIGKILL a process that rewrites the model as fast as it can: the file always loads whole."""
    path = tmp_path / "tower.json"
    revisions = []
    for attempt in range(6):
        proc = subprocess.Popen(
            [sys.executable, "-c", WRITER, str(MISSIONS / "one_bay.yaml"), str(path)],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert proc.stdout.readline().strip() == "ready"
            # Let it make progress (reading is safe while it writes), then kill at an arbitrary point.
            last = revisions[-1] if revisions else 0
            deadline = time.monotonic() + 20.0
            while TowerModel.load(mission, path).revision < last + 5:
                assert time.monotonic() < deadline, "writer made no progress"
                time.sleep(0.005)
            time.sleep(0.002 * attempt)
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        model = TowerModel.load(mission, path)
        revisions.append(model.revision)
        assert (model.state("bay1/cross_frame") == PLACED) == (model.revision % 2 == 1)
    assert revisions == sorted(revisions) and revisions[-1] > revisions[0]
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != "tower.json"]
    assert all(name.endswith(".tmp") for name in leftovers)
    TowerModel.open(mission, path)  # a restart clears the temp files of killed writers
    assert [p.name for p in tmp_path.iterdir()] == ["tower.json"]
