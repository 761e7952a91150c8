"""Tower model: each riveted joint's verification record, persisted and resumed, the operator's
decisions on it, and the records a file may not hold."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import (
    JOINT_FIELDS,
    TowerModel,
    TowerModelError,
    TransitionRefused,
    _checksum,
)

MISSIONS = Path(__file__).resolve().parents[3] / "missions"
MEMBER = "bay1/vertical/x0_y1"


@pytest.fixture
def mission():
    return load_mission(MISSIONS / "one_bay.yaml")


def _joints(mission):
    return [joint for joint, _ in mission.member(MEMBER).joints]


def _record(state="failed", verdict="unseated", **changes):
    record = {
        "state": state, "verdict": verdict, "reason": "head stands 4.2 mm proud", "shots": 2,
        "looks": 2, "verdicts": [verdict] * 2, "height": 0.0042, "along": 0.0003, "pixels": 120,
        "head": [1.0, 2.0, 3.0], "camera": "ars_y/d405",
    }  # fmt: skip
    return {**record, **changes}


def test_records_persist_resume_and_say_which_joints_want_the_operator(mission, tmp_path):
    path = tmp_path / "tower.json"
    model = TowerModel(mission, path)
    first, second = _joints(mission)
    model.record_joint(MEMBER, first, _record("verified", "good"))
    model.record_joint(MEMBER, second, _record())
    assert set(model.open_joints(MEMBER)) == {second}
    back = TowerModel.load(mission, path)
    assert back.joints_of(MEMBER) == {first: _record("verified", "good"), second: _record()}
    back.decide_joint(MEMBER, second, "retry")
    assert TowerModel.load(mission, path).open_joints(MEMBER)[second]["state"] == "retry"
    back.decide_joint(MEMBER, second, "confirmed")
    assert back.open_joints(MEMBER) == {}
    with pytest.raises(TransitionRefused, match="wants no decision"):
        back.decide_joint(MEMBER, first, "retry")


def test_unsound_records_and_decisions_are_refused_and_change_nothing(mission, tmp_path):
    model = TowerModel(mission, tmp_path / "tower.json")
    joint = _joints(mission)[0]
    for member, name, record, why in [
        (MEMBER, "bay9/x0_y0", _record(), "no joint of a member"),
        ("bay1/nothing", joint, _record(), "no joint of a member"),
        (MEMBER, joint, _record(state="fine"), "state 'fine'"),
        (MEMBER, joint, _record(shots="two"), "shots 'two'"),
        (MEMBER, joint, {k: v for k, v in _record().items() if k != "camera"}, "exactly"),
    ]:
        with pytest.raises(TransitionRefused, match=why):
            model.record_joint(member, name, record)
    assert model.joints == {} and model.revision == 0
    model.record_joint(MEMBER, joint, _record())
    with pytest.raises(TransitionRefused, match="confirmed or retry"):
        model.decide_joint(MEMBER, joint, "verified")


def test_a_member_built_again_loses_its_joints_records(mission, tmp_path):
    model = TowerModel(mission, tmp_path / "tower.json")
    for m in ("bay1/cross_frame", MEMBER):
        model.place(m)
    model.rivet(MEMBER)
    model.record_joint(MEMBER, _joints(mission)[0], _record())
    model.correct_member(MEMBER, "unplaced")
    assert model.joints_of(MEMBER) == {}


def test_a_file_with_an_unsound_joint_record_is_refused(mission, tmp_path):
    path = tmp_path / "tower.json"
    TowerModel(mission, path).record_joint(MEMBER, _joints(mission)[0], _record())
    document = json.loads(path.read_text())
    document.pop("checksum")
    key = next(iter(document["joints"]))
    document["joints"][key]["state"] = "maybe"
    path.write_text(json.dumps({"checksum": _checksum(document), **document}))
    with pytest.raises(TowerModelError, match="state 'maybe'"):
        TowerModel.load(mission, path)


def test_a_file_without_joints_resumes_with_none(mission, tmp_path):
    path = tmp_path / "tower.json"
    TowerModel(mission, path)
    document = json.loads(path.read_text())
    document.pop("checksum")
    document.pop("joints")
    path.write_text(json.dumps({"checksum": _checksum(document), **document}))
    assert TowerModel.load(mission, path).joints == {}
    assert set(JOINT_FIELDS) == set(_record())
