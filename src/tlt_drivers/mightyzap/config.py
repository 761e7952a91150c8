"""Schema of the Top Grippers' YAML (config/hardware/top_grippers.yaml): one IR-USB02 port, N MightyZAPs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate


def _actuator_check(act: dict[str, Any]) -> str | None:
    if act["lower"] >= act["upper"]:
        return f"lower limit {act['lower']} is not below upper limit {act['upper']}"
    return None


ACTUATOR_SCHEMA = {
    "name": Field("str"),
    "id": Field("int", minimum=0, maximum=253),
    "lower": Field("float", doc="lower stroke limit, m"),
    "upper": Field("float", doc="upper stroke limit, m"),
    "engaged_above": Field("float", doc="stroke (m) beyond which the push pin counts as engaged"),
}

COMM_SCHEMA = {
    "retries_per_transfer": opt("int", 2, minimum=0, maximum=10),
    "response_timeout_s": opt("float", 0.05, minimum=0.001, maximum=1.0),
    "recover_period_s": opt("float", 1.0, minimum=0.05),
}

SCHEMA = {
    "component": Field("str"),
    "port": Field("str"),
    "baudrate": opt("int", 57600, choices=(9600, 19200, 57600, 115200)),
    "rate_hz": opt("float", 20.0, minimum=1.0, maximum=200.0),
    "state_rate_hz": opt("float", 10.0, minimum=0.1, maximum=200.0),
    "feedback_return_mode": opt(
        "int", 1, choices=(1, 2), doc="1: answers to reads only; 2: to every command"
    ),
    "stroke_m": Field("float", minimum=1e-4, doc="full stroke of the actuator, m"),
    "full_stroke_ticks": opt("int", 4095, minimum=1),
    "goal_speed": opt("int", 1023, minimum=1, maximum=1023),
    "goal_current": opt("int", 800, minimum=0, maximum=1600),
    "comm": opt("dict", validate({}, COMM_SCHEMA, source="defaults"), schema=COMM_SCHEMA),
    "actuators": Field(
        "list", item=Field("dict", schema=ACTUATOR_SCHEMA, check=_actuator_check), min_items=1
    ),
}


def validate_mightyzap(data: Any, source: str | Path = "<dict>") -> dict[str, Any]:
    cfg = validate(data, SCHEMA, source=source)
    names = [a["name"] for a in cfg["actuators"]]
    ids = [a["id"] for a in cfg["actuators"]]
    if len(set(names)) != len(names) or len(set(ids)) != len(ids):
        raise ConfigError(source, "actuators", f"names or ids repeat: {names} / {ids}")
    for i, act in enumerate(cfg["actuators"]):
        if act["lower"] < 0 or act["upper"] > cfg["stroke_m"]:
            raise ConfigError(
                source, f"actuators[{i}]", f"limits must lie within the stroke 0..{cfg['stroke_m']} m"
            )
    return cfg


def load_mightyzap(path: str | Path) -> dict[str, Any]:
    return validate_mightyzap(load_yaml(path), path)
