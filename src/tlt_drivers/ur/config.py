"""The UR driver's configuration (``config/hardware/ur_x.yaml``, ``ur_y.yaml``), validated on load."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from tlt_common.config_schema import ConfigError, Field, load_validated, opt

CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "hardware"
DEFAULT_CONFIG = CONFIG_DIR / "ur_x.yaml"

# UR10e published limits: +-360 deg on every joint; 120 deg/s (base, shoulder), 180 deg/s (others).
UR10E_POSITION_LIMIT = 2 * math.pi
UR10E_MAX_VELOCITY = (math.radians(120),) * 2 + (math.radians(180),) * 4


def _check_joints(joints: list) -> str | None:
    if len(joints) != 6:
        return f"expected the 6 joints of a UR10e, got {len(joints)}"
    names = [j["name"] for j in joints]
    if len(set(names)) != len(names):
        return f"joint names must be unique, got {names}"
    for i, j in enumerate(joints):
        if j["min_position"] >= j["max_position"]:
            return f"joint {j['name']}: min_position must be below max_position"
        if (
            j["min_position"] < -UR10E_POSITION_LIMIT - 1e-3
            or j["max_position"] > UR10E_POSITION_LIMIT + 1e-3
        ):
            limit = UR10E_POSITION_LIMIT
            return f"joint {j['name']}: limits must lie within the UR10e range of +-{limit:.4f} rad"
        if j["max_velocity"] > UR10E_MAX_VELOCITY[i] + 1e-3:
            return (
                f"joint {j['name']}: max_velocity above the UR10e limit of {UR10E_MAX_VELOCITY[i]:.4f} rad/s"
            )
    return None


JOINT_SCHEMA = {
    "name": Field("str"),
    "min_position": Field("float", doc="lower position limit, rad"),
    "max_position": Field("float", doc="upper position limit, rad"),
    "max_velocity": Field("float", minimum=1e-6, doc="rad/s"),
}

UR_SCHEMA = {
    "component": Field("str", doc="name reported on HardwareStatus, e.g. ur_x"),
    "host": Field("str", doc="controller address (the emulator's loopback address in simulation)"),
    "rtde_frequency_hz": opt("float", 500.0, minimum=1.0, maximum=500.0),
    "control_rate_hz": opt("float", 125.0, minimum=1.0, maximum=500.0),
    "joint_state_rate_hz": opt(
        "float", 50.0, minimum=1.0, maximum=500.0, doc="JointState publications per second of ROS time"
    ),
    "status_rate_hz": opt("float", 2.0, minimum=0.1, maximum=100.0),
    "link_timeout_s": opt(
        "float", 0.5, minimum=0.01, doc="no new controller data for this long is a link fault"
    ),
    "probe_timeout_s": opt("float", 0.5, minimum=0.01),
    "reconnect_period_s": opt("float", 1.0, minimum=0.05),
    "auto_restart_program": opt("bool", True, doc="re-upload the control script when it stops"),
    "move_velocity": opt("float", 1.0, minimum=1e-3, maximum=3.14, doc="moveJ speed, rad/s"),
    "move_acceleration": opt("float", 1.4, minimum=1e-3, maximum=40.0, doc="moveJ acceleration, rad/s^2"),
    "servo_lookahead_s": opt("float", 0.05, minimum=0.03, maximum=0.2),
    "servo_gain": opt("float", 1000.0, minimum=100.0, maximum=2000.0),
    "stop_deceleration": opt("float", 3.0, minimum=0.1, maximum=40.0, doc="rad/s^2 for stopJ/servoStop"),
    "default_path_tolerance": opt("float", 0.1, minimum=0.0),
    "default_goal_tolerance": opt("float", 0.01, minimum=0.0),
    "default_goal_time_tolerance_s": opt("float", 1.0, minimum=0.0),
    "default_goal_velocity_tolerance": opt(
        "float", 0.01, doc="rad/s a joint may still move at its goal; negative: not checked"
    ),
    "goal_settle_s": opt(
        "float", 0.1, minimum=0.0, doc="how long the arm stays within its goal tolerances before success, s"
    ),
    "max_trajectory_step_s": opt(
        "float", 0.05, minimum=0.001, doc="most trajectory time one control cycle may move on, s"
    ),
    "path_lag_window_s": opt(
        "float", 0.5, minimum=0.0, doc="an arm this late along its path is not off it, s"
    ),
    "joints": Field("list", item=Field("dict", schema=JOINT_SCHEMA), check=_check_joints),
}


@dataclass(frozen=True)
class URJoint:
    name: str
    min_position: float
    max_position: float
    max_velocity: float


@dataclass(frozen=True)
class URConfig:
    """Everything the UR driver reads from configuration."""

    component: str
    host: str
    joints: tuple[URJoint, ...]
    rtde_frequency_hz: float = 500.0
    control_rate_hz: float = 125.0
    joint_state_rate_hz: float = 50.0
    status_rate_hz: float = 2.0
    link_timeout_s: float = 0.5
    probe_timeout_s: float = 0.5
    reconnect_period_s: float = 1.0
    auto_restart_program: bool = True
    move_velocity: float = 1.0
    move_acceleration: float = 1.4
    servo_lookahead_s: float = 0.05
    servo_gain: float = 1000.0
    stop_deceleration: float = 3.0
    default_path_tolerance: float = 0.1
    default_goal_tolerance: float = 0.01
    default_goal_time_tolerance_s: float = 1.0
    default_goal_velocity_tolerance: float = 0.01
    goal_settle_s: float = 0.1
    max_trajectory_step_s: float = 0.05
    path_lag_window_s: float = 0.5

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def limits(self) -> dict[str, tuple[float, float]]:
        return {j.name: (j.min_position, j.max_position) for j in self.joints}


def load_ur_config(path: str | Path = DEFAULT_CONFIG) -> URConfig:
    """Load and validate a UR arm's YAML; ``ConfigError`` names the file, key and reason."""
    doc = load_validated(path, UR_SCHEMA)
    if doc["link_timeout_s"] <= 1.0 / doc["rtde_frequency_hz"]:
        raise ConfigError(path, "link_timeout_s", "must be longer than one RTDE period")
    if doc["joint_state_rate_hz"] > doc["control_rate_hz"]:
        raise ConfigError(
            path,
            "joint_state_rate_hz",
            "joint states go out from the control cycle: "
            f"at most control_rate_hz ({doc['control_rate_hz']:g})",
        )
    joints = tuple(URJoint(**j) for j in doc.pop("joints"))
    return URConfig(joints=joints, **doc)


