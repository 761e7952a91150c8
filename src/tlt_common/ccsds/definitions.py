"""The command and telemetry definitions of the ground link, loaded from one YAML file.

Reads ``config/ccsds/definitions.yaml`` (or the file named by ``$TLT_CCSDS_DEFINITIONS``, or a path
given by the caller) and checks it with :mod:`tlt_common.config_schema` plus cross-checks (unique
APIDs and command ids, known enums, sane limits). Any problem raises :class:`ConfigError` naming the
file, the dotted key and the reason; nothing is half-loaded.
"""

from __future__ import annotations

import os
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tlt_common.ccsds.reasons import AckStage, Reason, Severity
from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate

DEFAULT_PATH = Path(__file__).resolve().parents[3] / "config" / "ccsds" / "definitions.yaml"
ENV_PATH = "TLT_CCSDS_DEFINITIONS"

INTEGER_TYPES = {
    "u8": (0, 2**8 - 1),
    "u16": (0, 2**16 - 1),
    "u32": (0, 2**32 - 1),
    "u64": (0, 2**64 - 1),
    "i8": (-(2**7), 2**7 - 1),
    "i16": (-(2**15), 2**15 - 1),
    "i32": (-(2**31), 2**31 - 1),
    "i64": (-(2**63), 2**63 - 1),
}
FLOAT_TYPES = ("f32", "f64")
FIELD_TYPES = (*INTEGER_TYPES, *FLOAT_TYPES, "bool", "enum", "string", "bytes", "value")
MAX_APID = 0x7FE  # 0x7FF is the idle APID of CCSDS 133.0-B


@dataclass(frozen=True)
class Limits:
    """Yellow and red ranges of a telemetry field; a value outside a range is in that colour."""

    yellow: tuple[float, float] | None = None
    red: tuple[float, float] | None = None

    def classify(self, value: Any) -> str | None:
        """Return ``"red"``, ``"yellow"`` or ``None`` (nominal) for a numeric value."""
        if isinstance(value, bool):
            value = int(value)
        if not isinstance(value, int | float):
            return None
        if self.red is not None and not self.red[0] <= value <= self.red[1]:
            return "red"
        if self.yellow is not None and not self.yellow[0] <= value <= self.yellow[1]:
            return "yellow"
        return None


@dataclass(frozen=True)
class FieldDef:
    """One field of a packet or one command parameter, in wire order."""

    name: str
    type: str
    unit: str = ""
    description: str = ""
    enum: tuple[str, ...] | None = None
    enum_name: str | None = None
    limits: Limits | None = None
    max_length: int | None = None
    optional: bool = False
    minimum: float | None = None
    maximum: float | None = None
    pattern: str | None = None
    actuator: bool = False


@dataclass(frozen=True)
class PacketDef:
    """A telemetry packet kind: its APID and fields."""

    name: str
    apid: int
    fields: tuple[FieldDef, ...]
    description: str = ""
    rate_hz: float | None = None


@dataclass(frozen=True)
class CommandDef:
    """One of the six ground commands of Table 1: its command id and parameters."""

    name: str
    id: int
    params: tuple[FieldDef, ...]
    description: str = ""
    hazardous: bool = False


@dataclass(frozen=True)
class ActuatorDef:
    """An actuator that Set Actuator State may drive."""

    name: str
    states: tuple[str, ...]
    value_minimum: float | None = None
    value_maximum: float | None = None
    unit: str = ""
    value_states: tuple[str, ...] = ()  # the states that need the value; the others take none


@dataclass(frozen=True)
class Definitions:
    """Everything both ends of the link agree on."""

    source: str
    version: int
    max_packet_bytes: int
    mac_bytes: int
    command_apid: int
    enums: Mapping[str, tuple[str, ...]]
    actuators: Mapping[str, ActuatorDef]
    commands: Mapping[str, CommandDef]
    telemetry: Mapping[str, PacketDef]
    commands_by_id: Mapping[int, CommandDef] = field(default_factory=dict)
    telemetry_by_apid: Mapping[int, PacketDef] = field(default_factory=dict)

    def command(self, name: str) -> CommandDef:
        try:
            return self.commands[name]
        except KeyError:
            raise KeyError(f"unknown command {name!r} (known: {', '.join(self.commands)})") from None

    def packet(self, name: str) -> PacketDef:
        try:
            return self.telemetry[name]
        except KeyError:
            known = ", ".join(self.telemetry)
            raise KeyError(f"unknown telemetry packet {name!r} (known: {known})") from None


