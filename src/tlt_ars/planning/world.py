"""The EDU world an arm plans in, built from ``config/planning/scene.yaml`` and a mission.

Reads the scene file (validated with ``tlt_common.config_schema``; an error names the file, key and
reason) and turns it, with the mission's tower geometry and dispenser poses, into the shapes of a
:class:`~tlt_ars.planning.collision_scene.CollisionScene`: floor, arm pedestals, lifter posts and
top beams (group ``lifter``), dispenser racks (``dispensers``), the tower as built so far
(``tower``: every placed member and the payload) and the other arm (``other_arm``).

World frame: z up, floor at ``site.floor_z``. The tower frame (mission joints) sits at
``base_origin + (0, 0, build_level + n * bay_height)`` while bay n is built: bay n's bottom cross
frame at the build level, the bays above it already lifted (the twin's convention).

Kept as one module over 500 lines: the scene file's schema and :class:`SceneConfig` (about half)
and the shapes drawn from its keys are one description of the world; the loader could stand in a
module of its own, but some twenty-five modules of the ARS, the tools and the tests of the twin and
of vision import the two together from here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tlt_ars.planning.collision_scene import Box, Capsule, CollisionScene, Shape, box_at
from tlt_common.config_schema import ConfigError, Field, load_validated, opt, validate
from tlt_common.geometry.transforms import pose_matrix, rot_z, rpy_matrix
from tlt_common.geometry.ur10e import Ur10eKinematics

REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_SCENE = REPO_ROOT / "config" / "planning" / "scene.yaml"


def _vec(n: int) -> Field:
    def check(v: list[Any]) -> str | None:
        if len(v) != n:
            return f"expected {n} numbers, got {len(v)}"
        return None

    return Field("list", item=Field("float"), check=check)


def _positive_vec(n: int) -> Field:
    def check(v: list[Any]) -> str | None:
        if len(v) != n:
            return f"expected {n} numbers, got {len(v)}"
        if any(x <= 0 for x in v):
            return "every value must be positive"
        return None

    return Field("list", item=Field("float"), check=check)


_ARM = {
    "base": _vec(3),
    "yaw_deg": Field("float"),
    "pedestal_height": Field("float", minimum=0.0),
    "pedestal_radius": Field("float", minimum=0.0),
    "home": _vec(6),
    "inspection": Field("dict", schema={"position": _vec(3), "rpy": _vec(3)}),
    "base_joint_range": opt(
        "list",
        None,
        item=Field("float"),
        check=lambda v: None if len(v) == 2 and v[0] < v[1] else "expected [lower, upper] with lower < upper",
    ),
}
_POSE = {"position": _vec(3), "rpy": _vec(3)}
# A box on the width slide (gripper b, gun b) moves out along flange x with the EE width joint.
# Where the slide stands: a width (m), or the (from, to) of a move under way.
Width = float | tuple[float, float]
_BOX = {
    "name": Field("str"),
    "position": _vec(3),
    "size": _positive_vec(3),
    "on_width_slide": opt("bool", False),
}
# Uprights of a part rack: each stands `beyond_part` (x, y) out from the stowed parts' ends/sides
# (a strut has no y extent), a square post of side `section`, rising `above_top_slot` above the
# top part of a full dispenser.
_UPRIGHTS = {
    "beyond_part": _positive_vec(2),
    "section": Field("float", minimum=0.001),
    "above_top_slot": Field("float", minimum=0.0),
}
_RACK = {"size": _positive_vec(2), "top": Field("float"), "uprights": opt("dict", None, schema=_UPRIGHTS)}
# The post that holds a dispenser's AprilTag: a square post of side `section` on the dispenser's
# -x axis, `beyond_part` out from the stowed parts' end (a feeder's: its tray's side), rising
# `above_top_slot` over the top slot of a full rack, or `feeder_height` for a rivet feeder.
_TAG_POST = {
    "beyond_part": Field("float", minimum=0.0),
    "section": Field("float", minimum=0.001),
    "above_top_slot": Field("float", minimum=0.0),
    "feeder_height": Field("float", minimum=0.001),
}

SCHEMA = {
    "format": Field("int", choices=(1,)),
    "padding": Field("float", minimum=0.0, maximum=0.1),
    "site": Field(
        "dict",
        schema={"build_level": Field("float"), "base_origin": _vec(3), "floor_z": Field("float")},
    ),
    "lifter": Field(
        "dict",
        schema={
            "posts": Field("list", item=_vec(2), min_items=1),
            "post_radius": Field("float", minimum=0.001),
            "post_height": Field("float", minimum=0.01),
            "top_beam_radius": Field("float", minimum=0.0),
        },
    ),
    "tower": Field(
        "dict",
        schema={
            "member_radius": Field("float", minimum=0.001),
            "end_clearance": Field("float", minimum=0.0),
            "payload_size": _positive_vec(3),
            "payload_gap": Field("float", minimum=0.0),
        },
    ),
    "dispensers": Field(
        "dict",
        schema={
            "cross_frame": Field("dict", schema=_RACK),
            "vertical": Field("dict", schema=_RACK),
            "diagonal": Field("dict", schema=_RACK),
            "rivet": Field("dict", schema=_RACK),
            "tag_post": Field("dict", schema=_TAG_POST),
            "first_slot_height": Field("float"),
            "slot_pitch": Field("float", minimum=0.0),
        },
    ),
    "arms": Field("map", item=Field("dict", schema=_ARM)),
    "link_radii": _positive_vec(6),
    "end_effector": Field(
        "dict",
        schema={
            "tool": Field("dict", schema=_POSE),
            "boxes": Field("list", item=Field("dict", schema=_BOX)),
            "approach_distance": Field("float", minimum=0.0),
            "cross_frame_approach_distance": Field("float", minimum=0.0),
        },
    ),
    "planning": Field(
        "dict",
        schema={
            "check_resolution": Field("float", minimum=1e-4, maximum=0.5),
            "dense_check_resolution": Field("float", minimum=1e-4, maximum=0.5),
            "planning_time_s": Field("float", minimum=0.001),
            "simplify_time_s": Field("float", minimum=0.0),
            "max_ik_solutions": Field("int", minimum=1, maximum=8),
            "via_configurations": opt("list", [], item=_vec(6)),
            "blend_deviation": opt("float", 0.1, minimum=0.0, maximum=0.5),
            "cartesian_blend_deviation": opt("float", 0.005, minimum=0.0, maximum=0.5),
        },
    ),
    "limits": Field(
        "dict",
        schema={
            "position_lower": _vec(6),
            "position_upper": _vec(6),
            "velocity": _positive_vec(6),
            "acceleration": _positive_vec(6),
        },
    ),
}


@dataclass(frozen=True)
class SceneConfig:
    """The validated scene file. ``raw`` is the dict with defaults filled in."""

    raw: dict[str, Any]
    source: str

    @property
    def padding(self) -> float:
        return self.raw["padding"]

    @property
    def planning(self) -> dict[str, Any]:
        return self.raw["planning"]

    @property
    def limits(self) -> dict[str, Any]:
        return self.raw["limits"]

    @property
    def arm_names(self) -> list[str]:
        return sorted(self.raw["arms"])

    def arm(self, name: str) -> dict[str, Any]:
        try:
            return self.raw["arms"][name]
        except KeyError:
            raise KeyError(f"{self.source}: no arm '{name}' (arms: {', '.join(self.arm_names)})") from None

    def home(self, arm: str) -> np.ndarray:
        return np.array(self.arm(arm)["home"], dtype=float)

    def tool(self) -> np.ndarray:
        t = self.raw["end_effector"]["tool"]
        return pose_matrix(t["position"], rpy_matrix(t["rpy"]))

    def base(self, arm: str) -> np.ndarray:
        """World pose of the arm's base frame (on top of its pedestal, turned by its yaw)."""
        a = self.arm(arm)
        x, y, z = a["base"]
        return pose_matrix((x, y, z + a["pedestal_height"]), rot_z(math.radians(a["yaw_deg"])))

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        """Position limits of ``arm``: the UR10e's, with the base joint narrowed to the arm's
        ``base_joint_range`` when the scene gives one."""
        lower = np.array(self.limits["position_lower"], dtype=float)
        upper = np.array(self.limits["position_upper"], dtype=float)
        rng = self.arm(arm).get("base_joint_range")
        if rng is not None:
            lower[0], upper[0] = max(lower[0], rng[0]), min(upper[0], rng[1])
        return lower, upper

    def kinematics(self, arm: str) -> Ur10eKinematics:
        lower, upper = self.joint_limits(arm)
        return Ur10eKinematics(base=self.base(arm), tool=self.tool(), lower=lower, upper=upper)

    def ee_boxes(self, width: Width = 0.0) -> list[tuple[str, np.ndarray, Sequence[float]]]:
        """The end effector's boxes (flange frame) with the width joint at ``width`` (m), or, for a
        ``(from, to)`` pair, each box on the slide stretched over its whole sweep between them."""
        lo, hi = (width, width) if np.isscalar(width) else sorted(width)
        out = []
        for b in self.raw["end_effector"]["boxes"]:
            x, y, z = b["position"]
            sx, sy, sz = b["size"]
            if b["on_width_slide"]:
                x, sx = x + (lo + hi) / 2, sx + (hi - lo)
            out.append((b["name"], pose_matrix((x, y, z)), (sx, sy, sz)))
        return out


