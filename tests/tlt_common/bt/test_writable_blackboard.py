"""The ground-writable blackboard registry: accepted writes land, every refusal changes nothing."""

from __future__ import annotations

from pathlib import Path

import py_trees
import pytest
from tlt_interfaces.msg import BlackboardValue

from tlt_common.bt.ground_keys import (
    GroundKey,
    dispenser_key,
    load_whitelists,
    member_key,
    route,
    writable_keys,
)
from tlt_common.bt.writable_blackboard import WritableBlackboard
from tlt_common.config_schema import ConfigError

REGISTRY = Path(__file__).resolve().parents[3] / "config" / "crs" / "writable_blackboard.yaml"


@pytest.fixture
def registry():
    py_trees.blackboard.Blackboard.clear()
    yield WritableBlackboard.load(REGISTRY)
    py_trees.blackboard.Blackboard.clear()


def storage() -> dict:
    return dict(py_trees.blackboard.Blackboard.storage)


def test_accepted_writes_go_to_the_blackboard(registry):
    assert registry.write("lifter_speed", 0.005).accepted
    assert registry.write("inspection_attempts", 3).accepted
    assert registry.write("compression_force", 10).accepted  # an int is a valid float
    assert registry.write("cross_frame_ars", "ars_y").accepted
    assert registry.write("clear_fault", True).accepted
    bb = py_trees.blackboard.Blackboard
    assert bb.get("/lifter_speed") == 0.005
    assert bb.get("/compression_force") == 10.0 and isinstance(bb.get("/compression_force"), float)
    assert bb.get("/cross_frame_ars") == "ars_y"


@pytest.mark.parametrize(
    ("key", "value", "reason"),
    [
        ("warp_drive", True, "unknown key 'warp_drive'"),
        ("started", True, "read-only"),
        ("tower_built", True, "read-only"),
        ("lifter_speed", "fast", "expected float, got str"),
        ("lifter_speed", True, "expected float, got bool"),
        ("inspection_attempts", 2.5, "expected int, got float"),
        ("clear_fault", 1, "expected bool, got int"),
        ("lifter_speed", 0.5, "above the maximum"),
        ("inspection_attempts", 0, "below the minimum"),
        ("cross_frame_ars", "ars_z", "not one of 'ars_x', 'ars_y'"),
        ("compression_force", float("nan"), "NaN"),
    ],
)
def test_refused_writes_change_nothing(registry, key, value, reason):
    registry.write("lifter_speed", 0.01)
    before = storage()
    result = registry.write(key, value)
    assert not result.accepted
    assert reason in result.reason
    assert storage() == before


def test_write_from_message(registry):
    ok = registry.write_msg(
        "lifter_speed", BlackboardValue(type=BlackboardValue.TYPE_FLOAT, float_value=0.004)
    )
    assert ok.accepted
    wrong = registry.write_msg(
        "lifter_speed", BlackboardValue(type=BlackboardValue.TYPE_STRING, string_value="x")
    )
    assert not wrong.accepted and "expected float, got a str value" in wrong.reason
    widened = registry.write_msg("lifter_speed", BlackboardValue(type=BlackboardValue.TYPE_INT, int_value=1))
    assert not widened.accepted and "above the maximum" in widened.reason
    bad_code = registry.write_msg("lifter_speed", BlackboardValue(type=9))
    assert not bad_code.accepted and "type code 9" in bad_code.reason
    assert py_trees.blackboard.Blackboard.get("/lifter_speed") == 0.004


def test_defaults_and_description(registry):
    registry.initialise_defaults()
    assert py_trees.blackboard.Blackboard.get("/inspection_attempts") == 2
    names = {d["name"] for d in registry.describe()}
    assert {"started", "clear_fault"} <= names


def test_namespace(tmp_path):
    path = tmp_path / "wb.yaml"
    path.write_text(
        "namespace: crs\nkeys:\n  speed: {type: float, writable: true, meaning: m, minimum: 0, maximum: 1}\n"
    )
    py_trees.blackboard.Blackboard.clear()
    registry = WritableBlackboard.load(path)
    assert registry.write("speed", 0.5).accepted
    assert py_trees.blackboard.Blackboard.get("/crs/speed") == 0.5


@pytest.mark.parametrize(
    ("text", "key", "reason"),
    [
        ("keys:\n  a: {type: complex, meaning: m}\n", "keys.a.type", "expected one of"),
        ("keys:\n  a: {type: int}\n", "keys.a.meaning", "missing required key"),
        ("keys:\n  a: {type: str, meaning: m, minimum: 1}\n", "keys.a", "apply to int and float"),
        ("keys:\n  a: {type: int, meaning: m, minimum: 5, maximum: 1}\n", "keys.a", "above maximum"),
        ("keys:\n  a: {type: int, meaning: m, default: x}\n", "keys.a", "default 'x'"),
        ("keys:\n  a: {type: bool, meaning: m, colour: red}\n", "keys.a.colour", "unknown key"),
        ("keys:\n  a/b: {type: bool, meaning: m}\n", "keys.a/b", "without '/'"),
        (
            "keys:\n  a: {type: int, meaning: m, writable: true, config: arm}\n",
            "keys.a",
            "config 'arm' is not 'section.name'",
        ),
        ("keys:\n  a: {type: int, meaning: m, config: arm.x}\n", "keys.a", "writable keys only"),
    ],
)
def test_bad_registry_files_name_file_key_reason(tmp_path, text, key, reason):
    path = tmp_path / "wb.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        WritableBlackboard.load(path)
    assert err.value.source == str(path)
    assert err.value.key == key
    assert reason in err.value.reason


def test_every_agents_project_whitelist_loads_and_routes_its_keys():
    whitelists = load_whitelists()
    assert set(whitelists) == {"crs", "ars_x", "ars_y"}
    keys = writable_keys(whitelists)
    assert "lifter_speed" in keys and "ars_x/settle_s" in keys and "ars_y/motion_attempts" in keys
    assert "started" not in keys  # read-only
    assert all(spec.config for key, spec in keys.items() if route(key).agent != "crs")
    assert route("ars_y/settle_s") == GroundKey("ars_y", "settle_s")
    assert route("crs/lifter_speed") == route("lifter_speed") == GroundKey("crs", "lifter_speed")
    assert route(member_key("bay1/vertical/x0_y1")) == GroundKey("tower", "bay1/vertical/x0_y1")
    assert route(dispenser_key("rivet_dispenser_x")) == GroundKey("dispenser", "rivet_dispenser_x")
    assert route("tower/bay1/cross_frame").agent is None


def test_a_bad_agent_whitelist_names_its_file(tmp_path):
    path = tmp_path / "ars.yaml"
    path.write_text("keys:\n  settle_s: {type: float, writable: true, meaning: m, minimum: 2, maximum: 1}\n")
    with pytest.raises(ConfigError) as err:
        load_whitelists({"ars_x": path})
    assert (err.value.source, err.value.key) == (str(path), "keys.settle_s")
    assert "above maximum" in err.value.reason
