"""The ARS configuration file (``config/ars/ars_x.yaml``, ``ars_y.yaml``), validated on load.

Reads the YAML with :mod:`tlt_common.config_schema`; every error is a ``ConfigError`` naming the
file, the key and the reason. Poses are joint configurations (``{joints: [6 rad]}``) or tool poses
in the world frame (``{position: [x, y, z], rpy: [r, p, y]}``); :class:`PoseSpec` holds either.
Semantic checks: six arm joints, a coarse pose for every dispenser this ARS takes parts from in the
mission (checked by :func:`check_against_mission` once the mission is loaded), as many grasp
positions as grasp joints, a width for every part kind.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_validated, opt, validate
from tlt_common.ros_names import ARS_AGENTS

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_DIR = REPO_ROOT / "config" / "ars"
PART_KINDS = ("cross_frame", "vertical", "diagonal", "rivet")


def _n_floats(n: int) -> Field:
    return Field(
        "list", item=Field("float"), check=lambda v: None if len(v) == n else f"expected {n} numbers"
    )


_POSE = {
    "joints": opt("list", None, item=Field("float")),
    "position": opt("list", None, item=Field("float")),
    "rpy": opt("list", None, item=Field("float")),
}

SCHEMA = {
    "ars": Field("str", choices=ARS_AGENTS),
    "mission": Field("str", doc="mission file, relative to the repository root or absolute"),
    "scene": Field("str", doc="planning scene file"),
    # Where a held part, a loaded rivet and the request that set its member are kept across a
    # restart (tlt_ars.request_data); none: in memory only.
    "state_file": opt("str", None, doc="ARS state file, relative to the repository root or absolute"),
    # The keys the ground may write (tlt_ars.ground_writes); none: config/ars/writable_blackboard.yaml.
    "writable_blackboard": opt(
        "str", None, doc="whitelist file, relative to the repository root or absolute"
    ),
    "check_reach": opt("bool", True),
    "started_on_launch": opt("bool", True),
    # Questions to vision given up (vision restarted, or no answer in timeouts.service_s) and asked
    # again once vision says ready, per question, before the question fails.
    "vision_retries": opt("int", 2, minimum=0, maximum=10),
    "tick_rate_hz": opt("float", 20.0, minimum=1.0, maximum=200.0),
    "status_rate_hz": opt("float", 5.0, minimum=0.1, maximum=200.0),
    "arm": Field(
        "dict",
        schema={
            "joint_names": Field(
                "list", item=Field("str"), check=lambda v: None if len(v) == 6 else "six joints"
            ),
            "velocity_scale": opt("float", 0.5, minimum=0.01, maximum=1.0),
            "sample_period_s": opt("float", 0.05, minimum=0.005, maximum=1.0),
            "stopped_velocity": opt("float", 0.01, minimum=0.0),
            "settle_s": opt("float", 1.0, minimum=0.0),
            # JointTolerance convention: 0 takes the driver's default, negative means no limit.
            "path_tolerance": opt("float", 0.25),
            "goal_tolerance": opt("float", 0.01, minimum=0.0),
            "goal_time_tolerance_s": opt("float", 1.0, minimum=0.0),
            "planning_time_s": opt("float", 2.0, minimum=0.01),
            "motion_attempts": opt("int", 2, minimum=1, maximum=5),
        },
    ),
    "poses": Field(
        "dict",
        schema={
            "dispensers": Field("map", item=Field("dict", schema=_POSE)),
            "dispensers_mission": opt("str", "missions/one_bay.yaml"),
            "inspection": Field("dict", schema=_POSE),
            "inspection_cross_frame": opt("dict", None, schema=_POSE),
            "cross_frame_transit": opt("dict", None, schema=_POSE),
            "discard": Field("dict", schema=_POSE),
        },
    ),
    "end_effector": Field(
        "dict",
        schema={
            "grasp_joints": Field("list", item=Field("str"), min_items=1),
            "grasp_open": Field("list", item=Field("float")),
            "grasp_closed": Field("list", item=Field("float")),
            "grasp_time_s": opt("float", 1.0, minimum=0.01),
            "width_joint": Field("str"),
            "width": Field("map", item=Field("float", minimum=0.0)),
            "width_tolerance": opt("float", 0.002, minimum=0.0),
            "rivet_gun": opt("str", "rivet_gun_0"),
            "fire_s": opt("float", 0.5, minimum=0.0),
        },
    ),
    "cameras": Field(
        "dict",
        schema={
            "inspection": Field("str"),
            "end_effector": Field("str"),
            "world_frame": opt("str", "world"),
        },
    ),
    # Verify Joint (tlt_ars.behaviours.joint_check): after each rivet shot into a strut's joint,
    # the EE camera looks at it; ``looks`` bounds the looks at a joint vision cannot judge,
    # ``reshots`` the new rivets shot into a joint seen bad before it is reported failed.
    "verify_joints": opt(
        "dict",
        {"enabled": False, "looks": 2, "reshots": 1},
        schema={
            "enabled": opt("bool", False),
            "looks": opt("int", 2, minimum=1, maximum=5),
            "reshots": opt("int", 1, minimum=0, maximum=3),
        },
    ),
    "timeouts": Field(
        "dict",
        schema={
            "server_s": opt("float", 5.0, minimum=0.0),
            "planning_s": opt("float", 5.0, minimum=0.01),
            "trajectory_margin_s": opt("float", 10.0, minimum=0.0),
            "service_s": opt("float", 30.0, minimum=0.0),
            "vision_back_s": opt("float", 300.0, minimum=0.0),
            "present_part_s": opt("float", 300.0, minimum=0.0),
            "width_s": opt("float", 120.0, minimum=0.0),
            "sensor_s": opt("float", 2.0, minimum=0.0),
            "stop_s": opt("float", 5.0, minimum=0.0),
        },
    ),
}


@dataclass(frozen=True)
class PoseSpec:
    """A hard-coded arm pose: ``joints`` (6 rad) or a world tool pose ``position`` + ``rpy``."""

    joints: tuple[float, ...] | None = None
    position: tuple[float, float, float] | None = None
    rpy: tuple[float, float, float] | None = None

    def describe(self) -> str:
        if self.joints is not None:
            return "joints [" + ", ".join(f"{v:.3f}" for v in self.joints) + "]"
        return f"tool at {self.position} rpy {self.rpy}"


def _pose(entry: dict[str, Any], source: str, key: str) -> PoseSpec:
    joints, position, rpy = entry.get("joints"), entry.get("position"), entry.get("rpy")
    if joints is not None:
        if position is not None or rpy is not None:
            raise ConfigError(source, key, "give either joints or position + rpy, not both")
        if len(joints) != 6:
            raise ConfigError(source, f"{key}.joints", f"expected 6 joint angles, got {len(joints)}")
        return PoseSpec(joints=tuple(joints))
    if position is None or rpy is None:
        raise ConfigError(source, key, "a pose needs joints, or both position and rpy")
    if len(position) != 3 or len(rpy) != 3:
        raise ConfigError(source, key, "position and rpy take 3 numbers each")
    return PoseSpec(position=tuple(position), rpy=tuple(rpy))


@dataclass(frozen=True)
class ArsConfig:
    """The validated file; ``raw`` has the defaults filled in."""

    raw: dict[str, Any]
    source: str
    dispenser_poses: dict[str, PoseSpec]
    inspection_pose: PoseSpec
    discard_pose: PoseSpec
    cross_frame_inspection_pose: PoseSpec | None = None
    cross_frame_transit_pose: PoseSpec | None = None

    def inspection_pose_for(self, part_kind: str) -> PoseSpec:
        """A cross frame sticks out to one side of the tool, so it may need its own inspection pose."""
        if part_kind == "cross_frame" and self.cross_frame_inspection_pose is not None:
            return self.cross_frame_inspection_pose
        return self.inspection_pose

    @property
    def ars(self) -> str:
        return self.raw["ars"]

    @property
    def mission_path(self) -> Path:
        return _resolve(self.raw["mission"])

    @property
    def dispensers_mission_path(self) -> Path:
        """The mission whose dispenser tags the configured coarse poses view."""
        return _resolve(self.raw["poses"]["dispensers_mission"])

    def with_dispenser_joints(self, joints: dict[str, Any]) -> ArsConfig:
        """The same configuration with these dispensers' coarse poses replaced by joint poses."""
        moved = {name: PoseSpec(joints=tuple(float(v) for v in q)) for name, q in joints.items()}
        return dataclasses.replace(self, dispenser_poses={**self.dispenser_poses, **moved})

    @property
    def scene_path(self) -> Path:
        return _resolve(self.raw["scene"])

    @property
    def state_path(self) -> Path | None:
        return None if self.raw.get("state_file") is None else _resolve(self.raw["state_file"])

    @property
    def writable_blackboard_path(self) -> Path | None:
        """The ground-writable keys' whitelist the file names; None: the project's."""
        path = self.raw.get("writable_blackboard")
        return None if path is None else _resolve(path)

    @property
    def arm(self) -> dict[str, Any]:
        return self.raw["arm"]

    @property
    def ee(self) -> dict[str, Any]:
        return self.raw["end_effector"]

    @property
    def cameras(self) -> dict[str, Any]:
        return self.raw["cameras"]

    @property
    def verify_joints(self) -> dict[str, Any]:
        return self.raw["verify_joints"]

    @property
    def timeouts(self) -> dict[str, float]:
        return self.raw["timeouts"]