def _check_semantics(raw: dict[str, Any], source: str) -> None:
    lim = raw["limits"]
    for i, (lo, hi) in enumerate(zip(lim["position_lower"], lim["position_upper"], strict=True)):
        if lo >= hi:
            raise ConfigError(source, f"limits.position_lower[{i}]", f"{lo} is not below position_upper {hi}")
    for name, arm in raw["arms"].items():
        for i, q in enumerate(arm["home"]):
            if not lim["position_lower"][i] <= q <= lim["position_upper"][i]:
                raise ConfigError(source, f"arms.{name}.home[{i}]", f"{q} is outside the joint limits")
        rng = arm.get("base_joint_range")
        if rng is not None and not rng[0] <= arm["home"][0] <= rng[1]:
            raise ConfigError(source, f"arms.{name}.home[0]", f"{arm['home'][0]} is outside base_joint_range")
    if not raw["arms"]:
        raise ConfigError(source, "arms", "expected at least one arm")


def load_scene_config(path: str | Path = DEFAULT_SCENE) -> SceneConfig:
    """Load and validate the scene file; :class:`ConfigError` names file, key and reason."""
    raw = load_validated(path, SCHEMA)
    _check_semantics(raw, str(path))
    return SceneConfig(raw, str(path))


def scene_config_from_dict(data: dict[str, Any], source: str = "<scene>") -> SceneConfig:
    """Validate an in-memory scene (tests and tools that vary the layout)."""
    raw = validate(data, SCHEMA, source=source)
    _check_semantics(raw, source)
    return SceneConfig(raw, source)


