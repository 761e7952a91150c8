"""config/crs/crs.yaml and the index record: validated on load, refused with file, key and reason."""

from __future__ import annotations

import pytest
import yaml

from tlt_common.bt.writable_blackboard import WritableBlackboard
from tlt_common.config_schema import ConfigError, load_yaml
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import TowerModelError
from tlt_crs.config import REPO_CONFIG, load_config
from tlt_crs.context import MissionClock
from tlt_crs.index_record import IndexRecord
from tlt_drivers.lifter.config import load_lifter_config


def test_shipped_configuration_loads_with_paths_relative_to_it():
    config = load_config(REPO_CONFIG)
    assert config.mission == REPO_CONFIG.parents[2] / "missions" / "one_bay.yaml"
    assert config.mission.exists() and config.writable_blackboard.exists()
    assert config.ars_writable_blackboard == REPO_CONFIG.parents[1] / "ars" / "writable_blackboard.yaml"
    assert config.progress_file.name == "tower_model.indexed.json"
    # The lifter targets are the twin's machine: lowered = the build position, raised = one bay up
    # (from the mission), and the payload starts on the Top Grippers one bay up (indexed for bay 1).
    edu = load_yaml(REPO_CONFIG.parents[1] / "twin" / "edu.yaml")
    assert config.lifter.lowered_m == edu["lifter"]["build_position"]
    assert config.lifter.raised_m is None and config.lifter.indexed_at_start


def test_the_ground_cannot_ask_the_lifter_for_more_than_its_lead_screws_give():
    """The writable ``lifter_speed`` stops at the lead screws' limit, on the EDU and in the twin."""
    config = load_config(REPO_CONFIG)
    speed = WritableBlackboard.load(config.writable_blackboard).keys["lifter_speed"]
    screws = min(j.max_velocity_m_s for j in load_lifter_config().joints)
    twin = load_yaml(REPO_CONFIG.parents[1] / "twin" / "edu.yaml")["lifter"]["max_velocity"]
    assert speed.default <= speed.maximum <= screws == twin


def test_overrides_are_relative_to_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = load_config(REPO_CONFIG, state_file="here.json")
    assert config.state_file == tmp_path / "here.json"


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"tick_rate_hz": 0}, "tick_rate_hz"),
        ({"timeouts": {"ars_server_s": -1}}, "timeouts.ars_server_s"),
        ({"timeouts": {"ars_sever_s": 1}}, "timeouts.ars_sever_s"),
        ({"lifter": {"raised_m": 0.01}}, "lifter.raised_m"),
        ({"camera_mounts": {"inward": [0.1]}}, "camera_mounts"),
        ({"colour": "red"}, "colour"),
    ],
)
def test_bad_configuration_names_file_and_key(tmp_path, change, key):
    data = yaml.safe_load(REPO_CONFIG.read_text())
    for name, value in change.items():
        if isinstance(value, dict) and isinstance(data.get(name), dict):
            data[name].update(value)
        else:
            data[name] = value
    path = tmp_path / "crs.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert error.value.key == key and str(path) in str(error.value)


def test_index_record_persists_and_refuses_another_mission(tmp_path, crs):
    one, two = load_mission(crs.ONE_BAY), load_mission(crs.TWO_BAY)
    path = tmp_path / "indexed.json"
    record = IndexRecord(two, path)
    assert not record.indexed(1)
    record.record(1)
    assert IndexRecord(two, path).indexed(1) and not IndexRecord(two, path).indexed(2)
    with pytest.raises(TowerModelError, match="another mission"):
        IndexRecord(one, path)
    path.write_text("{not json")
    with pytest.raises(TowerModelError, match="unreadable"):
        IndexRecord(two, path)


def test_mission_clock_stands_still_while_paused():
    now = [100.0]
    clock = MissionClock(lambda: now[0])
    now[0] = 105.0
    assert clock() == 105.0
    clock.pause()
    now[0] = 200.0
    assert clock() == 105.0
    clock.resume()
    now[0] = 201.0
    assert clock() == 106.0
    clock.begin_tick()
    now[0] = 300.0
    assert clock() == 106.0  # one time per tick
    clock.end_tick()
    assert clock() == 205.0


def test_mission_clock_runs_again_only_when_every_hold_is_released():
    now = [100.0]
    clock = MissionClock(lambda: now[0])
    clock.pause("lifter link")
    assert clock.held and not clock.paused  # held by the CRS, not paused by the operator
    now[0] = 110.0
    clock.pause()  # the operator pauses meanwhile
    clock.resume("lifter link")
    now[0] = 120.0
    assert clock.held and clock.paused and clock() == 100.0
    clock.resume()
    now[0] = 121.0
    assert not clock.held and clock() == 101.0
