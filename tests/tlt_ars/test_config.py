"""The ARS configuration files: shipped files load and fit their mission; bad files name the key."""

from __future__ import annotations

import copy

import pytest

from tlt_ars.config import (
    ars_config_from_dict,
    check_against_mission,
    default_config_path,
    dispensers_used,
    load_ars_config,
)
from tlt_common.config_schema import ConfigError, load_yaml
from tlt_common.mission.schema import load_mission


@pytest.mark.parametrize("ars", ["ars_x", "ars_y"])
def test_shipped_configs_load_and_cover_every_dispenser_their_mission_uses(ars):
    config = load_ars_config(default_config_path(ars))
    assert config.ars == ars
    mission = load_mission(config.mission_path)
    check_against_mission(config, mission)
    for name in ("one_bay", "two_bay", "ten_bay"):
        check_against_mission(config, load_mission(f"missions/{name}.yaml"))
    assert all(n.startswith(f"ur_{ars[-1]}_") for n in config.arm["joint_names"])
    assert config.inspection_pose.joints is not None and len(config.inspection_pose.joints) == 6


SHORT = {"joints": [0.0] * 5}
BOTH = {"joints": [0.0] * 6, "position": [0, 0, 1], "rpy": [0, 0, 0]}


def _raw():
    return copy.deepcopy(load_yaml(default_config_path("ars_x")))


@pytest.mark.parametrize(
    ("edit", "key", "reason"),
    [
        (lambda r: r.update(ars="ars_z"), "ars", "ars_z"),
        (lambda r: r["arm"].update(velocity_scale=1.5), "arm.velocity_scale", "1.5"),
        (lambda r: r["arm"]["joint_names"].pop(), "arm.joint_names", "six joints"),
        (lambda r: r["poses"]["dispensers"].update(rivet_dispenser_x=SHORT),
         "poses.dispensers.rivet_dispenser_x.joints", "expected 6"),
        (lambda r: r["poses"].update(inspection={"position": [0, 0, 1]}), "poses.inspection",
         "position and rpy"),
        (lambda r: r["poses"].update(discard=BOTH), "poses.discard", "not both"),
        (lambda r: r["end_effector"].update(grasp_closed=[1.0]), "end_effector.grasp_closed",
         "one per grasp joint"),
        (lambda r: r["end_effector"]["width"].pop("diagonal"), "end_effector.width", "diagonal"),
        (lambda r: r["timeouts"].update(unknown_s=1.0), "timeouts.unknown_s", ""),
    ],
)  # fmt: skip
def test_bad_config_names_key_and_reason(edit, key, reason):
    raw = _raw()
    edit(raw)
    with pytest.raises(ConfigError) as err:
        ars_config_from_dict(raw, "bad.yaml")
    assert err.value.key == key
    assert reason in str(err.value)


def test_missing_coarse_pose_for_a_used_dispenser_is_refused():
    raw = _raw()
    del raw["poses"]["dispensers"]["rivet_dispenser_x"]
    config = ars_config_from_dict(raw, "ars_x.yaml")
    mission = load_mission("missions/one_bay.yaml")
    assert "rivet_dispenser_x" in dispensers_used(mission, "ars_x")
    with pytest.raises(ConfigError, match="rivet_dispenser_x but no coarse pose"):
        check_against_mission(config, mission)


def test_cross_frame_has_its_own_inspection_pose_when_configured():
    config = load_ars_config(default_config_path("ars_x"))
    assert config.inspection_pose_for("cross_frame") != config.inspection_pose_for("vertical")
    y = load_ars_config(default_config_path("ars_y"))
    assert y.inspection_pose_for("cross_frame") == y.inspection_pose
