"""The shared definitions file loads, is checked on load, and grows by one YAML edit."""

from __future__ import annotations

import copy

import pytest
import yaml

from tlt_common.ccsds.codec import encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import DEFAULT_PATH, load_definitions, parse_definitions
from tlt_common.ccsds.reasons import Reason
from tlt_common.config_schema import ConfigError


@pytest.fixture(scope="module")
def raw_doc():
    return yaml.safe_load(DEFAULT_PATH.read_text())


def test_project_file_has_table_1_commands_and_telemetry():
    defs = load_definitions()
    assert [c for c in defs.commands] == [
        "start",
        "stop",
        "pause",
        "resume",
        "set_blackboard_value",
        "set_actuator_state",
        "switch_tm_key",  # link management: telemetry key rotation
    ]
    assert {c.id for c in defs.commands.values()} == {1, 2, 3, 4, 5, 6, 7}
    assert defs.commands["stop"].hazardous and defs.commands["set_actuator_state"].hazardous
    assert not defs.commands["start"].hazardous
    for kind in (
        "ack",
        "event",
        "link_stats",
        "tree_status",
        "hk_lifter",
        "hk_grippers",
        "hk_ee",
        "hk_arm_joints",
        "hk_mission",
    ):
        assert kind in defs.telemetry
    apids = [p.apid for p in defs.telemetry.values()] + [defs.command_apid]
    assert len(apids) == len(set(apids))
    assert defs.enums["reason"] == tuple(r.name.lower() for r in Reason)


def test_limits_classify_values():
    lifter = load_definitions().packet("hk_lifter")
    position = next(f for f in lifter.fields if f.name == "position_0")
    assert position.unit == "m"
    assert position.limits.classify(1.0) is None
    assert position.limits.classify(1.95) == "yellow"
    assert position.limits.classify(2.5) == "red"
    link_ok = next(f for f in lifter.fields if f.name == "link_ok")
    assert link_ok.limits.classify(True) is None
    assert link_ok.limits.classify(False) == "red"


def test_an_f32_value_sent_exactly_at_its_limit_is_within_it(raw_doc):
    """0.1 m travels as the f32 0.10000000149: against a red limit 0.1 as written it would be red;
    an f32 field's limits are the nearest f32 values, so it is only yellow (above 0.09)."""
    from tlt_common.ccsds.codec import encode_telemetry, parse_datagram

    def tight(doc):
        width = next(f for f in doc["telemetry"]["hk_ee"]["fields"] if f["name"] == "width")
        width["limits"] = {"yellow": [0.0, 0.09], "red": [-0.002, 0.1]}

    defs = parse_definitions(_broken(raw_doc, tight), "defs.yaml")
    values = {
        "ars": "ars_x", "grasp_left": 0.0, "grasp_right": 0.0, "width": 0.1, "max_load": 0.7,
        "calibrated": True, "part_grasped": False, "rivet_guns": 0, "fault": False,
    }  # fmt: skip
    packet = parse_datagram(encode_telemetry(defs, "hk_ee", values, seq_count=1, timestamp=1.0), defs)
    fields = {f.name: f for f in defs.packet("hk_ee").fields}
    assert (
        packet.fields["width"] != 0.1 and fields["width"].limits.classify(packet.fields["width"]) == "yellow"
    )
    assert fields["width"].limits.classify(0.1001) == "red"


def test_the_shipped_limits_leave_the_hardwares_travel_in_the_green():
    """An end effector's width slide runs 0-0.35 m and the lifter 0-1.2 m (config/hardware): a
    nominal build, which opens the width to 0.25 m for a diagonal and raises the Active Grippers
    past a metre, raises no limit event."""
    defs = load_definitions()
    width = next(f for f in defs.packet("hk_ee").fields if f.name == "width")
    height = next(f for f in defs.packet("hk_grippers").fields if f.name == "active_height")
    assert width.limits.classify(0.25) is None and width.limits.classify(0.1) is None
    assert height.limits.classify(1.05) is None and height.limits.classify(1.25) == "red"


def _broken(raw_doc, change):
    doc = copy.deepcopy(raw_doc)
    change(doc)
    return doc


