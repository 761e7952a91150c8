"""The CRS node's configuration (``config/crs/crs.yaml``), validated on load.

Relative paths in the file (mission, writable blackboard registry, state files) are taken
relative to the directory holding the configuration file, so the file works from any working
directory; ``~`` is expanded. Every section has defaults (see :class:`CrsConfig`), so a test can
build a configuration in code and a file need only say what differs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_validated, opt

REPO_CONFIG = Path(__file__).resolve().parents[2] / "config" / "crs" / "crs.yaml"


@dataclass(frozen=True)
class Timeouts:
    """Bounds on every wait of the CRS (seconds of mission time: they stand still while paused)."""

    ars_server_s: float = 5.0  # an ARS action server must be discoverable (and stay so) this long
    service_s: float = 5.0  # a service (vision, lifter mode, ARS ground command) must appear
    vision_s: float = 30.0  # a vision inspection must answer
    actuator_s: float = 30.0  # a lifter/gripper/camera motion and its sensor confirmation
    part_presented_s: float = 600.0  # the ARS must present the part for inspection
    inspect_handoff_s: float = 60.0  # /crs/inspect_part holds the ARS's call at most this long
    forward_s: float = 2.0  # each ARS must answer a forwarded ground command
    sensor_max_age_s: float = 1.0  # older sensor messages count as no message
    lifter_link_s: float = 1.0  # the lifter unreachable this long (ROS time) holds the build
    vision_back_s: float = 300.0  # a restarted vision must say ready this long after a lost inspection


@dataclass(frozen=True)
class LifterSetup:
    joints: tuple[str, ...] = ("lifter_joint_0", "lifter_joint_1", "lifter_joint_2", "lifter_joint_3")
    # Lead-screw position of Raise Payload; None: lowered_m + the mission's bay height.
    raised_m: float | None = None
    lowered_m: float = 0.1  # lead-screw position of Lower Lifter: the Active Grippers at the build level
    # True when the machine starts with the payload already one bay up on the Top Grippers (the
    # twin's start): bay 1 is then built without indexing first.
    indexed_at_start: bool = False
    tolerance_m: float = 0.003  # encoder positions within this of the target count as there
    compression_stiffness_n_per_m: float = 50000.0  # compression_force / this = travel of Test Bay


@dataclass(frozen=True)
class GripperSetup:
    joints: tuple[str, ...]
    engage: float  # position commanded to engage (m for Top, rad for Active)
    disengage: float
    move_time_s: float = 1.0


@dataclass(frozen=True)
class CameraSetup:
    joints: tuple[str, ...] = ("camera_mount_1", "camera_mount_2")
    inward: tuple[float, ...] = (1.15, 1.15)  # rad: ZEDs look into the bay (Fig. 26)
    outward: tuple[float, ...] = (0.0, 0.0)  # rad: ZEDs look at parts held by an ARS (Fig. 22)
    move_time_s: float = 1.5
    part_camera: str = "zed_left"


def _top_default() -> GripperSetup:
    return GripperSetup(tuple(f"top_gripper_{i}" for i in range(1, 5)), 0.027, 0.0)


def _active_default() -> GripperSetup:
    return GripperSetup(tuple(f"active_gripper_{i}" for i in range(1, 5)), 1.5, 0.0, 1.5)


DEFAULT_WRITABLE_BLACKBOARD = REPO_CONFIG.parent / "writable_blackboard.yaml"
# The ARSs' whitelist: the CRS checks a ground write to an ARS key on arrival, before forwarding it.
DEFAULT_ARS_WRITABLE_BLACKBOARD = REPO_CONFIG.parents[1] / "ars" / "writable_blackboard.yaml"


@dataclass(frozen=True)
class CrsConfig:
    mission: Path
    state_file: Path  # tower model (tlt_common.mission.tower_model)
    progress_file: Path  # which bays the payload was indexed for (tlt_crs.index_record)
    writable_blackboard: Path = DEFAULT_WRITABLE_BLACKBOARD
    ars_writable_blackboard: Path = DEFAULT_ARS_WRITABLE_BLACKBOARD
    tick_rate_hz: float = 10.0
    progress_rate_hz: float = 2.0
    status_rate_hz: float = 5.0
    vision_retries: int = 2  # inspections lost with a restarted vision, asked again per inspection
    timeouts: Timeouts = field(default_factory=Timeouts)
    lifter: LifterSetup = field(default_factory=LifterSetup)
    top_grippers: GripperSetup = field(default_factory=_top_default)
    active_grippers: GripperSetup = field(default_factory=_active_default)
    camera_mounts: CameraSetup = field(default_factory=CameraSetup)


def _positive(minimum: float = 1e-6) -> Field:
    return opt("float", None, minimum=minimum)


_TIMEOUTS = {name: _positive(1e-3) for name in Timeouts.__dataclass_fields__}
_LIFTER = {
    "joints": opt("list", None, item=Field("str"), min_items=1),
    "raised_m": opt("float", None),
    "lowered_m": opt("float", None),
    "indexed_at_start": opt("bool", None),
    "tolerance_m": _positive(),
    "compression_stiffness_n_per_m": _positive(),
}
_GRIPPER = {
    "joints": opt("list", None, item=Field("str"), min_items=1),
    "engage": opt("float", None),
    "disengage": opt("float", None),
    "move_time_s": _positive(),
}
_CAMERA = {
    "joints": opt("list", None, item=Field("str"), min_items=1),
    "inward": opt("list", None, item=Field("float")),
    "outward": opt("list", None, item=Field("float")),
    "move_time_s": _positive(),
    "part_camera": opt("str", None),
}
SCHEMA = {
    "mission": Field("str", doc="mission file (relative to this file's directory)"),
    "state_file": Field("str", doc="tower model state file, persisted on every change"),
    "progress_file": opt("str", None, doc="payload indexing record; default: next to state_file"),
    "writable_blackboard": opt("str", None),
    "ars_writable_blackboard": opt(
        "str", None, doc="the ARSs' whitelist (config/ars/writable_blackboard.yaml)"
    ),
    "tick_rate_hz": opt("float", 10.0, minimum=0.1, maximum=1000.0),
    "progress_rate_hz": opt("float", 2.0, minimum=0.01, maximum=100.0),
    "status_rate_hz": opt("float", 5.0, minimum=0.01, maximum=1000.0),
    "vision_retries": opt("int", 2, minimum=0, maximum=10),
    "timeouts": opt("dict", None, schema=_TIMEOUTS),
    "lifter": opt("dict", None, schema=_LIFTER),
    "top_grippers": opt("dict", None, schema=_GRIPPER),
    "active_grippers": opt("dict", None, schema=_GRIPPER),
    "camera_mounts": opt("dict", None, schema=_CAMERA),
}


def _merge(default: Any, section: dict[str, Any] | None) -> Any:
    if not section:
        return default
    values = {k: (tuple(v) if isinstance(v, list) else v) for k, v in section.items() if v is not None}
    return type(default)(**{**default.__dict__, **values})


def _path(base: Path, text: str) -> Path:
    path = Path(text).expanduser()
    return path if path.is_absolute() else (base / path).resolve()


_PATH_KEYS = ("mission", "state_file", "progress_file", "writable_blackboard", "ars_writable_blackboard")


def load_config(path: str | Path, **overrides: Any) -> CrsConfig:
    """Load and validate ``path``; ``overrides`` (mission, state_file, ...) replace file values
    (paths among them relative to the working directory).

    Raises ``ConfigError`` naming the file, the key and the reason.
    """
    path = Path(path)
    data = load_validated(path, SCHEMA)
    for key, value in overrides.items():
        if value is not None:
            # Overrides come from a command line: relative to the working directory.
            data[key] = str(Path(value).expanduser().resolve()) if key in _PATH_KEYS else value
    base = path.resolve().parent
    state = _path(base, data["state_file"])
    config = CrsConfig(
        mission=_path(base, data["mission"]),
        state_file=state,
        progress_file=_path(base, data["progress_file"])
        if data["progress_file"]
        else state.with_name(state.stem + ".indexed.json"),
        writable_blackboard=_path(base, data["writable_blackboard"])
        if data["writable_blackboard"]
        else DEFAULT_WRITABLE_BLACKBOARD,
        ars_writable_blackboard=_path(base, data["ars_writable_blackboard"])
        if data["ars_writable_blackboard"]
        else DEFAULT_ARS_WRITABLE_BLACKBOARD,
        tick_rate_hz=data["tick_rate_hz"],
        progress_rate_hz=data["progress_rate_hz"],
        status_rate_hz=data["status_rate_hz"],
        vision_retries=data["vision_retries"],
        timeouts=_merge(Timeouts(), data["timeouts"]),
        lifter=_merge(LifterSetup(), data["lifter"]),
        top_grippers=_merge(_top_default(), data["top_grippers"]),
        active_grippers=_merge(_active_default(), data["active_grippers"]),
        camera_mounts=_merge(CameraSetup(), data["camera_mounts"]),
    )
    cam = config.camera_mounts
    if not len(cam.inward) == len(cam.outward) == len(cam.joints):
        raise ConfigError(path, "camera_mounts", "inward, outward and joints must have the same length")
    if config.lifter.raised_m is not None and config.lifter.raised_m <= config.lifter.lowered_m:
        raise ConfigError(path, "lifter.raised_m", "must be above lifter.lowered_m")
    return config


__all__ = ["CameraSetup", "CrsConfig", "GripperSetup", "LifterSetup", "Timeouts", "load_config"]
