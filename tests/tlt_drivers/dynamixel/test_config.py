"""Chain YAML validation: every mistake is named with its key and reason."""

from __future__ import annotations

import pytest

from tlt_common.config_schema import ConfigError
from tlt_drivers.dynamixel.config import validate_chain


def joint(**over):
    base = {
        "name": "a",
        "id": 1,
        "mode": "position",
        "controller": "trajectory",
        "unit": "rad",
        "lower": -1.0,
        "upper": 1.0,
        "max_velocity": 1.0,
    }
    return {**base, **over}


def chain(*joints, **over):
    return {"component": "c", "port": "/dev/null", "joints": list(joints), **over}


@pytest.mark.parametrize(
    ("data", "key", "words"),
    [
        (chain(joint(), joint(name="b")), "joints", "servo ids repeat"),
        (chain(joint(), joint(id=2)), "joints", "joint names repeat"),
        (chain(joint(lower=1.0, upper=0.0)), "joints[0]", "not below upper limit"),
        (chain(joint(mode="current_based_position")), "joints[0]", "needs goal_current_ma"),
        (
            chain(joint(mode="velocity")),
            "joints[0]",
            "velocity-mode joint cannot be under a position controller",
        ),
        (chain(joint(mode="pwm")), "joints[0].mode", "expected one of"),
        (chain(joint(id=300)), "joints[0].id", "at most 252"),
        (chain(joint(), baudrate=12345), "baudrate", "expected one of"),
        (
            chain(
                joint(),
                ee={
                    "ars": "ars_x",
                    "width_joint": "w",
                    "grasp_joints": ["a"],
                    "limit_switch_input": "s",
                    "rivet_gun_outputs": ["l", "r"],
                },
            ),
            "joints",
            "ee names joint 'w'",
        ),
        (chain(joint(), comm={"retries": 3}), "comm.retries", "unknown key"),
    ],
)
def test_mistakes_are_named(data, key, words):
    with pytest.raises(ConfigError) as info:
        validate_chain(data, "x.yaml")
    assert info.value.key == key and words in info.value.reason


def test_defaults_filled():
    cfg = validate_chain(chain(joint()))
    assert cfg["comm"]["retries_per_transfer"] == 2 and cfg["comm"]["latency_timer_ms"] == 16.0
    assert cfg["trajectory"]["goal_time_tolerance_s"] == 0.5 and cfg["ee"] is None
    assert cfg["joints"][0]["zero_ticks"] == 2048
