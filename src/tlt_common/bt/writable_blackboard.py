"""The registry of blackboard keys the ground may write ("Set Blackboard Value", Table 1).

Every key the ground may name is declared in YAML (``config/crs/writable_blackboard.yaml``) with
its type (bool, int, float, str), its range or choices, its meaning and whether it is writable.
Declared read-only keys are listed so a refusal can say "read-only" rather than "unknown", and
so operators can read what they mean. A write is checked against the declaration; a refused
write names the reason and changes nothing. An accepted write goes to the py_trees blackboard.

Each agent has one such file: the CRS ``config/crs/writable_blackboard.yaml``, each ARS
``config/ars/writable_blackboard.yaml``. An ARS's tree reads its tuning values from its
configuration, so its keys name that entry (``config: arm.settle_s``) and the ARS applies an
accepted write there (:mod:`tlt_ars.ground_writes`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import py_trees

from tlt_common.config_schema import ConfigError, Field, load_validated, opt

_TYPES = ("bool", "int", "float", "str")
_CONFIG_ENTRY = re.compile(r"[a-z_][a-z0-9_]*\.[a-z_][a-z0-9_]*")


def _check_key(entry: dict[str, Any]) -> str | None:
    kind = entry["type"]
    numeric = kind in ("int", "float")
    if not numeric and (entry["minimum"] is not None or entry["maximum"] is not None):
        return f"minimum/maximum apply to int and float keys, not {kind}"
    if entry["choices"] is not None and kind == "bool":
        return "choices do not apply to bool keys"
    bounded = numeric and entry["minimum"] is not None and entry["maximum"] is not None
    if bounded and entry["minimum"] > entry["maximum"]:
        return f"minimum {entry['minimum']} is above maximum {entry['maximum']}"
    if entry["choices"] is not None:
        for choice in entry["choices"]:
            problem = _type_problem(kind, choice)
            if problem:
                return f"choice {choice!r}: {problem}"
    if entry["config"] is not None and not _CONFIG_ENTRY.fullmatch(entry["config"]):
        return f"config {entry['config']!r} is not 'section.name'"
    if entry["config"] is not None and not entry["writable"]:
        return "config applies to writable keys only"
    if entry["default"] is not None:
        problem = _type_problem(kind, entry["default"]) or _range_problem(entry, entry["default"])
        if problem:
            return f"default {entry['default']!r}: {problem}"
    return None


KEY_SCHEMA = {
    "type": Field("str", choices=_TYPES, doc="bool, int, float or str"),
    "meaning": Field("str", doc="what the key means to an operator"),
    "writable": opt("bool", False),
    "minimum": opt("float"),
    "maximum": opt("float"),
    "choices": opt("list"),
    "default": opt("any"),
    "units": opt("str", ""),
    "config": opt("str", None, doc="the agent's configuration entry 'section.name' the key stands for"),
}

SCHEMA = {
    "namespace": opt("str", "", doc="blackboard namespace the keys live under, e.g. '' or 'crs'"),
    "keys": Field(
        "map",
        item=Field("dict", schema=KEY_SCHEMA, check=_check_key),
        doc="key name -> declaration",
    ),
}


def _type_problem(kind: str, value: Any) -> str | None:
    if kind == "bool":
        ok = isinstance(value, bool)
    elif kind == "int":
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind == "float":
        ok = isinstance(value, int | float) and not isinstance(value, bool)
    else:
        ok = isinstance(value, str)
    return None if ok else f"expected {kind}, got {type(value).__name__} {value!r}"


def _range_problem(entry: Mapping[str, Any], value: Any) -> str | None:
    if entry.get("choices") is not None and value not in entry["choices"]:
        return f"{value!r} is not one of {', '.join(repr(c) for c in entry['choices'])}"
    if entry.get("minimum") is not None and value < entry["minimum"]:
        return f"{value!r} is below the minimum {entry['minimum']:g}"
    if entry.get("maximum") is not None and value > entry["maximum"]:
        return f"{value!r} is above the maximum {entry['maximum']:g}"
    if isinstance(value, float) and value != value:
        return "NaN is not a value"
    return None


@dataclass(frozen=True)
class KeySpec:
    name: str
    type: str
    meaning: str
    writable: bool
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[Any, ...] | None = None
    default: Any = None
    units: str = ""
    config: str = ""


@dataclass(frozen=True)
class WriteResult:
    accepted: bool
    reason: str  # empty when accepted


class WritableBlackboard:
    """Checks ground writes against the declared keys and applies the accepted ones."""

    def __init__(self, keys: Mapping[str, KeySpec], namespace: str = "") -> None:
        self.keys = dict(keys)
        self.namespace = namespace.strip("/")
        self.source = ""

    @classmethod
    def load(cls, path: str | Path) -> WritableBlackboard:
        """Load and validate a registry file; raises ``ConfigError`` naming file, key and reason."""
        data = load_validated(path, SCHEMA)
        keys = {}
        for name, entry in data["keys"].items():
            if not name or "/" in name or "." in name:
                raise ConfigError(path, f"keys.{name}", "a key name must be non-empty without '/' or '.'")
            choices = tuple(entry["choices"]) if entry["choices"] is not None else None
            keys[name] = KeySpec(
                name,
                entry["type"],
                entry["meaning"],
                entry["writable"],
                entry["minimum"],
                entry["maximum"],
                choices,
                entry["default"],
                entry["units"],
                entry["config"] or "",
            )
        registry = cls(keys, data["namespace"])
        registry.source = str(path)
        return registry

    def blackboard_name(self, key: str) -> str:
        return f"/{self.namespace}/{key}" if self.namespace else f"/{key}"

    def check(self, key: str, value: Any) -> WriteResult:
        """Whether the ground may write ``value`` to ``key``, and why not."""
        spec = self.keys.get(key)
        if spec is None:
            return WriteResult(False, f"unknown key '{key}'")
        if not spec.writable:
            return WriteResult(False, f"key '{key}' is read-only")
        problem = _type_problem(spec.type, value)
        if problem is None:
            entry = {"choices": spec.choices, "minimum": spec.minimum, "maximum": spec.maximum}
            problem = _range_problem(entry, value)
        if problem:
            return WriteResult(False, f"key '{key}': {problem}")
        return WriteResult(True, "")

    def write(self, key: str, value: Any) -> WriteResult:
        """Check and, when accepted, set the key on the py_trees blackboard."""
        result = self.check(key, value)
        if result.accepted:
            spec = self.keys[key]
            py_trees.blackboard.Blackboard.set(
                self.blackboard_name(key), float(value) if spec.type == "float" else value
            )
        return result

    def writable(self) -> list[KeySpec]:
        """The keys the ground may write, in file order."""
        return [spec for spec in self.keys.values() if spec.writable]

    def write_msg(self, key: str, value_msg: Any) -> WriteResult:
        """Write a ``tlt_interfaces/BlackboardValue``: its ``type`` picks which field is the value."""
        kinds = {
            0: ("bool", "bool_value"),
            1: ("int", "int_value"),
            2: ("float", "float_value"),
            3: ("str", "string_value"),
        }
        if value_msg.type not in kinds:
            return WriteResult(False, f"value type code {value_msg.type} is not bool/int/float/string (0..3)")
        kind, field = kinds[value_msg.type]
        spec = self.keys.get(key)
        value = getattr(value_msg, field)
        if (
            spec is not None
            and spec.writable
            and spec.type != kind
            and not (spec.type == "float" and kind == "int")
        ):
            return WriteResult(False, f"key '{key}': expected {spec.type}, got a {kind} value")
        return self.write(key, value)

    def initialise_defaults(self) -> None:
        """Set every declared key that has a default and is not already on the blackboard."""
        storage = py_trees.blackboard.Blackboard.storage
        for spec in self.keys.values():
            name = self.blackboard_name(spec.name)
            if spec.default is not None and name not in storage:
                py_trees.blackboard.Blackboard.set(name, spec.default)

    def describe(self) -> list[dict[str, Any]]:
        """Every declared key as a plain dict, for operator displays."""
        return [spec.__dict__.copy() for spec in self.keys.values()]


def value_msg(value: Any, kind: str | None = None) -> Any:
    """``value`` as a ``tlt_interfaces/BlackboardValue`` of ``kind`` (bool, int, float, str; by
    default the value's own type): how a write travels to another agent's registry."""
    from tlt_interfaces.msg import BlackboardValue

    kind = kind or {bool: "bool", int: "int", float: "float"}.get(type(value), "str")
    msg = BlackboardValue()
    if kind == "bool":
        msg.type, msg.bool_value = BlackboardValue.TYPE_BOOL, bool(value)
    elif kind == "int":
        msg.type, msg.int_value = BlackboardValue.TYPE_INT, int(value)
    elif kind == "float":
        msg.type, msg.float_value = BlackboardValue.TYPE_FLOAT, float(value)
    else:
        msg.type, msg.string_value = BlackboardValue.TYPE_STRING, str(value)
    return msg


__all__ = ["SCHEMA", "KeySpec", "WritableBlackboard", "WriteResult", "value_msg"]
