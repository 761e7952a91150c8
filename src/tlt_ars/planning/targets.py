"""Where the tool goes for each assembly step: candidate tool poses (world, 4x4) of one arm.

Reads the scene file (tool, approach distance, dispenser stacks, inspection poses are the
scene's) and the mission (member joints, dispenser poses). Writes :class:`Target` lists; a target
is a tool pose and its pre-pose (standing off by the approach distance, where a straight final
move starts). Several candidates exist for most steps (which side to come from, which way the
bar points); the planner or the reachability check takes the first that works.

Tool frame conventions (docs/motion-planning.md):

* A strut is held along tool x (a vertical at its middle, a diagonal off it: below); the tool z is
  the approach direction.
* A cross frame is held at the middle of one side, along tool x, the frame extending along
  tool +y; tool z points down.
* A rivet gun sits at tool (+-gun_offset, 0, 0): riveting a joint puts one gun on it.
* A strut is held with gun 0 on one end, ready for its add rivet: one longer than the guns' span
  (a diagonal) has its middle off the tool, towards gun 1 (:func:`held_offset`). Jaws closing on
  a tube hold it where it lies along them, so the offset is kept from the grasp to the placement.
* The end effector widens by sliding gripper b and gun b out along tool +x: a diagonal is grasped
  with the grippers spread (its width in the ARS configuration), which moves no target.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from tlt_ars.planning.world import (
    GUN_OFFSET,
    SceneConfig,
    dispenser_frame,
    held_offset,
    member_segments,
    tower_origin,
)
from tlt_common.geometry.transforms import pose_matrix, rpy_matrix

_DOWN = np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class Target:
    """A tool pose ``pose`` reached through ``pre_pose``; ``label`` says which candidate it is."""

    label: str
    pose: np.ndarray
    pre_pose: np.ndarray


def frame_from_axes(origin: np.ndarray, x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Pose with tool x along ``x`` (made orthogonal to ``z``) and tool z along ``z``."""
    z = z / np.linalg.norm(z)
    x = x - np.dot(x, z) * z
    x = x / np.linalg.norm(x)
    return pose_matrix(origin, np.column_stack([x, np.cross(z, x), z]))


def _target(label: str, pose: np.ndarray, back: np.ndarray) -> Target:
    pre = pose.copy()
    pre[:3, 3] = pose[:3, 3] + back
    return Target(label, pose, pre)


