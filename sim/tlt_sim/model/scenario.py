"""Scenarios: the faults a twin run injects, read from ``config/twin/scenarios/*.yaml``.

Part faults are the model's: a defective part (a strut without one end fitting, or with a bent
tube) is built that way; an empty dispenser is built with no parts; a grasp that slips lets go
after some seconds; a part taken off-centre ends up placed out of tolerance. Rivet faults spoil a
chosen joint's shot, or joints drawn at random with a seed, as one of the ways a rivet fails
(:mod:`tlt_sim.model.rivet_outcomes`). Device faults (a servo
failure, a stuck lifter limit switch, a dropped link) belong to the emulators: they are validated
here and handed on unchanged in :attr:`Scenario.device_faults`.

``built`` lists members of the first bay that stand in the tower from the start, placed and
riveted as the mission says, their parts and rivets taken from the dispensers in order: a run can
begin late in a bay (a test of the last member, the bay test or the foundation rivets) without
building the rest first. The CRS must be told the same in its tower model.

:func:`load_scenario` refuses a file with a missing, unknown, out-of-range or inconsistent key
(a dispenser the mission does not have, a part index beyond its count) with ``ConfigError``
naming the file, the dotted key and the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate
from tlt_common.mission.schema import ARS_NAMES, Mission
from tlt_sim.model.rivet_outcomes import FAULT_KINDS, NO_FAULTS, RandomRivetFaults, RivetFaultPlan

DEFECTS = ("missing_end_fitting", "bent_tube")
LINKS = ("lifter", "top_grippers", "active_grippers", "camera_mounts", "ee_x", "ee_y", "ur_x", "ur_y")
SERVO_LINKS = ("top_grippers", "active_grippers", "camera_mounts", "ee_x", "ee_y")


def _offset(value: list[Any]) -> str | None:
    if len(value) != 3 or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return f"expected 3 numbers [x, y, z] in m, got {value!r}"
    if not all(math.isfinite(v) and abs(v) <= 0.2 for v in value):
        return "each component must be finite and within 0.2 m"
    return None


PART = {"dispenser": Field("str"), "index": Field("int", minimum=0, doc="0 = the first part taken")}
SCHEMA = {
    "name": Field("str", check=lambda v: None if v.strip() else "must not be empty"),
    "description": opt("str", ""),
    "built": opt("list", [], item=Field("str"), doc="members of bay 1 standing at the start"),
    "faults": Field(
        "dict",
        schema={
            "defective_parts": opt(
                "list",
                [],
                item=Field(
                    "dict",
                    schema={
                        **PART,
                        "defect": Field("str", choices=DEFECTS),
                        "end": opt("str", "b", choices=("a", "b"), doc="which end fitting is missing"),
                        "bend_deg": opt("float", 8.0, minimum=0.5, maximum=45.0),
                    },
                ),
            ),
            "grasp_slips": opt(
                "list",
                [],
                item=Field(
                    "dict",
                    schema={
                        "arm": Field("str", choices=ARS_NAMES),
                        "grasp": opt("int", 1, minimum=1, doc="which grasp of that arm, 1 = first"),
                        "after_s": Field("float", minimum=0.0, maximum=3600.0),
                    },
                ),
            ),
            "placement_offsets": opt(
                "list",
                [],
                item=Field(
                    "dict", schema={**PART, "offset": Field("list", check=_offset, doc="m, part frame")}
                ),
            ),
            "empty_dispensers": opt("list", [], item=Field("str")),
            "rivet_faults": opt(
                "list",
                [],
                item=Field(
                    "dict",
                    schema={
                        "member": Field("str"),
                        "joint": Field("str", doc="a joint the mission rivets the member at"),
                        "kind": Field("str", choices=FAULT_KINDS),
                        "shot": opt("int", 1, minimum=1, doc="which shot at that joint, 1 = first"),
                    },
                ),
            ),
            "random_rivet_faults": opt(
                "dict",
                None,
                schema={
                    "rate": Field("float", minimum=0.0, maximum=1.0, doc="chance a joint's first shot fails"),
                    "seed": Field("int", minimum=0),
                    "kinds": opt(
                        "list", list(FAULT_KINDS), item=Field("str", choices=FAULT_KINDS), min_items=1
                    ),
                },
            ),
            "servo_failure": opt(
                "list",
                [],
                item=Field(
                    "dict",
                    schema={
                        "link": Field("str", choices=SERVO_LINKS),
                        "servo_id": Field("int", minimum=0, maximum=252),
                        "at_s": Field("float", minimum=0.0),
                    },
                ),
            ),
            "limit_switch_stuck": opt(
                "list",
                [],
                item=Field(
                    "dict",
                    schema={
                        "switch": Field("int", minimum=0, maximum=7, doc="0-3 upper, 4-7 lower"),
                        "pressed": Field("bool"),
                        "at_s": Field("float", minimum=0.0),
                    },
                ),
            ),
            "link_drop": opt(
                "list",
                [],
                item=Field(
                    "dict",
                    schema={
                        "link": Field("str", choices=LINKS),
                        "at_s": Field("float", minimum=0.0),
                        "duration_s": opt("float", math.inf, minimum=0.0),
                    },
                ),
            ),
        },
    ),
}


@dataclass(frozen=True)
class Defect:
    kind: str  # missing_end_fitting | bent_tube
    end: str = "b"
    bend_deg: float = 8.0


@dataclass
class Scenario:
    """Validated faults. Parts are named ``<dispenser>/<index>`` (index 0 is taken first)."""

    name: str
    source: str = "<none>"
    description: str = ""
    defects: dict[str, Defect] = field(default_factory=dict)
    offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    slips: dict[tuple[str, int], float] = field(default_factory=dict)  # (arm, grasp number) -> s
    empty: frozenset[str] = frozenset()
    device_faults: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    built: tuple[str, ...] = ()  # member ids, in the mission's build order
    rivets: RivetFaultPlan = NO_FAULTS


NOMINAL = Scenario(name="nominal")


def _check_part(entry: dict[str, Any], key: str, mission: Mission, empty: set[str], source: str) -> str:
    name = entry["dispenser"]
    if name not in mission.dispensers:
        known = ", ".join(mission.dispensers)
        raise ConfigError(source, f"{key}.dispenser", f"unknown dispenser '{name}' (known: {known})")
    dispenser = mission.dispensers[name]
    if dispenser.part_kind == "rivet":
        raise ConfigError(source, f"{key}.dispenser", f"'{name}' holds rivets, not parts")
    count = 0 if name in empty else dispenser.count
    if entry["index"] >= count:
        raise ConfigError(source, f"{key}.index", f"dispenser '{name}' holds {count} part(s)")
    return f"{name}/{entry['index']}"


def _check_built(ids: list[str], mission: Mission, empty: set[str], source: str) -> tuple[str, ...]:
    known = {m.id: m for m in mission.members}
    taken: dict[str, int] = {}
    for i, member_id in enumerate(ids):
        key = f"built[{i}]"
        member = known.get(member_id)
        if member is None:
            raise ConfigError(source, key, f"'{member_id}' is not a member of mission '{mission.name}'")
        if member_id in ids[:i]:
            raise ConfigError(source, key, f"'{member_id}' is listed twice")
        if member.kind == "foundation_rivet" or member.bay != 1:
            # A later bay stands on an indexed payload, which the twin does not stage.
            raise ConfigError(source, key, f"'{member_id}': only the members of bay 1 can start built")
        frame = next(m.id for m in mission.bay_members(1) if m.kind == "cross_frame")
        if member.kind != "cross_frame" and frame not in ids:
            raise ConfigError(source, key, f"'{member_id}' needs '{frame}' built too, to be riveted to")
        for name in (member.dispenser, *(r.dispenser for r in member.rivets)):
            taken[name] = taken.get(name, 0) + 1
            if taken[name] > (0 if name in empty else mission.dispensers[name].count):
                raise ConfigError(source, key, f"dispenser '{name}' runs out building '{member_id}'")
    order = [m.id for m in mission.members]
    return tuple(sorted(ids, key=order.index))


def _check_rivets(faults: dict[str, Any], mission: Mission, source: str) -> RivetFaultPlan:
    chosen: dict[tuple[str, str, int], str] = {}
    members = {m.id: m for m in mission.members}
    for i, entry in enumerate(faults["rivet_faults"]):
        key = f"faults.rivet_faults[{i}]"
        member = members.get(entry["member"])
        if member is None:
            raise ConfigError(
                source, f"{key}.member", f"'{entry['member']}' is not a member of mission '{mission.name}'"
            )
        joints = [r.joint for r in member.rivets]
        if entry["joint"] not in joints:
            raise ConfigError(
                source,
                f"{key}.joint",
                f"'{member.id}' is riveted at {', '.join(joints) or 'no joint'}, not at '{entry['joint']}'",
            )
        slot = (member.id, entry["joint"], entry["shot"])
        if slot in chosen:
            raise ConfigError(source, key, f"shot {slot[2]} at {slot[1]} of {slot[0]} already has a fault")
        chosen[slot] = entry["kind"]
    drawn = faults["random_rivet_faults"]
    random = None
    if drawn is not None:
        kinds = drawn["kinds"]
        for i, kind in enumerate(kinds):
            if kind in kinds[:i]:
                raise ConfigError(
                    source, f"faults.random_rivet_faults.kinds[{i}]", f"'{kind}' is listed twice"
                )
        random = RandomRivetFaults(drawn["rate"], drawn["seed"], tuple(kinds))
    return RivetFaultPlan(chosen, random)


def parse_scenario(raw: Any, mission: Mission, source: str | Path = "<scenario>") -> Scenario:
    """Validate loaded YAML as a scenario for ``mission``."""
    source = str(source)
    data = validate(raw, SCHEMA, source=source)
    faults = data["faults"]
    empty: set[str] = set()
    for i, name in enumerate(faults["empty_dispensers"]):
        if name not in mission.dispensers:
            raise ConfigError(source, f"faults.empty_dispensers[{i}]", f"unknown dispenser '{name}'")
        empty.add(name)
    defects: dict[str, Defect] = {}
    for i, entry in enumerate(faults["defective_parts"]):
        key = f"faults.defective_parts[{i}]"
        part = _check_part(entry, key, mission, empty, source)
        if mission.dispensers[entry["dispenser"]].part_kind == "cross_frame":
            raise ConfigError(source, f"{key}.dispenser", "defects are modelled on struts, not cross frames")
        if part in defects:
            raise ConfigError(source, key, f"part {part} is already defective")
        defects[part] = Defect(entry["defect"], entry["end"], entry["bend_deg"])
    offsets = {}
    for i, entry in enumerate(faults["placement_offsets"]):
        part = _check_part(entry, f"faults.placement_offsets[{i}]", mission, empty, source)
        offsets[part] = tuple(float(v) for v in entry["offset"])
    slips = {}
    for i, entry in enumerate(faults["grasp_slips"]):
        slot = (entry["arm"], entry["grasp"])
        if slot in slips:
            raise ConfigError(source, f"faults.grasp_slips[{i}]", f"grasp {slot[1]} of {slot[0]} slips twice")
        slips[slot] = entry["after_s"]
    device = {k: faults[k] for k in ("servo_failure", "limit_switch_stuck", "link_drop")}
    built = _check_built(data["built"], mission, empty, source)
    rivets = _check_rivets(faults, mission, source)
    return Scenario(
        data["name"], source, data["description"], defects, offsets, slips, frozenset(empty), device, built,
        rivets,
    )  # fmt: skip


def load_scenario(path: str | Path, mission: Mission) -> Scenario:
    """Load and check a scenario file against ``mission`` (``ConfigError``: file, key, reason)."""
    return parse_scenario(load_yaml(path), mission, path)


__all__ = ["DEFECTS", "LINKS", "NOMINAL", "SCHEMA", "Defect", "Scenario", "load_scenario", "parse_scenario"]
