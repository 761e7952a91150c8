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