# Distance of each rivet gun from the tool along the bar with the width joint at 0 (grip spacing
# / 2 + gun offset; the twin's end effector, config/twin/edu.yaml).
GUN_OFFSET = 0.375


# ----- shapes of the world -----
def static_shapes(cfg: SceneConfig, mission: Any | None = None) -> dict[str, list[Shape]]:
    """Floor, pedestals, lifter frame and (with a mission) dispenser racks, by group."""
    raw = cfg.raw
    floor_z = raw["site"]["floor_z"]
    env: list[Shape] = [box_at("floor", (0.0, 0.0, floor_z - 0.05), (20.0, 20.0, 0.1))]
    for name in cfg.arm_names:
        a = cfg.arm(name)
        if a["pedestal_height"] > 0 and a["pedestal_radius"] > 0:
            x, y, z = a["base"]
            # A box circumscribing the round pedestal, stopping 2 cm under the arm's own base.
            h = a["pedestal_height"] - 0.02
            side = 2 * a["pedestal_radius"]
            env.append(box_at(f"{name}/pedestal", (x, y, z + h / 2), (side, side, h)))
    lf = raw["lifter"]
    lifter: list[Shape] = []
    posts = lf["posts"]
    for i, (x, y) in enumerate(posts):
        lifter.append(
            Capsule(
                f"lifter/post_{i}", (x, y, floor_z), (x, y, floor_z + lf["post_height"]), lf["post_radius"]
            )
        )
    if lf["top_beam_radius"] > 0 and len(posts) > 1:
        top = floor_z + lf["post_height"]
        for i in range(len(posts)):
            (x0, y0), (x1, y1) = posts[i], posts[(i + 1) % len(posts)]
            lifter.append(Capsule(f"lifter/beam_{i}", (x0, y0, top), (x1, y1, top), lf["top_beam_radius"]))
    groups: dict[str, list[Shape]] = {"environment": env, "lifter": lifter}
    if mission is not None:
        groups["dispensers"] = dispenser_shapes(cfg, mission)
    return groups


