"""The EDU machine description (``config/twin/edu.yaml``), validated against the mission it builds.

:func:`load_edu` reads the file, checks every key (type, range, unknown keys) with
``tlt_common.config_schema`` and then checks the machine against the mission geometry: the lifter
travel covers a whole bay, the end effector can widen to a diagonal, the posts reach above the
top grippers; and the rivets' tolerances and failure shapes against the gun and the parts (a
tolerance inside the gun's reach, a wrong hole on the fitting, a bad joint softer than a good one).
Any problem raises ``ConfigError`` naming the file, the dotted key and the reason.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate
from tlt_common.mission.schema import Mission, load_mission

REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_EDU = REPO_ROOT / "config" / "twin" / "edu.yaml"


def _numbers(n: int, positive: bool = False):
    def check(value: list[Any]) -> str | None:
        if len(value) != n or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
            return f"expected {n} numbers, got {value!r}"
        if not all(math.isfinite(v) for v in value):
            return "values must be finite"
        if positive and not all(v > 0 for v in value):
            return f"values must be positive, got {value!r}"
        return None

    return check


def _range(value: list[Any]) -> str | None:
    problem = _numbers(2)(value)
    if problem:
        return problem
    return None if value[0] < value[1] else f"expected [low, high] with low < high, got {value!r}"


def _pos(doc: str = "", maximum: float | None = None) -> Field:
    return Field("float", minimum=1e-9, maximum=maximum, doc=doc)


SOLREF = Field("list", check=_numbers(2, positive=True), doc="[time constant s, damping ratio]")
VEC3 = Field("list", check=_numbers(3), doc="[x, y, z]")
ARM = {
    "base": VEC3,
    "yaw_deg": Field("float", minimum=-360.0, maximum=360.0),
    "pedestal_height": Field("float", minimum=0.0, maximum=3.0),
    "home": Field("list", check=_numbers(6), doc="six joint angles, rad"),
}
SCHEMA = {
    "format": Field("int", choices=(1,)),
    "mission": opt("str", "missions/one_bay.yaml"),
    "physics": Field(
        "dict",
        schema={
            "timestep": Field("float", minimum=1e-4, maximum=0.02),
            "rivet_solref": SOLREF,
            "grasp_solref": SOLREF,
            "hold_solref": SOLREF,
        },
    ),
    "site": Field(
        "dict",
        schema={"build_level": _pos(), "foundation_top": Field("float", minimum=0.0), "base_origin": VEC3},
    ),
    "lifter": Field(
        "dict",
        schema={
            "post_offset": _pos(),
            "post_radius": _pos(),
            "post_height": _pos(),
            "travel": Field("list", check=_range),
            "build_position": Field("float"),
            "max_velocity": _pos(),
            "kp": _pos(),
            "carriage_mass": _pos(),
        },
    ),
    "active_grippers": Field(
        "dict",
        schema={
            "range": Field("list", check=_range),
            "engaged_above": Field("float"),
            "finger_length": _pos(),
            "max_velocity": _pos(),
            "reach": _pos(),
        },
    ),
    "top_grippers": Field(
        "dict",
        schema={"stroke": _pos(), "engaged_above": _pos(), "max_velocity": _pos(), "reach": _pos()},
    ),
    "camera_mounts": Field(
        "dict",
        schema={
            "height": Field("float"),
            "pitch_deg": Field("float", minimum=-90.0, maximum=90.0),
            "range": Field("list", check=_range),
            "inward_angle": Field("float", minimum=-math.pi, maximum=math.pi),
            "max_velocity": _pos(),
        },
    ),
    "payload": Field(
        "dict", schema={"mass": _pos(), "size": Field("list", check=_numbers(3, positive=True))}
    ),
    "arms": Field(
        "dict",
        schema={
            "kp": _pos(),
            "kv": Field("float", minimum=0.0),
            "armature": Field("float", minimum=0.0),
            "ars_x": Field("dict", schema=ARM),
            "ars_y": Field("dict", schema=ARM),
        },
    ),
    "end_effector": Field(
        "dict",
        schema={
            "bar_length": _pos(),
            "grip_spacing": _pos(),
            "width_travel": _pos(),
            "width_max_velocity": _pos(),
            "jaw_range": Field("list", check=_range, doc="[open, closed] rad"),
            "jaw_contact": Field("float", doc="rad, where the jaws meet a tube"),
            "jaw_max_velocity": _pos(),
            "grasp_depth": _pos(),
            "rivet_gun_offset": Field("float", minimum=0.0),
            "grasp_reach": _pos(),
            "rivet_reach": _pos(),
            "limit_switch_below": _pos(),
        },
    ),
    "cameras": Field(
        "dict",
        schema={
            "zed_fovy_deg": _pos(maximum=179.0),
            "d405_fovy_deg": _pos(maximum=179.0),
            "d405_tilt_deg": Field("float", minimum=-80.0, maximum=80.0),
        },
    ),
    "parts": Field(
        "dict",
        schema={
            "tube_radius": _pos(),
            "fitting_radius": _pos(),
            "fitting_length": _pos(),
            "corner_size": _pos(),
            "strut_mass": _pos(),
            "cross_frame_mass": _pos(),
            "rivet_radius": _pos(),
        },
    ),
    "rivets": Field(
        "dict",
        schema={
            "max_offset": _pos(doc="m, gun muzzle to the hole"),
            "max_angle_deg": _pos(maximum=90.0),
            "proud_height": _pos(),
            "partial_grip_height": _pos(),
            "wrong_hole_offset": _pos(),
            "unseated_solref": SOLREF,
            "loose_solref": SOLREF,
        },
    ),
    "dispensers": Field(
        "dict",
        schema={
            "slot_pitch": _pos(),
            "first_slot_height": _pos(),
            "tag_size": _pos(),
            "rivet_pickup_height": Field("float", minimum=0.0),
        },
    ),
    "render": Field(
        "dict",
        schema={
            "width": Field("int", minimum=16, maximum=4096),
            "height": Field("int", minimum=16, maximum=4096),
            "lookat": VEC3,
            "distance": _pos(),
            "azimuth": Field("float"),
            "elevation": Field("float", minimum=-90.0, maximum=90.0),
        },
    ),
}


def check_against_mission(edu: dict[str, Any], mission: Mission, source: str) -> None:
    """Refuse a machine that cannot build ``mission`` (``ConfigError`` naming ``source`` and the key)."""
    lifter, ee, parts = edu["lifter"], edu["end_effector"], edu["parts"]
    low, high = lifter["travel"]
    if not low <= lifter["build_position"] <= high:
        raise ConfigError(source, "lifter.build_position", f"must lie within lifter.travel [{low}, {high}]")
    if lifter["build_position"] + mission.bay_height > high:
        raise ConfigError(
            source,
            "lifter.travel",
            f"the Active Grippers must rise one bay ({mission.bay_height} m) from build_position"
            f" {lifter['build_position']} m, but travel ends at {high} m",
        )
    top = edu["site"]["build_level"] + mission.bay_height
    if lifter["post_height"] < top + 0.1:
        raise ConfigError(
            source, "lifter.post_height", f"posts must reach above the top grippers at {top:.3f} m"
        )
    seat = edu["site"]["build_level"] - edu["parts"]["corner_size"] / 2
    if edu["site"]["foundation_top"] > seat + 1e-9:
        raise ConfigError(
            source,
            "site.foundation_top",
            f"the pads would hold a cross frame above build_level (top at most {seat:.4f} m:"
            " build_level - parts.corner_size / 2)",
        )
    ag = edu["active_grippers"]
    if not ag["range"][0] < ag["engaged_above"] <= ag["range"][1]:
        raise ConfigError(source, "active_grippers.engaged_above", "must lie inside active_grippers.range")
    cm = edu["camera_mounts"]
    if not cm["range"][0] <= cm["inward_angle"] <= cm["range"][1]:
        raise ConfigError(source, "camera_mounts.inward_angle", "must lie inside camera_mounts.range")
    if edu["top_grippers"]["engaged_above"] > edu["top_grippers"]["stroke"]:
        raise ConfigError(source, "top_grippers.engaged_above", "must not exceed top_grippers.stroke")
    if not ee["jaw_range"][0] + 0.2 <= ee["jaw_contact"] <= ee["jaw_range"][1] - 0.1:
        raise ConfigError(
            source,
            "end_effector.jaw_contact",
            "jaws must meet a tube at least 0.2 rad from open and 0.1 rad before they close fully",
        )
    if ee["grip_spacing"] >= ee["bar_length"]:
        raise ConfigError(source, "end_effector.grip_spacing", "grippers must sit on the bar")
    vertical = mission.strut_lengths["vertical"]
    diagonal = mission.strut_lengths["diagonal"]
    needed = diagonal - vertical
    if needed > ee["width_travel"]:
        raise ConfigError(
            source,
            "end_effector.width_travel",
            f"diagonals ({diagonal} m) are {needed:.3f} m longer than verticals; the width joint"
            f" travels only {ee['width_travel']} m",
        )
    if ee["grip_spacing"] + 2 * ee["rivet_gun_offset"] > vertical + 1e-6 + 2 * ee["rivet_reach"]:
        raise ConfigError(
            source,
            "end_effector.rivet_gun_offset",
            f"rivet guns do not meet the ends of a {vertical} m strut",
        )
    check_rivets(edu, source)
    if 2 * (parts["corner_size"] / 2 + parts["fitting_length"]) >= vertical:
        raise ConfigError(source, "parts.fitting_length", "end fittings and corners leave no tube")
    if parts["tube_radius"] >= parts["fitting_radius"]:
        raise ConfigError(source, "parts.tube_radius", "the tube must be thinner than its end fittings")


def check_rivets(edu: dict[str, Any], source: str) -> None:
    """Refuse rivet tolerances and failure shapes the machine and its parts cannot have."""
    rivets, ee, parts = edu["rivets"], edu["end_effector"], edu["parts"]
    if rivets["max_offset"] >= ee["rivet_reach"]:
        raise ConfigError(
            source,
            "rivets.max_offset",
            f"must be less than end_effector.rivet_reach ({ee['rivet_reach']} m): past the reach a"
            " gun rivets nothing",
        )
    if rivets["partial_grip_height"] >= rivets["proud_height"]:
        raise ConfigError(source, "rivets.partial_grip_height", "must be less than rivets.proud_height")
    room = parts["fitting_length"] / 2 - parts["rivet_radius"]
    if rivets["wrong_hole_offset"] > room:
        raise ConfigError(
            source,
            "rivets.wrong_hole_offset",
            f"the wrong hole must lie on the end fitting: at most {room:.4f} m"
            " (parts.fitting_length / 2 - parts.rivet_radius)",
        )
    if rivets["wrong_hole_offset"] < 2 * parts["rivet_radius"]:
        raise ConfigError(
            source, "rivets.wrong_hole_offset", "a head in the wrong hole must not overlap the right hole's"
        )
    good = edu["physics"]["rivet_solref"][0]
    for key in ("unseated_solref", "loose_solref"):
        if rivets[key][0] <= good:
            raise ConfigError(
                source,
                f"rivets.{key}",
                f"a joint that holds badly must be softer than a good one: time constant above"
                f" physics.rivet_solref's {good} s",
            )


def load_edu(
    path: str | Path = DEFAULT_EDU, mission: Mission | str | Path | None = None
) -> tuple[dict[str, Any], Mission]:
    """Load ``edu.yaml`` and the mission (given, or the file's ``mission`` key); check them together."""
    path = Path(path)
    edu = validate(load_yaml(path), SCHEMA, source=path)
    if mission is None:
        mission = REPO_ROOT / edu["mission"]
    if not isinstance(mission, Mission):
        mission = load_mission(mission)
    check_against_mission(edu, mission, str(path))
    return edu, mission


__all__ = ["DEFAULT_EDU", "REPO_ROOT", "SCHEMA", "check_against_mission", "check_rivets", "load_edu"]
