"""The ARS state file: the part in the gripper, the step that sets a member left in doubt and the
request that set its member, kept for a restarted ARS."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tlt_ars.mission_state import Request
from tlt_ars.planning.targets import Target
from tlt_ars.request_data import RequestData, RequestFile, RequestFileError
from tlt_common.mission.schema import load_mission

MISSION = load_mission("missions/two_bay.yaml")
MEMBER = "bay1/diagonal/face_y0"


def _set_request() -> RequestData:
    pose = np.eye(4)
    pose[:3, 3] = (1.2, -0.4, 0.9)
    pre = pose.copy()
    pre[0, 3] += 0.2
    return RequestData(
        request=Request("add_member", MEMBER, "ars_x", bay=1, kind=2, position="face_y0"),
        member=MISSION.member(MEMBER),
        holding="diagonal",
        dispenser="diagonal_dispenser_x",
        targets={"place": Target("from +x", pose, pre)},
        recorded="placed",
        discarded_from=["diagonal_dispenser_x"],
    )


def test_a_request_that_set_its_member_comes_back_as_it_was_kept(tmp_path):
    file = RequestFile(tmp_path / "state" / "ars_x.json", MISSION, "ars_x")
    assert file.load() is None  # nothing kept yet
    data = _set_request()
    file.save(data)
    back = file.load()
    assert back.request == data.request and back.member.id == MEMBER
    assert (back.recorded, back.holding, back.dispenser) == ("placed", "diagonal", "diagonal_dispenser_x")
    target = back.targets["place"]
    assert target.label == "from +x"
    np.testing.assert_array_equal(target.pose, data.targets["place"].pose)
    np.testing.assert_array_equal(target.pre_pose, data.targets["place"].pre_pose)
    file.clear()
    assert file.load() is None
    file.clear()  # clearing twice is no error


def test_a_request_is_kept_while_it_holds_a_part_or_a_rivet_or_has_set_its_member(tmp_path):
    file = RequestFile(tmp_path / "ars_x.json", MISSION, "ars_x")
    data = _set_request()
    data.recorded = ""  # taken and held, not set yet
    file.save(data)
    back = file.load()
    assert (back.recorded, back.holding, back.dispenser) == ("", "diagonal", "diagonal_dispenser_x")
    assert not back.rivet_in_gun
    data.holding, data.rivet_in_gun = None, True  # only a rivet in the gun
    file.save(data)
    assert file.load().rivet_in_gun
    data.rivet_in_gun = False  # nothing held, nothing set: nothing to keep
    with pytest.raises(ValueError, match="holds a part or a rivet, or has set its member"):
        file.save(data)


def test_a_step_in_doubt_is_kept_with_where_it_began_and_makes_the_request_unfinished(tmp_path):
    file = RequestFile(tmp_path / "ars_x.json", MISSION, "ars_x")
    data = _set_request()
    data.recorded, data.holding, data.rivet_in_gun = "", None, True
    assert not data.unfinished()
    data.setting, data.setting_q = "placed", (0.1, -1.2, 1.5, -1.9, -1.6, 0.3)  # the gun told to fire
    assert data.unfinished()
    file.save(data)
    back = file.load()
    assert back.unfinished() and (back.setting, back.recorded) == ("placed", "")
    assert back.setting_q == pytest.approx(data.setting_q)
    data.rivet_in_gun = False  # the gun's output was on for its time, then not seen off
    file.save(data)  # kept for the step alone
    assert file.load().setting == "placed"


def test_a_file_from_before_steps_in_doubt_were_kept_has_none(tmp_path):
    path = tmp_path / "ars_x.json"
    file = RequestFile(path, MISSION, "ars_x")
    file.save(_set_request())
    _edited(path, lambda d: (d.pop("setting"), d.pop("setting_q")))
    back = file.load()
    assert (back.setting, back.setting_q, back.recorded) == ("", None, "placed")


def test_a_writer_killed_mid_write_leaves_nothing_that_is_read(tmp_path):
    file = RequestFile(tmp_path / "ars_x.json", MISSION, "ars_x")
    stale = tmp_path / ".ars_x.json.4242.tmp"
    stale.write_text('{"format": 1, "half')
    assert file.load() is None
    assert not stale.exists()


def _edited(path, change) -> None:
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        (lambda d: d.update(mission_hash="0" * 64, mission="one_bay"), "belongs to mission 'one_bay'"),
        (lambda d: d.update(ars="ars_y"), "belongs to 'ars_y', not to 'ars_x'"),
        (lambda d: d.update(format=7), "not an ARS state file of format 1"),
        (lambda d: d.update(recorded="half done"), "'recorded' is 'half done'"),
        (lambda d: d.update(holding="rivet"), "'holding' is 'rivet'"),
        (lambda d: d.update(setting="fired"), "'setting' is 'fired', not one of placed"),
        (lambda d: d.update(setting="placed"), "'setting' is 'placed' but 'setting_q' is None"),
        (lambda d: d.update(setting="placed", setting_q=[0.1, "x"]), "has a bad entry: ValueError"),
        (lambda d: d.update(rivet_in_gun="yes"), "'rivet_in_gun' is 'yes', not true or false"),
        (lambda d: d.update(dispenser="bin"), "'dispenser' is 'bin', not one of mission 'two_bay'"),
        (lambda d: d["request"].update(member_id="bay1/vertical/x9_y9"), "has a bad entry"),
        (lambda d: d["targets"]["place"].update(pose=[[1.0, 0.0]]), "a pose must be 4x4"),
        (lambda d: d.pop("targets"), "has a bad entry: KeyError"),
    ],
)
def test_a_file_that_cannot_be_resumed_from_is_refused_with_its_path_and_reason(tmp_path, change, reason):
    path = tmp_path / "ars_x.json"
    file = RequestFile(path, MISSION, "ars_x")
    file.save(_set_request())
    _edited(path, change)
    with pytest.raises(RequestFileError) as exc:
        file.load()
    assert str(path) in str(exc.value) and reason in str(exc.value)


def test_a_corrupt_file_is_refused(tmp_path):
    path = tmp_path / "ars_x.json"
    path.write_bytes(b"\x00\xff not json")
    with pytest.raises(RequestFileError, match="not valid JSON"):
        RequestFile(path, MISSION, "ars_x").load()