def with_rtde_frequency(config: URConfig, hz: float, path: str | Path) -> URConfig:
    """``config`` asking the controller for ``hz`` (a launch set's override of the file at
    ``path``); ``ConfigError`` under the file's key when the rate is out of range or the link
    timeout is not longer than one period."""
    if not 1.0 <= hz <= 500.0:
        raise ConfigError(path, "rtde_frequency_hz", f"{hz:g} given: must be 1 to 500")
    if config.link_timeout_s <= 1.0 / hz:
        why = f"{hz:g} given: link_timeout_s must be longer than one RTDE period"
        raise ConfigError(path, "rtde_frequency_hz", why)
    return replace(config, rtde_frequency_hz=hz)


def with_link_timeout(config: URConfig, seconds: float, path: str | Path) -> URConfig:
    """``config`` declaring the link down after ``seconds`` without new controller data (a launch
    set's override of the file at ``path``); ``ConfigError`` when it is not longer than one RTDE
    period."""
    if seconds <= 1.0 / config.rtde_frequency_hz:
        why = f"{seconds:g} given: must be longer than one RTDE period ({1.0 / config.rtde_frequency_hz:g} s)"
        raise ConfigError(path, "link_timeout_s", why)
    return replace(config, link_timeout_s=seconds)


__all__ = [
    "CONFIG_DIR",
    "DEFAULT_CONFIG",
    "UR_SCHEMA",
    "URConfig",
    "URJoint",
    "load_ur_config",
    "with_link_timeout",
    "with_rtde_frequency",
]