@pytest.mark.parametrize(
    ("change", "key", "words"),
    [
        (lambda d: d["telemetry"]["hk_ee"].update(apid=0x040), "telemetry.hk_ee.apid", "already used"),
        (lambda d: d["commands"]["pause"].update(id=1), "commands.pause.id", "already used"),
        (
            lambda d: d["telemetry"]["hk_lifter"]["fields"][0].update(enum="nope"),
            "telemetry.hk_lifter.fields[0].enum",
            "unknown enum",
        ),
        (
            lambda d: d["telemetry"]["hk_mission"]["fields"][8].pop("max_length"),
            "telemetry.hk_mission.fields[8].max_length",
            "needs max_length",
        ),
        (
            lambda d: d["telemetry"]["hk_lifter"]["fields"][1].update(limits={"red": [3, 1]}),
            "telemetry.hk_lifter.fields[1].limits.red",
            "low <= high",
        ),
        (
            lambda d: d["telemetry"]["hk_lifter"]["fields"][1].update(type="float128"),
            "telemetry.hk_lifter.fields[1].type",
            "expected one of",
        ),
        (lambda d: d["enums"]["reason"].reverse(), "enums.reason", "must be exactly"),
        (
            lambda d: d["telemetry"]["hk_lifter"].update(colour="red"),
            "telemetry.hk_lifter.colour",
            "unknown key",
        ),
        (lambda d: d["telemetry"].pop("ack"), "telemetry.ack", "missing required packet"),
        (lambda d: d["telemetry"]["hk_tower"].update(apid=0x010), "telemetry.hk_tower.apid", "command APID"),
        (
            lambda d: d["actuators"]["camera_mounts"]["value"].update(states=["warp"]),
            "actuators.camera_mounts.value.states",
            "not states of camera_mounts: warp",
        ),
        (
            lambda d: d["actuators"]["lifter"].update(states=["safe", "safe"]),
            "actuators.lifter.states",
            "duplicate state",
        ),
    ],
)
def test_errors_name_file_key_and_reason(raw_doc, change, key, words):
    with pytest.raises(ConfigError) as info:
        parse_definitions(_broken(raw_doc, change), "defs.yaml")
    assert info.value.source == "defs.yaml"
    assert info.value.key == key
    assert words in info.value.reason


def test_adding_a_housekeeping_field_is_one_yaml_edit(tmp_path):
    text = DEFAULT_PATH.read_text()
    anchor = "      - {name: link_ok, type: bool, limits: {yellow: [1, 1], red: [1, 1]}}\n"
    assert anchor in text
    added = (
        "      - {name: motor_temperature, type: f32, unit: degC,"
        " limits: {yellow: [0, 60], red: [-10, 80]}}\n"
    )
    edited = tmp_path / "definitions.yaml"
    edited.write_text(text.replace(anchor, anchor + added))
    defs = load_definitions(edited)
    values = {
        "state": "safe",
        "position_0": 0.1,
        "position_1": 0.1,
        "position_2": 0.1,
        "position_3": 0.1,
        "velocity": 0,
        "limit_switches": 0,
        "watchdog_tripped": False,
        "link_ok": True,
        "motor_temperature": 71.5,
    }
    packet = parse_datagram(encode_telemetry(defs, "hk_lifter", values, seq_count=1), defs)
    assert packet.ok
    assert packet.fields["motor_temperature"] == pytest.approx(71.5)
    field = defs.packet("hk_lifter").fields[-1]
    assert (field.unit, field.limits.classify(71.5)) == ("degC", "yellow")


def test_env_variable_selects_the_file(tmp_path, monkeypatch):
    other = tmp_path / "d.yaml"
    other.write_text(DEFAULT_PATH.read_text().replace("max_packet_bytes: 2048", "max_packet_bytes: 4096"))
    monkeypatch.setenv("TLT_CCSDS_DEFINITIONS", str(other))
    assert load_definitions().max_packet_bytes == 4096
    with pytest.raises(ConfigError, match="cannot read file"):
        load_definitions(tmp_path / "missing.yaml")