def dispenser_frame(cfg: SceneConfig, dispenser: Any) -> np.ndarray:
    """World pose of a mission dispenser."""
    origin = np.asarray(cfg.raw["site"]["base_origin"], dtype=float)
    return pose_matrix(origin + np.asarray(dispenser.position, dtype=float), rpy_matrix(dispenser.rpy))


def dispenser_shapes(cfg: SceneConfig, mission: Any) -> list[Shape]:
    racks = cfg.raw["dispensers"]
    floor_z = cfg.raw["site"]["floor_z"]
    out: list[Shape] = []
    for name, disp in mission.dispensers.items():
        rack = racks[disp.part_kind]
        frame = dispenser_frame(cfg, disp)
        top = frame[2, 3] + rack["top"]
        height = top - floor_z
        if height <= 0:
            continue
        pose = frame.copy()
        pose[2, 3] = floor_z + height / 2
        out.append(Box(f"dispenser/{name}", pose, (rack["size"][0], rack["size"][1], height)))
        out += _upright_shapes(cfg, mission, name, disp, frame)
    for name, disp in mission.dispensers.items():
        out.append(tag_post_shape(cfg, mission, name, disp))
    return out


def tag_post_shape(cfg: SceneConfig, mission: Any, name: str, dispenser: Any) -> Box:
    """The post that holds ``dispenser``'s AprilTag (full dispenser), from the dispenser's origin
    up. It stands where the D405 looks to locate the dispenser: a joint-space path to a coarse pose
    that does not know of it can run an end effector's gun bracket into it and overload the width
    servo."""
    racks = cfg.raw["dispensers"]
    spec = racks["tag_post"]
    kind = dispenser.part_kind
    if kind == "rivet":
        extent, height = racks["rivet"]["size"][0], spec["feeder_height"]
    else:
        extent = mission.bay_width if kind == "cross_frame" else mission.strut_lengths[kind]
        top = racks["first_slot_height"] + max(dispenser.count - 1, 0) * racks["slot_pitch"]
        height = top + spec["above_top_slot"]
    x = -(extent / 2 + spec["beyond_part"])
    pose = dispenser_frame(cfg, dispenser) @ pose_matrix((x, 0.0, height / 2))
    return Box(f"dispenser/{name}/tag_post", pose, (spec["section"], spec["section"], height))


def rack_upright_positions(cfg: SceneConfig, mission: Any, dispenser: Any) -> list[np.ndarray]:
    """Centre (x, y) of each upright of ``dispenser``'s rack in its own frame (none configured: [])."""
    spec = cfg.raw["dispensers"][dispenser.part_kind].get("uprights")
    if spec is None:
        return []
    if dispenser.part_kind == "cross_frame":
        extent = (mission.bay_width, mission.bay_width)
    else:
        extent = (mission.strut_lengths[dispenser.part_kind], 0.0)
    hx, hy = (extent[k] / 2 + spec["beyond_part"][k] for k in range(2))
    return [np.array([sx * hx, sy * hy]) for sx in (-1, 1) for sy in (-1, 1)]