_LIMITS = {"yellow": opt("list"), "red": opt("list")}
_FIELD = {
    "name": Field("str"),
    "type": Field("str", choices=FIELD_TYPES),
    "unit": opt("str", ""),
    "description": opt("str", ""),
    "enum": opt("str"),
    "limits": opt("dict", schema=_LIMITS),
    "max_length": opt("int", minimum=1),
    "optional": opt("bool", False),
    "minimum": opt("float"),
    "maximum": opt("float"),
    "pattern": opt("str"),
    "actuator": opt("bool", False),
}
_FIELD_LIST = Field("list", item=Field("dict", schema=_FIELD))
_SCHEMA = {
    "version": Field("int", choices=(1,)),
    "link": Field(
        "dict",
        schema={
            "max_packet_bytes": Field("int", minimum=64, maximum=65542),
            "mac_bytes": Field("int", minimum=16, maximum=32),
            "command_apid": Field("int", minimum=0, maximum=MAX_APID),
        },
    ),
    "enums": Field("map", item=Field("list", item=Field("str"), min_items=1)),
    "actuators": Field(
        "map",
        item=Field(
            "dict",
            schema={
                "states": Field("list", item=Field("str"), min_items=1),
                "value": opt(
                    "dict",
                    schema={
                        "minimum": Field("float"),
                        "maximum": Field("float"),
                        "unit": opt("str", ""),
                        "states": Field("list", item=Field("str"), min_items=1),
                    },
                ),
            },
        ),
    ),
    "commands": Field(
        "map",
        item=Field(
            "dict",
            schema={
                "id": Field("int", minimum=1, maximum=255),
                "description": opt("str", ""),
                "hazardous": opt("bool", False),
                "params": opt("list", [], item=Field("dict", schema=_FIELD)),
            },
        ),
    ),
    "telemetry": Field(
        "map",
        item=Field(
            "dict",
            schema={
                "apid": Field("int", minimum=0, maximum=MAX_APID),
                "description": opt("str", ""),
                "rate_hz": opt("float", minimum=0.0),
                "fields": _FIELD_LIST,
            },
        ),
    ),
}


def _as_f32(value: float) -> float:
    return struct.unpack(">f", struct.pack(">f", value))[0]


def _limits(raw: dict[str, Any] | None, source: str, key: str, f32: bool = False) -> Limits | None:
    """The limits of a field; for an ``f32`` field, each bound as the nearest f32 (the value the
    field can carry): a value sent exactly at its limit (0.1 m, which is 0.10000000149 as f32)
    is within it, not outside by the rounding."""
    if raw is None:
        return None
    pairs: dict[str, tuple[float, float] | None] = {}
    for colour in ("yellow", "red"):
        pair = raw.get(colour)
        if pair is None:
            pairs[colour] = None
            continue
        ok = len(pair) == 2 and all(isinstance(v, int | float) and not isinstance(v, bool) for v in pair)
        if not ok or pair[0] > pair[1]:
            raise ConfigError(
                source, f"{key}.limits.{colour}", "expected [low, high] numbers with low <= high"
            )
        low, high = float(pair[0]), float(pair[1])
        pairs[colour] = (_as_f32(low), _as_f32(high)) if f32 else (low, high)
    return Limits(**pairs)


def _field(raw: dict[str, Any], enums: Mapping[str, tuple[str, ...]], source: str, key: str) -> FieldDef:
    kind = raw["type"]
    enum_values = None
    if kind == "enum":
        if raw["enum"] is None:
            raise ConfigError(source, f"{key}.enum", "an enum field must name a list under `enums`")
        if raw["enum"] not in enums:
            raise ConfigError(source, f"{key}.enum", f"unknown enum {raw['enum']!r}")
        enum_values = enums[raw["enum"]]
        if len(enum_values) > 256:
            raise ConfigError(source, f"enums.{raw['enum']}", "an enum has at most 256 values")
    elif raw["enum"] is not None:
        raise ConfigError(source, f"{key}.enum", "only fields of type enum name an enum")
    max_length = raw["max_length"]
    if kind in ("string", "bytes", "value"):
        if max_length is None:
            raise ConfigError(source, f"{key}.max_length", f"a {kind} field needs max_length")
        if kind in ("string", "value") and max_length > 255:
            raise ConfigError(source, f"{key}.max_length", "strings hold at most 255 bytes")
    if raw["pattern"] is not None:
        try:
            re.compile(raw["pattern"])
        except re.error as exc:
            raise ConfigError(source, f"{key}.pattern", f"invalid regular expression: {exc}") from exc
    if raw["actuator"] and kind != "string":
        raise ConfigError(source, f"{key}.actuator", "only a string parameter can name an actuator")
    lo, hi = raw["minimum"], raw["maximum"]
    if lo is not None and hi is not None and lo > hi:
        raise ConfigError(source, f"{key}.minimum", "minimum is above maximum")
    return FieldDef(
        name=raw["name"],
        type=kind,
        unit=raw["unit"],
        description=raw["description"],
        enum=enum_values,
        enum_name=raw["enum"],
        limits=_limits(raw["limits"], source, key, f32=kind == "f32"),
        max_length=max_length,
        optional=raw["optional"],
        minimum=lo,
        maximum=hi,
        pattern=raw["pattern"],
        actuator=raw["actuator"],
    )


