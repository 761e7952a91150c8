"""Mission files (``missions/*.yaml``): the tower to build, checked before anything acts on it.

A mission lists every member explicitly, in build order (paper §V.C.2): per bay the cross frame,
the far verticals (x0_y1, x1_y0: one ARS adds, the other affixes), the near verticals (x0_y0,
x1_y1: the same ARS adds and affixes), the diagonals; then the foundation rivets. Each member
names its joints (ids of the ``joints`` table, 3D points in the tower frame, m), the dispenser it
takes its part from, and the rivets that fix it (joint, ARS, rivet dispenser, and whether the
rivet is set by the Add or the Affix request). The format is described in docs/missions.md.

:func:`load_mission` checks the file against :data:`SCHEMA` (types, ranges, unknown keys) and then
the semantics: unique ids, references to joints and dispensers that exist, bay numbering and
count, the ARS of each member, adders and affixers of far and near verticals, strut lengths
against the joint distances, and enough parts in every dispenser. Every error is a
``ConfigError`` naming the file, the dotted key and the reason.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate

FORMAT = 1
ARS_NAMES = ("ars_x", "ars_y")
PART_KINDS = ("cross_frame", "vertical", "diagonal", "rivet")
KINDS = {"cross_frame": 0, "vertical": 1, "diagonal": 2, "foundation_rivet": 3}  # MemberState.KIND_*
FAR_POSITIONS = ("x0_y1", "x1_y0")
NEAR_POSITIONS = ("x0_y0", "x1_y1")


def _vector3(value: list[Any]) -> str | None:
    if len(value) != 3 or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return f"expected 3 numbers [x, y, z], got {value!r}"
    if not all(math.isfinite(v) for v in value):
        return "coordinates must be finite"
    return None


VECTOR3 = Field("list", check=_vector3, doc="[x, y, z] in m")
POSE = {
    "frame": Field("str", doc="frame the pose is given in, e.g. 'base'"),
    "position": VECTOR3,
    "rpy": Field("list", check=_vector3, doc="[roll, pitch, yaw] in rad"),
}
RIVET = {
    "joint": Field("str", doc="joint id the rivet goes in"),
    "ars": Field("str", choices=ARS_NAMES),
    "dispenser": Field("str", doc="rivet dispenser the ARS loads the rivet from"),
    "step": Field("str", choices=("add", "affix"), doc="request that sets this rivet"),
}
MEMBER = {
    "id": Field("str", doc="unique member id, e.g. bay1/vertical/x0_y1"),
    "position": Field("str", doc="where in the bay, e.g. x0_y1 or face_x0"),
    "add_ars": Field("str", choices=ARS_NAMES, doc="ARS that adds (places) the member"),
    "affix_ars": opt("str", choices=ARS_NAMES, doc="ARS that sets the second rivet (verticals)"),
    "dispenser": Field("str", doc="dispenser the part comes from"),
    "joints": Field("list", item=Field("str"), min_items=2, doc="joint ids the member connects"),
    "rivets": opt("list", [], item=Field("dict", schema=RIVET)),
}
BAY = {
    "number": Field("int", minimum=1),
    "cross_frame": Field("dict", schema=MEMBER),
    "far_verticals": Field("list", item=Field("dict", schema=MEMBER)),
    "near_verticals": Field("list", item=Field("dict", schema=MEMBER)),
    "diagonals": Field("list", item=Field("dict", schema=MEMBER)),
}
FOUNDATION_RIVET = {
    "id": Field("str"),
    "position": Field("str"),
    "ars": Field("str", choices=ARS_NAMES),
    "joint": Field("str"),
    "dispenser": Field("str"),
}
SCHEMA = {
    "format": Field("int", choices=(FORMAT,)),
    "name": Field("str", check=lambda v: None if v.strip() else "must not be empty"),
    "description": opt("str", ""),
    "bay_count": Field("int", minimum=1, maximum=100),
    "geometry": Field(
        "dict",
        schema={
            "bay_width": Field("float", minimum=0.01, doc="m, side of the square cross frame"),
            "bay_height": Field("float", minimum=0.01, doc="m, distance between cross frames"),
            "strut_lengths": Field(
                "dict",
                schema={
                    "cross_frame_side": Field("float", minimum=0.01),
                    "vertical": Field("float", minimum=0.01),
                    "diagonal": Field("float", minimum=0.01),
                },
            ),
            "length_tolerance": opt("float", 0.002, minimum=0.0, doc="m, strut length vs joint distance"),
        },
    ),
    "joints": Field("map", item=VECTOR3, doc="joint id -> [x, y, z] in the tower frame, m"),
    "dispensers": Field(
        "list",
        min_items=1,
        item=Field(
            "dict",
            schema={
                "name": Field("str"),
                "part_kind": Field("str", choices=PART_KINDS),
                "count": Field("int", minimum=0, doc="parts loaded at the start of the mission"),
                "pose": Field("dict", schema=POSE),
            },
        ),
    ),
    "inspection": Field(
        "dict",
        schema={
            "position_tolerance": Field("float", minimum=0.0, doc="m"),
            "angle_tolerance": Field("float", minimum=0.0, doc="rad"),
            "chamfer_thresholds": Field("map", item=Field("float", minimum=0.0), doc="object class -> m"),
        },
    ),
    "bays": Field("list", min_items=1, item=Field("dict", schema=BAY)),
    "foundation_rivets": Field("list", item=Field("dict", schema=FOUNDATION_RIVET)),
}


@dataclass(frozen=True)
class Rivet:
    joint: str
    ars: str
    dispenser: str
    step: str  # "add" or "affix"


@dataclass(frozen=True)
class Member:
    """One member of the tower (or one foundation rivet), as the mission file lists it."""

    id: str
    kind: str  # cross_frame, vertical, diagonal, foundation_rivet
    group: str  # cross_frame, far_vertical, near_vertical, diagonal, foundation_rivet
    bay: int  # 1-based; foundation rivets carry the last bay
    position: str
    add_ars: str
    affix_ars: str | None
    dispenser: str
    joints: tuple[tuple[str, tuple[float, float, float]], ...]
    rivets: tuple[Rivet, ...]

    @property
    def kind_code(self) -> int:
        return KINDS[self.kind]


@dataclass(frozen=True)
class Dispenser:
    name: str
    part_kind: str
    count: int
    frame: str
    position: tuple[float, float, float]
    rpy: tuple[float, float, float]


@dataclass(frozen=True)
class Mission:
    name: str
    source: str
    bay_count: int
    bay_width: float
    bay_height: float
    strut_lengths: dict[str, float]
    joints: dict[str, tuple[float, float, float]]
    members: tuple[Member, ...]  # build order
    dispensers: dict[str, Dispenser]
    inspection: dict[str, Any]
    hash: str  # SHA-256 of the validated content, hex

    def member(self, member_id: str) -> Member:
        for m in self.members:
            if m.id == member_id:
                return m
        raise KeyError(member_id)

    def bay_members(self, bay: int) -> list[Member]:
        return [m for m in self.members if m.bay == bay and m.kind != "foundation_rivet"]


def content_hash(data: dict[str, Any]) -> str:
    """SHA-256 of the canonical JSON of validated mission data (stable across runs and machines)."""
    return hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _semantics(data: dict[str, Any], source: str) -> Mission:
    joints = {k: (float(v[0]), float(v[1]), float(v[2])) for k, v in data["joints"].items()}
    geometry = data["geometry"]
    tolerance = geometry["length_tolerance"]
    lengths = geometry["strut_lengths"]

    dispensers: dict[str, Dispenser] = {}
    for i, d in enumerate(data["dispensers"]):
        if d["name"] in dispensers:
            raise ConfigError(source, f"dispensers[{i}].name", f"dispenser '{d['name']}' listed twice")
        pose = d["pose"]
        dispensers[d["name"]] = Dispenser(
            d["name"], d["part_kind"], d["count"], pose["frame"], tuple(pose["position"]), tuple(pose["rpy"])
        )
    demand = dict.fromkeys(dispensers, 0)
    demand_key: dict[str, str] = {}

    def dispenser_of(name: str, kind: str, key: str) -> None:
        if name not in dispensers:
            raise ConfigError(source, key, f"unknown dispenser '{name}' (known: {', '.join(dispensers)})")
        if dispensers[name].part_kind != kind:
            raise ConfigError(
                source, key, f"dispenser '{name}' holds {dispensers[name].part_kind} parts, not {kind}"
            )
        demand[name] += 1
        demand_key.setdefault(name, key)

    def joint_of(joint: str, key: str) -> tuple[float, float, float]:
        if joint not in joints:
            raise ConfigError(source, key, f"unknown joint '{joint}'")
        return joints[joint]

    if data["bay_count"] != len(data["bays"]):
        raise ConfigError(
            source, "bay_count", f"bay_count is {data['bay_count']} but {len(data['bays'])} bay(s) are listed"
        )

    members: list[Member] = []
    seen: dict[str, str] = {}

    def member(entry: dict[str, Any], key: str, kind: str, group: str, bay: int) -> Member:
        if entry["id"] in seen:
            raise ConfigError(
                source, f"{key}.id", f"member id '{entry['id']}' already used at {seen[entry['id']]}"
            )
        seen[entry["id"]] = key
        dispenser_of(entry["dispenser"], kind, f"{key}.dispenser")
        points = tuple((j, joint_of(j, f"{key}.joints[{n}]")) for n, j in enumerate(entry["joints"]))
        if kind == "cross_frame":
            if len(points) != 4:
                raise ConfigError(
                    source, f"{key}.joints", f"a cross frame has 4 corner joints, got {len(points)}"
                )
            expected, pairs = (
                lengths["cross_frame_side"],
                [(points[i][1], points[(i + 1) % 4][1]) for i in range(4)],
            )
        else:
            if len(points) != 2:
                raise ConfigError(source, f"{key}.joints", f"a {kind} connects 2 joints, got {len(points)}")
            expected, pairs = lengths[kind], [(points[0][1], points[1][1])]
        for a, b in pairs:
            if abs(math.dist(a, b) - expected) > tolerance:
                raise ConfigError(
                    source,
                    f"{key}.joints",
                    f"joints are {math.dist(a, b):.4f} m apart; a {kind} strut is {expected:.4f} m"
                    f" (tolerance {tolerance:g} m)",
                )
        if group == "far_vertical" and (entry["affix_ars"] is None or entry["affix_ars"] == entry["add_ars"]):
            raise ConfigError(
                source,
                f"{key}.affix_ars",
                "a far vertical is affixed by the other ARS than the one that adds it",
            )
        if group == "near_vertical" and entry["affix_ars"] != entry["add_ars"]:
            raise ConfigError(
                source, f"{key}.affix_ars", "a near vertical is affixed by the ARS that adds it"
            )
        rivets = []
        for n, r in enumerate(entry["rivets"]):
            rkey = f"{key}.rivets[{n}]"
            if r["joint"] not in entry["joints"]:
                raise ConfigError(
                    source, f"{rkey}.joint", f"joint '{r['joint']}' is not one of the member's joints"
                )
            want = entry["add_ars"] if r["step"] == "add" else entry["affix_ars"]
            if r["ars"] != want:
                raise ConfigError(
                    source, f"{rkey}.ars", f"the {r['step']} rivet is set by {want}, not {r['ars']}"
                )
            dispenser_of(r["dispenser"], "rivet", f"{rkey}.dispenser")
            rivets.append(Rivet(r["joint"], r["ars"], r["dispenser"], r["step"]))
        return Member(
            entry["id"], kind, group, bay, entry["position"], entry["add_ars"], entry["affix_ars"],
            entry["dispenser"], points, tuple(rivets),
        )  # fmt: skip

    for i, bay in enumerate(data["bays"]):
        key = f"bays[{i}]"
        if bay["number"] != i + 1:
            raise ConfigError(
                source,
                f"{key}.number",
                f"bays must be numbered 1..{len(data['bays'])} in order; expected {i + 1}",
            )
        number = bay["number"]
        members.append(member(bay["cross_frame"], f"{key}.cross_frame", "cross_frame", "cross_frame", number))
        for group, field, positions in (
            ("far_vertical", "far_verticals", FAR_POSITIONS),
            ("near_vertical", "near_verticals", NEAR_POSITIONS),
        ):
            got = sorted(m["position"] for m in bay[field])
            if got != sorted(positions):
                raise ConfigError(
                    source,
                    f"{key}.{field}",
                    f"expected positions {', '.join(positions)}, got {', '.join(got) or 'none'}",
                )
            for n, entry in enumerate(bay[field]):
                members.append(member(entry, f"{key}.{field}[{n}]", "vertical", group, number))
        for n, entry in enumerate(bay["diagonals"]):
            members.append(member(entry, f"{key}.diagonals[{n}]", "diagonal", "diagonal", number))
    for n, r in enumerate(data["foundation_rivets"]):
        key = f"foundation_rivets[{n}]"
        if r["id"] in seen:
            raise ConfigError(source, f"{key}.id", f"member id '{r['id']}' already used at {seen[r['id']]}")
        seen[r["id"]] = key
        point = joint_of(r["joint"], f"{key}.joint")
        dispenser_of(r["dispenser"], "rivet", f"{key}.dispenser")
        rivet = Rivet(r["joint"], r["ars"], r["dispenser"], "add")
        members.append(
            Member(
                r["id"], "foundation_rivet", "foundation_rivet", data["bay_count"], r["position"],
                r["ars"], None, r["dispenser"], ((r["joint"], point),), (rivet,),
            )
        )  # fmt: skip

    for i, d in enumerate(data["dispensers"]):
        if demand[d["name"]] > d["count"]:
            raise ConfigError(
                source, f"dispensers[{i}].count",
                f"dispenser '{d['name']}' holds {d['count']} part(s)"
                f" but the mission needs {demand[d['name']]}",
            )  # fmt: skip

    return Mission(
        name=data["name"],
        source=source,
        bay_count=data["bay_count"],
        bay_width=geometry["bay_width"],
        bay_height=geometry["bay_height"],
        strut_lengths=dict(lengths),
        joints=joints,
        members=tuple(members),
        dispensers=dispensers,
        inspection=data["inspection"],
        hash=content_hash(data),
    )


def parse_mission(raw: Any, source: str | Path = "<mission>") -> Mission:
    """Validate already-loaded YAML data as a mission."""
    source = str(source)
    data = validate(raw, SCHEMA, source=source)
    return _semantics(data, source)


def load_mission(path: str | Path) -> Mission:
    """Load, validate and check a mission file; raises ``ConfigError`` (file, key, reason)."""
    return parse_mission(load_yaml(path), path)


__all__ = [
    "SCHEMA",
    "Dispenser",
    "Member",
    "Mission",
    "Rivet",
    "content_hash",
    "load_mission",
    "parse_mission",
]