def rack_upright_height(cfg: SceneConfig, dispenser: Any) -> float:
    """Height of ``dispenser``'s rack uprights above its origin (full dispenser)."""
    racks = cfg.raw["dispensers"]
    top = racks["first_slot_height"] + max(dispenser.count - 1, 0) * racks["slot_pitch"]
    return top + racks[dispenser.part_kind]["uprights"]["above_top_slot"]


def _upright_shapes(cfg: SceneConfig, mission: Any, name: str, disp: Any, frame: np.ndarray) -> list[Shape]:
    # The uprights rise above the stowed parts, where the end effector works: a path that clears
    # the rack's box may still run a rivet gun into one.
    centres = rack_upright_positions(cfg, mission, disp)
    if not centres:
        return []
    side = cfg.raw["dispensers"][disp.part_kind]["uprights"]["section"]
    height = rack_upright_height(cfg, disp)
    out: list[Shape] = []
    for k, (x, y) in enumerate(centres):
        pose = frame @ pose_matrix((x, y, height / 2))
        out.append(Box(f"dispenser/{name}/upright_{k}", pose, (side, side, height)))
    return out


def tower_origin(cfg: SceneConfig, mission: Any, bay: int) -> np.ndarray:
    """World position of the tower frame while bay ``bay`` (1-based) is being built."""
    origin = np.asarray(cfg.raw["site"]["base_origin"], dtype=float)
    return origin + np.array([0.0, 0.0, cfg.raw["site"]["build_level"] + bay * mission.bay_height])


