"""Schema of a Dynamixel chain's YAML (config/hardware/active_grippers.yaml, camera_mounts.yaml, ee_*.yaml).

One file describes one U2D2 link: the port, the servos on it and, per servo, its operating mode,
the controller that commands it, joint limits and unit conversion. ``ee`` is present only for an
end effector (limit switch, rivet guns, calibration).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate
from tlt_drivers.dynamixel.control_table import MODEL_NUMBER_MX106_2, OPERATING_MODES

BAUDRATES = (57600, 115200, 1000000, 2000000, 3000000, 4000000)


def _joint_check(joint: dict[str, Any]) -> str | None:
    if joint["lower"] >= joint["upper"]:
        return f"lower limit {joint['lower']} is not below upper limit {joint['upper']}"
    if joint["unit"] == "m" and not joint["lead_m_per_rev"]:
        return "a joint in metres needs lead_m_per_rev (travel per lead-screw turn)"
    if joint["mode"] == "current_based_position" and joint["goal_current_ma"] is None:
        return "current_based_position needs goal_current_ma"
    if joint["mode"] == "velocity" and joint["controller"] != "none":
        return "a velocity-mode joint cannot be under a position controller (controller: none)"
    return None


JOINT_SCHEMA = {
    "name": Field("str", doc="joint name"),
    "id": Field("int", minimum=0, maximum=252, doc="Dynamixel id"),
    "mode": Field("str", choices=tuple(m for m in OPERATING_MODES if m != "current")),
    "controller": Field("str", choices=("trajectory", "group_position", "none")),
    "unit": Field("str", choices=("rad", "m")),
    "gear_ratio": opt("float", 1.0, minimum=1e-6, doc="servo turns per joint (or lead-screw) turn"),
    "lead_m_per_rev": opt("float", None, minimum=1e-6),
    "zero_ticks": opt("int", 2048, doc="ticks at which the joint reads 0"),
    "direction": opt("int", 1, choices=(1, -1)),
    "lower": Field("float", doc="lower joint limit"),
    "upper": Field("float", doc="upper joint limit"),
    "max_velocity": Field("float", minimum=1e-6, doc="profile velocity, joint units/s"),
    "goal_current_ma": opt("float", None, minimum=0.0, maximum=6878.0),
    "engaged_above": opt("float", None, doc="gripper joints: position above which it counts as engaged"),
}

COMM_SCHEMA = {
    "retries_per_transfer": opt("int", 2, minimum=0, maximum=10),
    "latency_timer_ms": opt(
        "float", 16.0, minimum=0.5, maximum=200.0, doc="USB latency the packet timeout allows for, twice"
    ),
    "recover_period_s": opt("float", 1.0, minimum=0.05),
    "reboot_on_hardware_error": opt("bool", True),
    "reboot_timeout_s": opt("float", 1.0, minimum=0.05, maximum=10.0),
}

TRAJECTORY_SCHEMA = {
    "path_tolerance": opt("float", 0.2, doc="default path tolerance, joint units (<=0: none)"),
    "goal_tolerance": opt("float", 0.02, doc="default goal tolerance, joint units (<=0: none)"),
    "goal_time_tolerance_s": opt("float", 0.5, minimum=0.0),
    # A servo entering its goal tolerance still moves (the position loop slows as it nears the
    # goal): what comes next, a camera frame or a grasp's hold, expects it at rest.
    "goal_velocity_tolerance": opt(
        "float", 0.05, doc="a goal succeeds only once each joint moves slower, units/s (<0: not checked)"
    ),
    "goal_settle_s": opt("float", 0.05, minimum=0.0, doc="...and has been that slow this long, s"),
    "max_time_step_s": opt(
        "float", 0.05, minimum=0.001, doc="most trajectory time one control cycle may move on, s"
    ),
    "path_lag_window_s": opt(
        "float", 0.5, minimum=0.0, doc="a joint this late along its path is not off it, s"
    ),
}

CALIBRATION_SCHEMA = {
    "direction": opt("int", -1, choices=(1, -1), doc="direction of travel towards the switch"),
    "speed": opt("float", 0.01, minimum=1e-6, doc="joint units/s while seeking the switch"),
    "switch_position": opt("float", 0.0, doc="joint value at the switch"),
    "max_travel": opt("float", 0.3, minimum=1e-6, doc="give up after this much travel"),
    "timeout_s": opt("float", 60.0, minimum=0.1),
    "on_start": opt("bool", True, doc="calibrate as soon as the driver is active"),
    "keep_within": opt(
        "float",
        0.002,
        minimum=0.0,
        doc="after a fault, the calibration holds while the width reads within this of its last reading "
        "(joint units; a servo that lost its multi-turn count reads whole turns off)",
    ),
    "release_travel": opt(
        "float",
        0.05,
        minimum=1e-6,
        doc="a part held when the count was lost counts as put down once no grasp presses and a grasp "
        "joint moved this far from where it held the part (rad)",
    ),
}

EE_SCHEMA = {
    "ars": Field("str", choices=("ars_x", "ars_y")),
    "width_joint": Field("str"),
    "grasp_joints": Field("list", item=Field("str"), min_items=1),
    "gpio_config": opt("str", None, doc="GPIO map YAML (relative paths: config/hardware/)"),
    "limit_switch_input": Field("str", doc="GPIO input name of the calibration limit switch"),
    "rivet_gun_outputs": Field("list", item=Field("str"), min_items=2),
    "grasp_effort_threshold": opt("float", 0.3, minimum=0.0, maximum=1.0),
    "calibration": opt(
        "dict", validate({}, CALIBRATION_SCHEMA, source="defaults"), schema=CALIBRATION_SCHEMA
    ),
}


def _chain_check(cfg: dict[str, Any]) -> str | None:
    names = [j["name"] for j in cfg["joints"]]
    ids = [j["id"] for j in cfg["joints"]]
    if len(set(names)) != len(names):
        return f"joint names repeat: {names}"
    if len(set(ids)) != len(ids):
        return f"servo ids repeat: {ids}"
    ee = cfg.get("ee")
    if ee:
        for name in [ee["width_joint"], *ee["grasp_joints"]]:
            if name not in names:
                return f"ee names joint {name!r}, which is not in joints"
    return None


CHAIN_SCHEMA = {
    "component": Field("str", doc="component name, e.g. active_grippers"),
    "port": Field("str", doc="serial device of the U2D2"),
    "baudrate": opt("int", 1000000, choices=BAUDRATES),
    "rate_hz": opt("float", 100.0, minimum=1.0, maximum=1000.0),
    "state_rate_hz": opt("float", 20.0, minimum=0.1, maximum=1000.0),
    "model_number": opt("int", MODEL_NUMBER_MX106_2),
    "stall_current_ma": opt("float", 5200.0, minimum=1.0, doc="current that reads as effort 1.0"),
    "comm": opt("dict", validate({}, COMM_SCHEMA, source="defaults"), schema=COMM_SCHEMA),
    "trajectory": opt("dict", validate({}, TRAJECTORY_SCHEMA, source="defaults"), schema=TRAJECTORY_SCHEMA),
    "joints": Field("list", item=Field("dict", schema=JOINT_SCHEMA, check=_joint_check), min_items=1),
    "ee": opt("dict", None, schema=EE_SCHEMA),
}


def validate_chain(data: Any, source: str | Path = "<dict>") -> dict[str, Any]:
    """Validate a chain config given as data (tests, or a launch set that builds one)."""
    cfg = validate(data, CHAIN_SCHEMA, source=source)
    problem = _chain_check(cfg)
    if problem:
        raise ConfigError(source, "joints", problem)
    return cfg


def load_chain(path: str | Path) -> dict[str, Any]:
    """Load and validate a chain YAML file; :class:`ConfigError` names file, key and reason."""
    return validate_chain(load_yaml(path), path)