def _resolve(path: str) -> Path:
    p = Path(path)
    return p if p.is_absolute() else REPO_ROOT / p


def _semantics(raw: dict[str, Any], source: str) -> ArsConfig:
    ee = raw["end_effector"]
    n = len(ee["grasp_joints"])
    for key in ("grasp_open", "grasp_closed"):
        if len(ee[key]) != n:
            raise ConfigError(source, f"end_effector.{key}", f"expected {n} positions (one per grasp joint)")
    missing = [k for k in PART_KINDS if k not in ee["width"]]
    if missing:
        raise ConfigError(source, "end_effector.width", f"no width for part kind(s) {', '.join(missing)}")
    unknown = sorted(set(ee["width"]) - set(PART_KINDS))
    if unknown:
        raise ConfigError(source, "end_effector.width", f"unknown part kind(s) {', '.join(unknown)}")
    poses = raw["poses"]
    dispensers = {
        name: _pose(entry, source, f"poses.dispensers.{name}") for name, entry in poses["dispensers"].items()
    }
    return ArsConfig(
        raw,
        source,
        dispensers,
        _pose(poses["inspection"], source, "poses.inspection"),
        _pose(poses["discard"], source, "poses.discard"),
        *(
            None if poses.get(key) is None else _pose(poses[key], source, f"poses.{key}")
            for key in ("inspection_cross_frame", "cross_frame_transit")
        ),
    )