def member_segments(member: Any, origin: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """World end points of a member's struts: four sides of a cross frame, else joint to joint."""
    points = [origin + np.asarray(p, dtype=float) for _, p in member.joints]
    if member.kind == "cross_frame":
        return [(points[i], points[(i + 1) % len(points)]) for i in range(len(points))]
    if len(points) < 2:
        return []
    return [(points[0], points[1])]


def _shortened(p0: np.ndarray, p1: np.ndarray, clearance: float) -> tuple[np.ndarray, np.ndarray]:
    d = p1 - p0
    n = float(np.linalg.norm(d))
    if n <= 2 * clearance + 1e-6:
        mid = (p0 + p1) / 2
        return mid, mid
    u = d / n
    return p0 + u * clearance, p1 - u * clearance


def tower_shapes(cfg: SceneConfig, mission: Any, placed: Iterable[str], bay: int) -> list[Shape]:
    """The payload and every placed member while bay ``bay`` is built, as world shapes."""
    tw = cfg.raw["tower"]
    origin = tower_origin(cfg, mission, bay)
    w = mission.bay_width
    sx, sy, sz = tw["payload_size"]
    shapes: list[Shape] = [
        box_at("tower/payload", origin + np.array([w / 2, w / 2, tw["payload_gap"] + sz / 2]), (sx, sy, sz))
    ]
    # The payload's own cross frame (bay0) is always there.
    corners = [origin + np.array([i * w, j * w, 0.0]) for i, j in ((0, 0), (1, 0), (1, 1), (0, 1))]
    for i in range(4):
        a, b = _shortened(corners[i], corners[(i + 1) % 4], tw["end_clearance"])
        shapes.append(Capsule(f"tower/payload_frame/side_{i}", tuple(a), tuple(b), tw["member_radius"]))
    wanted = set(placed)
    for member in mission.members:
        if member.id not in wanted or member.kind == "foundation_rivet":
            continue
        for k, (p0, p1) in enumerate(member_segments(member, origin)):
            a, b = _shortened(p0, p1, tw["end_clearance"])
            shapes.append(Capsule(f"tower/{member.id}#{k}", tuple(a), tuple(b), tw["member_radius"]))
    return shapes


def held_offset(mission: Any, kind: str, gun_offset: float = GUN_OFFSET) -> float:
    """How far along tool x the middle of a held ``kind`` part is from the tool: a strut sits with
    its end at gun 0 (0 for a vertical, which spans both guns; 0.155 m for the EDU's diagonal); a
    cross frame is held at the middle of its side."""
    if kind not in ("vertical", "diagonal"):
        return 0.0
    return mission.strut_lengths[kind] / 2 - gun_offset


def carried_capsules(cfg: SceneConfig, mission: Any, kind: str) -> list[Capsule]:
    """A held part in the tool frame: a strut along tool x, its middle where :func:`held_offset`
    says; a cross frame held at the middle of one side (along tool x), the frame extending along
    tool +y."""
    tw = cfg.raw["tower"]
    r, c = tw["member_radius"], tw["end_clearance"]
    if kind == "cross_frame":
        w = mission.bay_width
        corners = [np.array(p) for p in ((-w / 2, 0, 0), (w / 2, 0, 0), (w / 2, w, 0), (-w / 2, w, 0))]
        out = []
        for i in range(4):
            a, b = _shortened(corners[i], corners[(i + 1) % 4], c)
            out.append(Capsule(f"cross_frame/side_{i}", tuple(a), tuple(b), r))
        return out
    if kind in ("vertical", "diagonal"):
        mid, half = held_offset(mission, kind), mission.strut_lengths[kind] / 2
        a, b = _shortened(np.array([mid - half, 0, 0]), np.array([mid + half, 0, 0]), c)
        return [Capsule(kind, tuple(a), tuple(b), r)]
    return []


def build_scene(
    cfg: SceneConfig,
    arm: str,
    mission: Any | None = None,
    *,
    placed: Iterable[str] = (),
    bay: int = 1,
    other_arm_q: Sequence[float] | None = None,
    carrying: str | None = None,
    contact: bool = False,
    width: Width = 0.0,
) -> CollisionScene:
    """A collision scene for ``arm``: the static world, the tower as built while bay ``bay`` is
    under construction (members in ``placed``), the other arm at ``other_arm_q`` (its home when
    omitted) and, when ``carrying`` names a part kind, that part in the tool. With ``contact`` the
    end effector and the part may touch the tower (the final move onto a joint). ``width`` is
    where the EE width joint stands (gripper b and gun b move with it), or the ``(from, to)`` of
    its move while the arm moves."""
    kin = cfg.kinematics(arm)
    scene = CollisionScene(
        kin,
        link_radii=cfg.raw["link_radii"],
        ee_boxes=cfg.ee_boxes(width),
        padding=cfg.padding,
        name=arm,
        allowed=[("link_1", f"{arm}/pedestal")],
        contact_groups=("tower",) if contact else (),
    )
    for group, shapes in static_shapes(cfg, mission).items():
        scene.set_group(group, shapes)
    if mission is not None:
        scene.set_group("tower", tower_shapes(cfg, mission, placed, bay))
    others = [a for a in cfg.arm_names if a != arm]
    if others:
        other = others[0]
        q = cfg.home(other) if other_arm_q is None else np.asarray(other_arm_q, dtype=float)
        scene.set_other_arm(cfg.kinematics(other), q, cfg.raw["link_radii"])
    if carrying is not None and mission is not None:
        scene.attach(carried_capsules(cfg, mission, carrying))
    return scene


__all__ = [
    "DEFAULT_SCENE",
    "GUN_OFFSET",
    "SCHEMA",
    "SceneConfig",
    "Width",
    "build_scene",
    "carried_capsules",
    "dispenser_frame",
    "dispenser_shapes",
    "held_offset",
    "load_scene_config",
    "member_segments",
    "scene_config_from_dict",
    "static_shapes",
    "tower_origin",
    "tower_shapes",
]
