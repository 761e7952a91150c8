"""config/twin/edu.yaml: the machine loads, and a bad parameter is refused with file, key and reason."""

from pathlib import Path

import pytest
import yaml
from tlt_sim.model.config import DEFAULT_EDU, load_edu

from tlt_common.config_schema import ConfigError


def _write(tmp_path: Path, change) -> Path:
    data = yaml.safe_load(DEFAULT_EDU.read_text())
    change(data)
    path = tmp_path / "edu.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_default_machine_loads_with_its_mission():
    edu, mission = load_edu()
    assert mission.name == "one_bay"
    assert edu["lifter"]["travel"] == [0.0, 1.2]


@pytest.mark.parametrize(
    ("change", "key", "reason"),
    [
        (lambda d: d["physics"].update(timestep=0.5), "physics.timestep", "at most"),
        (lambda d: d["lifter"].update(travel=[1.0, 0.5]), "lifter.travel", "low < high"),
        (lambda d: d["lifter"].update(travel=[0.0, 0.5]), "lifter.travel", "rise one bay"),
        (lambda d: d["end_effector"].update(width_travel=0.1), "end_effector.width_travel", "diagonals"),
        (lambda d: d["end_effector"].update(jaw_contact=1.35), "end_effector.jaw_contact", "close fully"),
        (lambda d: d["end_effector"].update(jaw_range=[1.4, -0.2]), "end_effector.jaw_range", "low < high"),
        (lambda d: d["arms"]["ars_x"].update(home=[0, 0, 0]), "arms.ars_x.home", "6 numbers"),
        (lambda d: d["parts"].pop("tube_radius"), "parts.tube_radius", "missing required key"),
        (lambda d: d["cameras"].update(zed_fov=70), "cameras.zed_fov", "unknown key"),
        (lambda d: d["rivets"].pop("max_angle_deg"), "rivets.max_angle_deg", "missing required key"),
        (lambda d: d["rivets"].update(max_offset=0.05), "rivets.max_offset", "end_effector.rivet_reach"),
        (
            lambda d: d["rivets"].update(partial_grip_height=0.01),
            "rivets.partial_grip_height",
            "proud_height",
        ),
        (
            lambda d: d["rivets"].update(wrong_hole_offset=0.02),
            "rivets.wrong_hole_offset",
            "on the end fitting",
        ),
        (lambda d: d["rivets"].update(wrong_hole_offset=0.01), "rivets.wrong_hole_offset", "overlap"),
        (lambda d: d["rivets"].update(loose_solref=[0.004, 1.0]), "rivets.loose_solref", "softer"),
        (lambda d: d["rivets"].update(unseated_solref=[0.03]), "rivets.unseated_solref", "2 numbers"),
    ],
)
def test_bad_parameter_is_refused_with_file_key_and_reason(tmp_path, change, key, reason):
    path = _write(tmp_path, change)
    with pytest.raises(ConfigError) as err:
        load_edu(path)
    assert err.value.source == str(path)
    assert err.value.key == key
    assert reason in err.value.reason