def _fields(raws: list[dict[str, Any]], enums: Mapping[str, tuple[str, ...]], source: str, key: str):
    out: list[FieldDef] = []
    seen: set[str] = set()
    for i, raw in enumerate(raws):
        fkey = f"{key}[{i}]"
        if raw["name"] in seen:
            raise ConfigError(source, f"{fkey}.name", f"duplicate field name {raw['name']!r}")
        seen.add(raw["name"])
        out.append(_field(raw, enums, source, fkey))
    return tuple(out)


def _check_enum(enums: Mapping[str, tuple[str, ...]], name: str, code_enum: Any, source: str) -> None:
    expected = tuple(member.name.lower() for member in code_enum)
    if enums.get(name) != expected:
        raise ConfigError(
            source, f"enums.{name}", f"must be exactly {list(expected)} (the codes the software sends)"
        )


def parse_definitions(data: Any, source: str | Path) -> Definitions:
    """Validate already-loaded YAML data and build :class:`Definitions`."""
    source = str(source)
    doc = validate(data, _SCHEMA, source=source)
    enums = {name: tuple(values) for name, values in doc["enums"].items()}
    for name, values in enums.items():
        if len(set(values)) != len(values):
            raise ConfigError(source, f"enums.{name}", "duplicate value")
    _check_enum(enums, "reason", Reason, source)
    _check_enum(enums, "ack_stage", AckStage, source)
    _check_enum(enums, "severity", Severity, source)

    actuators = {}
    for name, raw in doc["actuators"].items():
        value = raw["value"]
        if value is not None and value["minimum"] > value["maximum"]:
            raise ConfigError(source, f"actuators.{name}.value", "minimum is above maximum")
        if len(set(raw["states"])) != len(raw["states"]):
            raise ConfigError(source, f"actuators.{name}.states", "duplicate state")
        stray = [s for s in (value["states"] if value else ()) if s not in raw["states"]]
        if stray:
            raise ConfigError(
                source, f"actuators.{name}.value.states", f"not states of {name}: {', '.join(stray)}"
            )
        actuators[name] = ActuatorDef(
            name=name,
            states=tuple(raw["states"]),
            value_minimum=value["minimum"] if value else None,
            value_maximum=value["maximum"] if value else None,
            unit=value["unit"] if value else "",
            value_states=tuple(value["states"]) if value else (),
        )

    commands: dict[str, CommandDef] = {}
    by_id: dict[int, CommandDef] = {}
    for name, raw in doc["commands"].items():
        key = f"commands.{name}"
        if raw["id"] in by_id:
            raise ConfigError(
                source, f"{key}.id", f"command id {raw['id']} is already used by {by_id[raw['id']].name}"
            )
        params = _fields(raw["params"], enums, source, f"{key}.params")
        if any(p.actuator for p in params) and not actuators:
            raise ConfigError(source, key, "an actuator parameter needs the `actuators` section")
        labels = enums.get("command", ())
        if raw["id"] >= len(labels) or labels[raw["id"]] != name:
            raise ConfigError(
                source, f"{key}.id", f"enums.command[{raw['id']}] must be {name!r} (acks name commands by id)"
            )
        cmd = CommandDef(name, raw["id"], params, raw["description"], raw["hazardous"])
        commands[name] = cmd
        by_id[cmd.id] = cmd

    link = doc["link"]
    telemetry: dict[str, PacketDef] = {}
    by_apid: dict[int, PacketDef] = {}
    for name, raw in doc["telemetry"].items():
        key = f"telemetry.{name}"
        apid = raw["apid"]
        if apid == link["command_apid"]:
            raise ConfigError(source, f"{key}.apid", f"APID {apid:#05x} is the command APID")
        if apid in by_apid:
            raise ConfigError(
                source, f"{key}.apid", f"APID {apid:#05x} is already used by {by_apid[apid].name}"
            )
        pkt = PacketDef(
            name,
            apid,
            _fields(raw["fields"], enums, source, f"{key}.fields"),
            raw["description"],
            raw["rate_hz"],
        )
        telemetry[name] = pkt
        by_apid[apid] = pkt
    for needed in ("ack", "event", "link_stats"):
        if needed not in telemetry:
            raise ConfigError(
                source, f"telemetry.{needed}", "missing required packet (the link sends it itself)"
            )

    return Definitions(
        source=source,
        version=doc["version"],
        max_packet_bytes=link["max_packet_bytes"],
        mac_bytes=link["mac_bytes"],
        command_apid=link["command_apid"],
        enums=enums,
        actuators=actuators,
        commands=commands,
        telemetry=telemetry,
        commands_by_id=by_id,
        telemetry_by_apid=by_apid,
    )


def load_definitions(path: str | Path | None = None) -> Definitions:
    """Load the definitions file: ``path``, else ``$TLT_CCSDS_DEFINITIONS``, else the project's."""
    chosen = Path(path or os.environ.get(ENV_PATH) or DEFAULT_PATH)
    return parse_definitions(load_yaml(chosen), chosen)


__all__ = [
    "ActuatorDef",
    "CommandDef",
    "Definitions",
    "FieldDef",
    "Limits",
    "PacketDef",
    "load_definitions",
    "parse_definitions",
]
