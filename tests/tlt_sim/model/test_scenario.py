"""Scenario files: each shipped one validates; bad ones are refused naming file, key and reason."""

from pathlib import Path

import pytest
from tlt_sim.model.config import REPO_ROOT
from tlt_sim.model.scenario import load_scenario, parse_scenario

from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission

SCENARIOS = sorted((REPO_ROOT / "config" / "twin" / "scenarios").glob("*.yaml"))
MISSION = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_validate(path: Path):
    scenario = load_scenario(path, MISSION)
    assert scenario.name


def test_device_faults_are_passed_on_for_the_emulators():
    raw = {
        "name": "links",
        "faults": {
            "servo_failure": [{"link": "active_grippers", "servo_id": 3, "at_s": 2.0}],
            "limit_switch_stuck": [{"switch": 5, "pressed": True, "at_s": 0.0}],
            "link_drop": [{"link": "ur_x", "at_s": 10.0, "duration_s": 1.5}],
        },
    }
    scenario = parse_scenario(raw, MISSION)
    assert scenario.device_faults["servo_failure"] == [
        {"link": "active_grippers", "servo_id": 3, "at_s": 2.0}
    ]
    assert scenario.device_faults["link_drop"][0]["duration_s"] == 1.5


@pytest.mark.parametrize(
    ("faults", "key", "reason"),
    [
        ({"empty_dispensers": ["nowhere"]}, "faults.empty_dispensers[0]", "unknown dispenser"),
        (
            {"defective_parts": [{"dispenser": "vertical_dispenser_x", "index": 99, "defect": "bent_tube"}]},
            "faults.defective_parts[0].index",
            "holds 5 part(s)",
        ),
        (
            {"defective_parts": [{"dispenser": "vertical_dispenser_x", "index": 0, "defect": "rusty"}]},
            "faults.defective_parts[0].defect",
            "expected one of",
        ),
        (
            {"defective_parts": [{"dispenser": "rivet_dispenser_x", "index": 0, "defect": "bent_tube"}]},
            "faults.defective_parts[0].dispenser",
            "holds rivets",
        ),
        ({"grasp_slips": [{"arm": "ars_z", "after_s": 1.0}]}, "faults.grasp_slips[0].arm", "expected one of"),
        (
            {"placement_offsets": [{"dispenser": "vertical_dispenser_x", "index": 0, "offset": [0, 0, 5]}]},
            "faults.placement_offsets[0].offset",
            "within 0.2 m",
        ),
        (
            {"limit_switch_stuck": [{"switch": 9, "pressed": True, "at_s": 0}]},
            "faults.limit_switch_stuck[0].switch",
            "at most",
        ),
        ({"link_drop": [{"link": "ur_x"}]}, "faults.link_drop[0].at_s", "missing required key"),
    ],
)
def test_bad_scenario_is_refused(tmp_path, faults, key, reason):
    path = tmp_path / "bad.yaml"
    import yaml

    path.write_text(yaml.safe_dump({"name": "bad", "faults": faults}))
    with pytest.raises(ConfigError) as err:
        load_scenario(path, MISSION)
    assert err.value.source == str(path)
    assert err.value.key == key
    assert reason in err.value.reason


@pytest.mark.parametrize(
    ("built", "empty", "key", "reason"),
    [
        (["bay1/cross_frame", "bay9/nothing"], [], "built[1]", "not a member of mission"),
        (["bay1/cross_frame", "bay1/cross_frame"], [], "built[1]", "listed twice"),
        (["bay1/cross_frame", "foundation/x0_y0"], [], "built[1]", "only the members of bay 1"),
        (["bay1/vertical/x0_y1"], [], "built[0]", "needs 'bay1/cross_frame' built too"),
        (
            ["bay1/cross_frame", "bay1/diagonal/face_x0"],
            ["diagonal_dispenser_x"],
            "built[1]",
            "dispenser 'diagonal_dispenser_x' runs out",
        ),
    ],
)
def test_bad_built_members_are_refused(built, empty, key, reason):
    raw = {"name": "late", "built": built, "faults": {"empty_dispensers": empty}}
    with pytest.raises(ConfigError) as err:
        parse_scenario(raw, MISSION, "late.yaml")
    assert (err.value.source, err.value.key) == ("late.yaml", key)
    assert reason in err.value.reason