def load_ars_config(path: str | Path) -> ArsConfig:
    """Load and validate an ARS file; :class:`ConfigError` names file, key and reason."""
    return _semantics(load_validated(path, SCHEMA), str(path))


def ars_config_from_dict(data: dict[str, Any], source: str = "<ars config>") -> ArsConfig:
    """Validate an in-memory configuration (tests vary timeouts and speeds)."""
    return _semantics(validate(data, SCHEMA, source=source), source)


def default_config_path(ars: str) -> Path:
    return CONFIG_DIR / f"{ars}.yaml"


def dispensers_used(mission: Any, ars: str) -> list[str]:
    """Dispensers ``ars`` takes parts or rivets from in ``mission``, in first-use order."""
    out: list[str] = []
    for member in mission.members:
        if member.add_ars == ars:
            out.append(member.dispenser)
        out.extend(r.dispenser for r in member.rivets if r.ars == ars)
    return list(dict.fromkeys(out))


def check_against_mission(config: ArsConfig, mission: Any) -> None:
    """Every dispenser the mission has this ARS use needs a coarse pose; ConfigError otherwise."""
    missing = [d for d in dispensers_used(mission, config.ars) if d not in config.dispenser_poses]
    if missing:
        raise ConfigError(
            config.source,
            "poses.dispensers",
            f"mission '{mission.name}' has {config.ars} take parts from {', '.join(missing)}"
            " but no coarse pose is configured for it",
        )


__all__ = [
    "CONFIG_DIR",
    "PART_KINDS",
    "ArsConfig",
    "PoseSpec",
    "ars_config_from_dict",
    "check_against_mission",
    "default_config_path",
    "dispensers_used",
    "load_ars_config",
]
