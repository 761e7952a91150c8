"""Mission files: the shipped missions load; every kind of error names the file, key and reason."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from tlt_common.config_schema import ConfigError
from tlt_common.mission.generate import build, main
from tlt_common.mission.schema import load_mission, parse_mission

MISSIONS = Path(__file__).resolve().parents[3] / "missions"


@pytest.mark.parametrize(("name", "bays"), [("one_bay", 1), ("two_bay", 2), ("ten_bay", 10)])
def test_shipped_missions_load(name, bays):
    mission = load_mission(MISSIONS / f"{name}.yaml")
    assert mission.name == name and mission.bay_count == bays
    assert len(mission.members) == 9 * bays + 4
    first = mission.members[:9]
    assert [m.group for m in first] == ["cross_frame"] + ["far_vertical"] * 2 + ["near_vertical"] * 2 + [
        "diagonal"
    ] * 4
    assert [m.kind for m in mission.members[-4:]] == ["foundation_rivet"] * 4
    far = mission.member("bay1/vertical/x0_y1")
    assert (far.add_ars, far.affix_ars) == ("ars_x", "ars_y")
    assert far.joints == (("bay0/x0_y1", (0.0, 0.75, 0.0)), ("bay1/x0_y1", (0.0, 0.75, -0.75)))
    assert [r.step for r in far.rivets] == ["add", "affix"]
    near = mission.member("bay1/vertical/x1_y1")
    assert near.add_ars == near.affix_ars == "ars_y"
    assert mission.inspection["chamfer_thresholds"]["strut_tube"] > 0
    assert len(mission.hash) == 64


def test_hash_follows_content():
    a = parse_mission(build("m", 2), "a.yaml")
    b = parse_mission(build("m", 2), "b.yaml")
    c = parse_mission(build("m", 2, height=0.8), "c.yaml")
    assert a.hash == b.hash != c.hash


def test_generator_writes_a_loadable_file(tmp_path):
    out = tmp_path / "three.yaml"
    assert main(["--name", "three", "--bays", "3", "-o", str(out)]) == 0
    assert load_mission(out).bay_count == 3


def broken(edit) -> dict:
    data = copy.deepcopy(build("m", 2))
    edit(data)
    return data


def far(data, bay=0, index=0):
    return data["bays"][bay]["far_verticals"][index]


def drop(data, key):
    del data[key]


CASES = [
    ("missing key", lambda d: drop(d, "geometry"), "geometry", "missing required key"),
    ("wrong type", lambda d: d.update(bay_count="two"), "bay_count", "expected an integer"),
    ("unknown key", lambda d: d.update(colour="red"), "colour", "unknown key"),
    ("bays count", lambda d: d.update(bay_count=3), "bay_count", "bay_count is 3 but 2 bay(s)"),
    ("bay numbering", lambda d: d["bays"][1].update(number=5), "bays[1].number", "expected 2"),
    (
        "duplicate member",
        lambda d: far(d, 1).update(id="bay1/vertical/x0_y1"),
        "bays[1].far_verticals[0].id",
        "already used at bays[0].far_verticals[0]",
    ),
    (
        "unknown joint",
        lambda d: far(d).update(joints=["bay0/x0_y1", "bay9/x0_y1"]),
        "bays[0].far_verticals[0].joints[1]",
        "unknown joint 'bay9/x0_y1'",
    ),
    (
        "bad ARS",
        lambda d: far(d).update(add_ars="ars_z"),
        "bays[0].far_verticals[0].add_ars",
        "expected one of",
    ),
    (
        "far vertical affixed by adder",
        lambda d: far(d).update(affix_ars="ars_x"),
        "bays[0].far_verticals[0].affix_ars",
        "other ARS",
    ),
    (
        "near vertical affixed by other",
        lambda d: d["bays"][0]["near_verticals"][0].update(affix_ars="ars_y"),
        "bays[0].near_verticals[0].affix_ars",
        "the ARS that adds it",
    ),
    (
        "negative dispenser count",
        lambda d: d["dispensers"][0].update(count=-1),
        "dispensers[0].count",
        "at least 0",
    ),
    (
        "dispenser too small",
        lambda d: d["dispensers"][0].update(count=1),
        "dispensers[0].count",
        "holds 1 part(s) but the mission needs 2",
    ),
    (
        "unknown dispenser",
        lambda d: far(d).update(dispenser="nowhere"),
        "bays[0].far_verticals[0].dispenser",
        "unknown dispenser 'nowhere'",
    ),
    (
        "dispenser of the wrong kind",
        lambda d: far(d).update(dispenser="diagonal_dispenser_x"),
        "bays[0].far_verticals[0].dispenser",
        "holds diagonal parts, not vertical",
    ),
    (
        "strut length",
        lambda d: d["joints"].update({"bay0/x0_y1": [0.0, 0.75, 0.1]}),
        "bays[0].far_verticals[0].joints",
        "a vertical strut is 0.7500 m",
    ),
    (
        "bad point",
        lambda d: d["joints"].update({"bay0/x0_y1": [0.0, 0.75]}),
        "joints.bay0/x0_y1",
        "3 numbers",
    ),
    (
        "missing far vertical",
        lambda d: d["bays"][0]["far_verticals"].pop(),
        "bays[0].far_verticals",
        "expected positions x0_y1, x1_y0",
    ),
    (
        "rivet on a foreign joint",
        lambda d: far(d)["rivets"][0].update(joint="bay1/x1_y1"),
        "bays[0].far_verticals[0].rivets[0].joint",
        "not one of the member's joints",
    ),
    (
        "rivet by the wrong ARS",
        lambda d: far(d)["rivets"][1].update(ars="ars_x"),
        "bays[0].far_verticals[0].rivets[1].ars",
        "set by ars_y",
    ),
    (
        "foundation rivet joint",
        lambda d: d["foundation_rivets"][0].update(joint="ground"),
        "foundation_rivets[0].joint",
        "unknown joint 'ground'",
    ),
    (
        "cross frame corners",
        lambda d: d["bays"][0]["cross_frame"]["joints"].pop(),
        "bays[0].cross_frame.joints",
        "4 corner joints",
    ),
]


@pytest.mark.parametrize(("what", "edit", "key", "reason"), CASES, ids=[c[0] for c in CASES])
def test_errors_name_file_key_and_reason(tmp_path, what, edit, key, reason):
    path = tmp_path / "bad_mission.yaml"
    path.write_text(yaml.safe_dump(broken(edit)))
    with pytest.raises(ConfigError) as err:
        load_mission(path)
    assert err.value.source == str(path)
    assert err.value.key == key, str(err.value)
    assert reason in err.value.reason, str(err.value)
    assert str(path) in str(err.value)


def test_unreadable_and_invalid_yaml(tmp_path):
    with pytest.raises(ConfigError, match="cannot read file"):
        load_mission(tmp_path / "absent.yaml")
    path = tmp_path / "bad.yaml"
    path.write_text("name: [unclosed\n")
    with pytest.raises(ConfigError, match="invalid YAML: line"):
        load_mission(path)
