"""The ground's writes to an ARS's keys: the whitelist checked against the ARS configuration on
start-up, and each write refused with the reason or applied to the running configuration."""

from __future__ import annotations

import copy

import py_trees
import pytest
import yaml
from tlt_interfaces.srv import SetBlackboardValue

from tlt_ars.config import ars_config_from_dict, default_config_path, load_ars_config
from tlt_ars.ground_writes import load_ground_writes
from tlt_common.bt.writable_blackboard import value_msg
from tlt_common.config_schema import ConfigError


@pytest.fixture
def raw():
    py_trees.blackboard.Blackboard.clear()
    yield copy.deepcopy(load_ars_config(default_config_path("ars_x")).raw)
    py_trees.blackboard.Blackboard.clear()


def _call(writes, key, value, kind=None):
    response = writes.on_request(
        SetBlackboardValue.Request(key=key, value=value_msg(value, kind)), SetBlackboardValue.Response()
    )
    return response.accepted, response.reason


def test_an_accepted_write_changes_the_running_configuration(raw):
    writes = load_ground_writes(raw)
    assert writes.value("settle_s") == raw["arm"]["settle_s"]
    assert _call(writes, "settle_s", 2.5) == (True, "")
    assert raw["arm"]["settle_s"] == 2.5 and writes.value("settle_s") == 2.5
    assert _call(writes, "motion_attempts", 3) == (True, "")
    assert raw["arm"]["motion_attempts"] == 3
    # An int is a valid float, and is kept as one.
    assert _call(writes, "fire_s", 1) == (True, "")
    assert raw["end_effector"]["fire_s"] == 1.0 and isinstance(raw["end_effector"]["fire_s"], float)
    assert py_trees.blackboard.Blackboard.get("/settle_s") == 2.5


@pytest.mark.parametrize(
    ("key", "value", "kind", "reason"),
    [
        ("velocity_scale", 0.9, None, "unknown key 'velocity_scale'"),
        ("settle_s", 11.0, None, "above the maximum 10"),
        ("motion_attempts", 0, None, "below the minimum 1"),
        ("motion_attempts", 2.0, "float", "expected int, got a float value"),
        ("planning_timeout_s", "slow", None, "expected float, got a str value"),
    ],
)
def test_a_refused_write_says_why_and_changes_nothing(raw, key, value, kind, reason):
    writes = load_ground_writes(raw)
    before = copy.deepcopy(raw)
    accepted, why = _call(writes, key, value, kind)
    assert not accepted and reason in why
    assert raw == before


def test_every_whitelisted_key_stands_for_a_configuration_entry(raw):
    writes = load_ground_writes(raw)
    for spec in writes.registry.writable():
        section, name = spec.config.split(".")
        assert name in raw[section], spec


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ("config: arm.sleep_s", "the ARS configuration has no entry 'arm.sleep_s'"),
        ("", "an ARS key names the configuration entry it stands for"),
    ],
)
def test_a_whitelist_that_does_not_fit_the_configuration_names_file_key_and_reason(
    raw, tmp_path, change, reason
):
    path = tmp_path / "ars_keys.yaml"
    path.write_text(
        f"keys:\n  settle_s: {{type: float, writable: true, meaning: m{', ' + change if change else ''}}}\n"
    )
    with pytest.raises(ConfigError) as err:
        load_ground_writes(raw, path)
    assert (err.value.source, err.value.key) == (str(path), "keys.settle_s.config")
    assert reason in err.value.reason


def test_a_configured_value_of_another_type_stops_the_ars(raw, tmp_path):
    path = tmp_path / "ars_keys.yaml"
    path.write_text("keys:\n  attempts: {type: int, writable: true, meaning: m, config: arm.settle_s}\n")
    with pytest.raises(ConfigError) as err:
        load_ground_writes(raw, path)
    assert err.value.key == "keys.attempts.config" and "holds float 1.0, the key is int" in err.value.reason


def test_the_ars_configuration_may_name_its_whitelist(tmp_path):
    config = load_ars_config(default_config_path("ars_x"))
    assert config.writable_blackboard_path is None
    path = tmp_path / "ars_keys.yaml"
    path.write_text(
        "keys:\n  attempts: {type: int, writable: true, meaning: m, config: arm.motion_attempts}\n"
    )
    data = yaml.safe_load(default_config_path("ars_x").read_text())
    named = ars_config_from_dict({**data, "writable_blackboard": str(path)})
    assert named.writable_blackboard_path == path
    writes = load_ground_writes(named.raw, named.writable_blackboard_path)
    assert [spec.name for spec in writes.registry.writable()] == ["attempts"]
