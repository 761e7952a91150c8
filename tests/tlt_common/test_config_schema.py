"""The validator every YAML file goes through: defaults, nesting, ranges and exact error text."""

from __future__ import annotations

import pytest

from tlt_common.config_schema import ConfigError, Field, load_validated, opt, validate

SCHEMA = {
    "port": Field("str"),
    "rate_hz": opt("float", 50.0, minimum=1.0, maximum=1000.0),
    "mode": opt("str", "position", choices=("position", "velocity")),
    "servos": opt(
        "list",
        [],
        item=Field("dict", schema={"id": Field("int", minimum=0, maximum=252), "name": Field("str")}),
    ),
    "limits": opt("map", {}, item=Field("float")),
    "ids": opt(
        "list", [], item=Field("int"), check=lambda v: "ids repeat" if len(set(v)) != len(v) else None
    ),
}


def test_defaults_are_filled_and_ints_become_floats_where_numbers_are_expected():
    out = validate({"port": "/dev/ttyUSB0", "rate_hz": 100}, SCHEMA, source="f.yaml")
    assert out == {
        "port": "/dev/ttyUSB0",
        "rate_hz": 100.0,
        "mode": "position",
        "servos": [],
        "limits": {},
        "ids": [],
    }
    assert isinstance(out["rate_hz"], float)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({}, "f.yaml: port: missing required key (a string)"),
        ({"port": 3}, "f.yaml: port: expected a string, got int 3"),
        (
            {"port": "p", "rate": 1},
            "f.yaml: rate: unknown key (known keys: ids, limits, mode, port, rate_hz, servos)",
        ),
        ({"port": "p", "rate_hz": 0.5}, "f.yaml: rate_hz: expected at least 1.0, got 0.5"),
        ({"port": "p", "rate_hz": True}, "f.yaml: rate_hz: expected a number, got bool True"),
        (
            {"port": "p", "mode": "torque"},
            "f.yaml: mode: expected one of 'position', 'velocity', got 'torque'",
        ),
        (
            {"port": "p", "servos": [{"id": 1, "name": "a"}, {"id": 300, "name": "b"}]},
            "f.yaml: servos[1].id: expected at most 252, got 300",
        ),
        ({"port": "p", "servos": [{"id": 1}]}, "f.yaml: servos[0].name: missing required key (a string)"),
        ({"port": "p", "limits": {"lift": "high"}}, "f.yaml: limits.lift: expected a number, got str 'high'"),
        ({"port": "p", "ids": [1, 1]}, "f.yaml: ids: ids repeat"),
        ([1, 2], "f.yaml: expected a mapping, got list [1, 2]"),
    ],
)
def test_errors_name_the_file_the_key_and_the_reason(data, message):
    with pytest.raises(ConfigError) as info:
        validate(data, SCHEMA, source="f.yaml")
    assert str(info.value) == message


def test_changing_a_result_leaves_the_defaults_alone():
    first = validate({"port": "p"}, SCHEMA, source="f.yaml")
    first["servos"].append({"id": 1, "name": "a"})
    first["limits"]["lift"] = 1.0
    second = validate({"port": "p"}, SCHEMA, source="f.yaml")
    assert second["servos"] == [] and second["limits"] == {}


def test_input_is_not_changed():
    data = {"port": "p"}
    validate(data, SCHEMA, source="f.yaml")
    assert data == {"port": "p"}


def test_load_validated_reports_yaml_syntax_with_its_position(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("port: p\nrate_hz: [1,\n")
    with pytest.raises(ConfigError, match=rf"^{path}: invalid YAML: line 3, column 1: "):
        load_validated(path, SCHEMA)
