"""The lifter driver's configuration (``config/hardware/lifter.yaml``), validated on load."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from tlt_common.config_schema import ConfigError, Field, load_validated, opt

from .protocol import NUM_MOTORS

DEFAULT_CONFIG = Path(__file__).resolve().parents[3] / "config" / "hardware" / "lifter.yaml"


def _check_joints(joints: list) -> str | None:
    if len(joints) != NUM_MOTORS:
        return f"expected {NUM_MOTORS} joints (one per lifter motor), got {len(joints)}"
    names = [j["name"] for j in joints]
    if len(set(names)) != len(names):
        return f"joint names must be unique, got {names}"
    for j in joints:
        if j["min_position_m"] >= j["max_position_m"]:
            return f"joint {j['name']}: min_position_m must be below max_position_m"
    return None


JOINT_SCHEMA = {
    "name": Field("str"),
    "counts_per_m": Field("float", minimum=1.0, doc="encoder counts per metre of travel"),
    "min_position_m": Field("float"),
    "max_position_m": Field("float"),
    "max_velocity_m_s": Field("float", minimum=1e-6),
}

LIFTER_SCHEMA = {
    "port": Field("str", doc="serial device of the Teensy"),
    "baudrate": opt("int", 115200, minimum=1200),
    "command_rate_hz": Field("float", minimum=1.0, maximum=1000.0),
    "answer_timeout_s": opt("float", 0.25, minimum=0.001, maximum=10.0),
    "link_timeout_s": opt("float", 0.2, minimum=0.001, maximum=10.0),
    "reconnect_period_s": opt("float", 1.0, minimum=0.01, maximum=60.0),
    "status_rate_hz": opt("float", 2.0, minimum=0.1, maximum=100.0),
    "controller": Field(
        "dict",
        schema={
            "position_gain": opt("float", 2.0, minimum=0.0),
            "default_goal_tolerance_m": opt("float", 0.002, minimum=0.0),
            "default_path_tolerance_m": opt("float", 0.02, minimum=0.0),
            "default_goal_time_tolerance_s": opt("float", 1.0, minimum=0.0),
        },
    ),
    "joints": Field("list", item=Field("dict", schema=JOINT_SCHEMA), check=_check_joints),
}


@dataclass(frozen=True)
class JointConfig:
    """One lead-screw joint: encoder scale, travel limits and speed limit."""

    name: str
    counts_per_m: float
    min_position_m: float
    max_position_m: float
    max_velocity_m_s: float

    @property
    def max_velocity_counts_s(self) -> int:
        return int(self.max_velocity_m_s * self.counts_per_m)


@dataclass(frozen=True)
class ControllerConfig:
    position_gain: float = 2.0
    default_goal_tolerance_m: float = 0.002
    default_path_tolerance_m: float = 0.02
    default_goal_time_tolerance_s: float = 1.0


@dataclass(frozen=True)
class LifterConfig:
    """Everything the lifter driver and its controller read from configuration."""

    port: str
    joints: tuple[JointConfig, ...]
    baudrate: int = 115200
    command_rate_hz: float = 50.0
    answer_timeout_s: float = 0.25
    link_timeout_s: float = 0.2
    reconnect_period_s: float = 1.0
    status_rate_hz: float = 2.0
    controller: ControllerConfig = ControllerConfig()

    @property
    def command_period_s(self) -> float:
        return 1.0 / self.command_rate_hz

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def with_port(self, port: str) -> LifterConfig:
        return replace(self, port=port)


def load_lifter_config(path: str | Path = DEFAULT_CONFIG) -> LifterConfig:
    """Load and validate the lifter's YAML. Raises ``ConfigError`` naming the file, key and reason."""
    doc = load_validated(path, LIFTER_SCHEMA)
    if doc["link_timeout_s"] <= 1.0 / doc["command_rate_hz"]:
        raise ConfigError(path, "link_timeout_s", "must be longer than one command period")
    return LifterConfig(
        port=doc["port"],
        joints=tuple(JointConfig(**j) for j in doc["joints"]),
        baudrate=doc["baudrate"],
        command_rate_hz=doc["command_rate_hz"],
        answer_timeout_s=doc["answer_timeout_s"],
        link_timeout_s=doc["link_timeout_s"],
        reconnect_period_s=doc["reconnect_period_s"],
        status_rate_hz=doc["status_rate_hz"],
        controller=ControllerConfig(**doc["controller"]),
    )


__all__ = [
    "DEFAULT_CONFIG",
    "LIFTER_SCHEMA",
    "ControllerConfig",
    "JointConfig",
    "LifterConfig",
    "load_lifter_config",
]