def test_rivet_faults_at_chosen_joints_and_at_random_make_the_scenarios_plan():
    raw = {
        "name": "rivets",
        "faults": {
            "rivet_faults": [
                {"member": "bay1/vertical/x0_y0", "joint": "bay1/x0_y0", "kind": "misfire"},
                {"member": "bay1/vertical/x0_y0", "joint": "bay1/x0_y0", "kind": "wrong_hole", "shot": 2},
                {"member": "foundation/x1_y1", "joint": "bay1/x1_y1", "kind": "loose"},
            ],
            "random_rivet_faults": {"rate": 0.05, "seed": 9, "kinds": ["proud_head", "no_rivet"]},
        },
    }
    plan = parse_scenario(raw, MISSION).rivets
    assert plan.chosen == {
        ("bay1/vertical/x0_y0", "bay1/x0_y0", 1): "misfire",
        ("bay1/vertical/x0_y0", "bay1/x0_y0", 2): "wrong_hole",
        ("foundation/x1_y1", "bay1/x1_y1", 1): "loose",
    }
    assert (plan.random.rate, plan.random.seed, plan.random.kinds) == (0.05, 9, ("proud_head", "no_rivet"))
    assert parse_scenario({"name": "plain", "faults": {}}, MISSION).rivets.random is None


RIVET = {"member": "bay1/diagonal/face_x0", "joint": "bay1/x0_y0", "kind": "loose"}


@pytest.mark.parametrize(
    ("faults", "key", "reason"),
    [
        ({"rivet_faults": [{**RIVET, "member": "bay9/x"}]}, "faults.rivet_faults[0].member", "not a member"),
        (
            {"rivet_faults": [{**RIVET, "joint": "bay0/x0_y1"}]},
            "faults.rivet_faults[0].joint",
            "riveted at bay1/x0_y0, not at 'bay0/x0_y1'",
        ),
        (
            {"rivet_faults": [{**RIVET, "member": "bay1/cross_frame"}]},
            "faults.rivet_faults[0].joint",
            "riveted at no joint",
        ),
        ({"rivet_faults": [{**RIVET, "kind": "good"}]}, "faults.rivet_faults[0].kind", "expected one of"),
        ({"rivet_faults": [{**RIVET, "shot": 0}]}, "faults.rivet_faults[0].shot", "at least 1"),
        (
            {"rivet_faults": [RIVET, {**RIVET, "kind": "misfire"}]},
            "faults.rivet_faults[1]",
            "already has a fault",
        ),
        ({"random_rivet_faults": {"rate": 1.5, "seed": 1}}, "faults.random_rivet_faults.rate", "at most"),
        ({"random_rivet_faults": {"rate": 0.1}}, "faults.random_rivet_faults.seed", "missing required key"),
        (
            {"random_rivet_faults": {"rate": 0.1, "seed": 1, "kinds": []}},
            "faults.random_rivet_faults.kinds",
            "at least 1 item",
        ),
        (
            {"random_rivet_faults": {"rate": 0.1, "seed": 1, "kinds": ["loose", "loose"]}},
            "faults.random_rivet_faults.kinds[1]",
            "listed twice",
        ),
        (
            {"random_rivet_faults": {"rate": 0.1, "seed": 1, "kinds": ["rusty"]}},
            "faults.random_rivet_faults.kinds[0]",
            "expected one of",
        ),
    ],
)
def test_bad_rivet_faults_are_refused_naming_file_key_and_reason(tmp_path, faults, key, reason):
    import yaml

    path = tmp_path / "rivets.yaml"
    path.write_text(yaml.safe_dump({"name": "bad", "faults": faults}))
    with pytest.raises(ConfigError) as err:
        load_scenario(path, MISSION)
    assert (err.value.source, err.value.key) == (str(path), key)
    assert reason in err.value.reason