def _horizontal_approaches(axis: np.ndarray, towards: np.ndarray) -> list[np.ndarray]:
    """Horizontal unit directions at right angles to ``axis`` that do not come back towards the
    arm (not negative along ``towards``), best aligned first. Those across the arm's reach come
    last: a near vertical has the lifter post between it and the arm, and only a sideways
    approach keeps the end effector's cameras off the post."""
    if abs(axis[2]) > 0.999:
        dirs = [np.array([math.cos(a), math.sin(a), 0.0]) for a in np.arange(8) * math.pi / 4]
    else:
        side = np.cross(axis, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        dirs = [side, -side]
    flat = np.array([towards[0], towards[1], 0.0])
    n = np.linalg.norm(flat)
    if n < 1e-9:
        return dirs
    flat /= n
    good = [d for d in dirs if np.dot(d, flat) > -1e-6]
    return sorted(good, key=lambda d: -float(np.dot(d, flat)))


def part_in_tool(mission: Any, kind: str) -> np.ndarray:
    """The frame of a held ``kind`` part (its middle, x along it) in the tool frame (4x4)."""
    return pose_matrix((held_offset(mission, kind), 0.0, 0.0))


def _holding(targets: list[Target], mission: Any, kind: str) -> list[Target]:
    """Tool targets holding a ``kind`` part where :func:`part_in_tool` has it, from ``targets``
    that put the tool on the part's middle."""
    back = np.linalg.inv(part_in_tool(mission, kind))
    return [Target(t.label, t.pose @ back, t.pre_pose @ back) for t in targets]


def strut_targets(
    p0: np.ndarray,
    p1: np.ndarray,
    arm_base: np.ndarray,
    approach: float,
    signs: tuple[float, ...] = (1.0, -1.0),
) -> list[Target]:
    """Candidates for holding the strut p0..p1 at its middle, coming from the arm's side, with
    the bar along the strut: tool x towards p1 ("bar +", rivet gun 0 at p0) and/or towards p0
    ("bar -"), as ``signs`` say."""
    mid = (p0 + p1) / 2
    u = (p1 - p0) / np.linalg.norm(p1 - p0)
    out = []
    for k, d in enumerate(_horizontal_approaches(u, mid - arm_base[:3, 3])):
        for sign in signs:
            pose = frame_from_axes(mid, sign * u, d)
            out.append(_target(f"approach {k} bar {'+' if sign > 0 else '-'}", pose, -approach * d))
    return out


def cross_frame_targets(corners: list[np.ndarray], arm_base: np.ndarray, approach: float) -> list[Target]:
    """Candidates for holding a cross frame (corners in order) by one side from above, nearest
    side to the arm first; the pre-pose stands off outwards, horizontally."""
    centre = sum(corners) / len(corners)
    out = []
    for i in range(len(corners)):
        a, b = corners[i], corners[(i + 1) % len(corners)]
        mid = (a + b) / 2
        inward = centre - mid
        inward[2] = 0.0
        inward /= np.linalg.norm(inward)
        # Tool z down and tool y inwards make tool x = y cross z.
        x = np.cross(inward, _DOWN)
        pose = frame_from_axes(mid, x, _DOWN)
        out.append(_target(f"side {i}", pose, -approach * inward))
    base_xy = arm_base[:3, 3]
    return sorted(out, key=lambda t: float(np.linalg.norm(t.pose[:2, 3] - base_xy[:2])))


def placement_targets(cfg: SceneConfig, mission: object, member: object, arm: str) -> list[Target]:
    """Where ``arm`` holds ``member`` when placing it (tower frame at the build level of its bay).
    A strut is held with rivet gun 0, the one loaded for it, on the joint of its ``add`` rivet."""
    approach = cfg.raw["end_effector"]["approach_distance"]
    base = cfg.base(arm)
    origin = tower_origin(cfg, mission, member.bay)
    if member.kind == "cross_frame":
        corners = [origin + np.asarray(p, dtype=float) for _, p in member.joints]
        return cross_frame_targets(corners, base, cfg.raw["end_effector"]["cross_frame_approach_distance"])
    if member.kind in ("vertical", "diagonal"):
        (p0, p1) = member_segments(member, origin)[0]
        add = [r.joint for r in getattr(member, "rivets", ()) if r.step == "add"]
        # Either gun may face either end: with gun 0 at the wrong end of a near vertical, its add
        # rivet would join the bottom joint, and the affix rivet meant for it find that end taken.
        signs = (1.0, -1.0) if not add else (1.0,) if add[0] == member.joints[0][0] else (-1.0,)
        return _holding(strut_targets(p0, p1, base, approach, signs=signs), mission, member.kind)
    return []


def rivet_targets(
    cfg: SceneConfig,
    mission: object,
    member: object,
    joint: str,
    arm: str,
    gun_offset: float = GUN_OFFSET,
) -> list[Target]:
    """Where the tool goes to put a rivet gun on ``joint`` of ``member`` (bar along the member,
    or vertical for a foundation rivet)."""
    approach = cfg.raw["end_effector"]["approach_distance"]
    base = cfg.base(arm)
    origin = tower_origin(cfg, mission, member.bay)
    points = dict(member.joints)
    if joint not in points:
        raise KeyError(f"member {member.id} has no joint {joint}")
    j = origin + np.asarray(points[joint], dtype=float)
    if member.kind in ("vertical", "diagonal"):
        others = [origin + np.asarray(p, dtype=float) for k, p in member.joints if k != joint]
        u = others[0] - j
        u /= np.linalg.norm(u)
    else:
        u = np.array([0.0, 0.0, 1.0])
    out = []
    # The gun at tool x = -gun_offset sits on the joint when the tool is gun_offset along the bar.
    for k, d in enumerate(_horizontal_approaches(u, j - base[:3, 3])):
        for sign in (1.0, -1.0):
            pose = frame_from_axes(j + gun_offset * sign * u, sign * u, d)
            out.append(
                _target(f"gun on {joint}, approach {k} bar {'+' if sign > 0 else '-'}", pose, -approach * d)
            )
    return out


def dispenser_targets(
    cfg: SceneConfig,
    mission: object,
    dispenser: str,
    arm: str,
    remaining: int | None = None,
    gun_offset: float = GUN_OFFSET,
) -> list[Target]:
    """Where ``arm`` grasps the top part of ``dispenser`` (``remaining`` parts, full when omitted);
    the pre-pose is straight above it. A strut is grasped off its middle by :func:`held_offset`;
    a rivet is picked up by gun 0."""
    disp = mission.dispensers[dispenser]
    racks = cfg.raw["dispensers"]
    approach = cfg.raw["end_effector"]["approach_distance"]
    frame = dispenser_frame(cfg, disp)
    base = cfg.base(arm)
    up = np.array([0.0, 0.0, approach])
    count = disp.count if remaining is None else remaining
    top = racks["first_slot_height"] + max(count - 1, 0) * racks["slot_pitch"]
    if disp.part_kind == "rivet":
        pick = rivet_pickup_point(cfg, disp)
        out = []
        for k, yaw in enumerate(np.arange(4) * math.pi / 2):
            x = rpy_matrix((0.0, 0.0, yaw)) @ np.array([1.0, 0.0, 0.0])
            pose = frame_from_axes(pick + gun_offset * x, x, _DOWN)
            out.append(_target(f"rivet gun, yaw {k}", pose, up))
        return out
    centre = (frame @ np.array([0.0, 0.0, top, 1.0]))[:3]
    if disp.part_kind == "cross_frame":
        w = mission.bay_width
        local = [(-w / 2, -w / 2), (w / 2, -w / 2), (w / 2, w / 2), (-w / 2, w / 2)]
        corners = [(frame @ np.array([x, y, top, 1.0]))[:3] for x, y in local]
        return [
            Target(t.label, t.pose, _lift(t.pose, up)) for t in cross_frame_targets(corners, base, approach)
        ]
    axis = frame[:3, 0]
    out = []
    for sign in (1.0, -1.0):
        pose = frame_from_axes(centre, sign * axis, _DOWN)
        out.append(_target(f"bar {'+' if sign > 0 else '-'}", pose, up))
    return _holding(out, mission, disp.part_kind)


def rivet_pickup_point(cfg: SceneConfig, dispenser: Any) -> np.ndarray:
    """World point where a gun's muzzle takes a rivet: just over the top of the feeder's tray."""
    top = cfg.raw["dispensers"]["rivet"]["top"]
    return (dispenser_frame(cfg, dispenser) @ np.array([0.0, 0.0, top + 0.02, 1.0]))[:3]


def _lift(pose: np.ndarray, up: np.ndarray) -> np.ndarray:
    pre = pose.copy()
    pre[:3, 3] += up
    return pre


def inspection_targets(cfg: SceneConfig, arm: str) -> list[Target]:
    """The configured inspection pose of ``arm`` (where the CRS camera sees the held part), and
    the same pose turned half a turn about the tool z (a strut looks the same; a cross frame then
    extends the other way)."""
    spec = cfg.arm(arm)["inspection"]
    pose = pose_matrix(spec["position"], rpy_matrix(spec["rpy"]))
    turned = pose.copy()
    turned[:3, :2] = -turned[:3, :2]
    return [Target("inspection", pose, pose.copy()), Target("inspection turned", turned, turned.copy())]


def poses(targets: Iterable[Target]) -> list[np.ndarray]:
    return [t.pose for t in targets]


__all__ = [
    "Target",
    "cross_frame_targets",
    "dispenser_targets",
    "frame_from_axes",
    "inspection_targets",
    "part_in_tool",
    "placement_targets",
    "poses",
    "rivet_pickup_point",
    "rivet_targets",
    "strut_targets",
]
