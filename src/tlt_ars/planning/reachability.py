"""Reachability of a mission, checked when it loads rather than found mid-build (paper §V.C.2).

Reads the scene file and a mission. For every member, in build order, and the arm the mission
assigns to each step, it looks for one candidate tool pose (:mod:`tlt_ars.planning.targets`)
with an IK solution within the joint limits that is collision-free against the tower as built
before that step (the part being placed is carried; the member a rivet goes into is not an
obstacle to the gun). The steps checked:

* ``place``: the adding arm holds the member at its placement pose (cross frames, verticals,
  diagonals);
* ``rivet``: the arm named by each rivet puts a gun on its joint; the ``affix`` rivets of far
  verticals are the reason the paper gives two arms those members;
* ``foundation``: the foundation rivets of the last bay.

:func:`check_mission_reach` returns a :class:`ReachReport` listing every unreachable step with
the reason of the best candidate; :func:`require_reachable` raises :class:`UnreachableMember`
naming them. Nothing here moves an arm.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from tlt_ars.planning.collision_scene import CollisionScene
from tlt_ars.planning.planner import Planner, PlanningFailed
from tlt_ars.planning.targets import Target, placement_targets, rivet_targets
from tlt_ars.planning.world import SceneConfig, build_scene
from tlt_common.geometry.transforms import describe_pose
from tlt_common.geometry.ur10e import IkFailed


@dataclass(frozen=True)
class ReachIssue:
    """An unreachable step: which member, which arm, which step, and why."""

    member: str
    arm: str
    step: str
    reason: str

    def __str__(self) -> str:
        return f"{self.member}: {self.arm} cannot {self.step}: {self.reason}"


@dataclass
class ReachReport:
    """Every step checked (``reached`` maps (member, arm, step) to the joint configuration found)."""

    issues: list[ReachIssue] = field(default_factory=list)
    reached: dict[tuple[str, str, str], np.ndarray] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.issues


class UnreachableMember(ValueError):
    """A mission with steps no arm can reach; ``issues`` lists them."""

    def __init__(self, mission_name: str, issues: list[ReachIssue]) -> None:
        self.issues = issues
        lines = "; ".join(str(i) for i in issues[:5])
        more = f" (and {len(issues) - 5} more)" if len(issues) > 5 else ""
        super().__init__(f"mission '{mission_name}': {len(issues)} unreachable step(s): {lines}{more}")


def reach_target(
    scene: CollisionScene,
    contact_scene: CollisionScene,
    target: Target,
    current: np.ndarray,
    resolution: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint configurations (pre-pose, pose) of one target, or :class:`TargetUnreachable`.

    The pose is checked in ``contact_scene`` (the end effector and part may touch the tower);
    the pre-pose in the full ``scene``; the straight Cartesian move of the tool between them
    (:meth:`Planner.plan_cartesian`), on the same IK branch, in ``contact_scene`` at
    ``resolution`` rad. IK solutions are tried nearest ``current`` first.
    """
    return usable_approaches(scene, contact_scene, target, current, resolution, first_only=True)[0]


def usable_approaches(
    scene: CollisionScene,
    contact_scene: CollisionScene,
    target: Target,
    current: np.ndarray,
    resolution: float,
    *,
    first_only: bool = False,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every IK branch (pre-pose, pose configurations) from which ``target`` can be approached, as
    :func:`reach_target` checks one; :class:`TargetUnreachable` when there is none."""
    try:
        solutions = scene.kin.inverse(target.pose, current)
    except IkFailed as exc:
        raise TargetUnreachable(exc.reason) from exc
    first_hit = None
    approach = Planner(
        contact_scene, check_resolution=max(resolution, 0.02), dense_check_resolution=resolution
    )
    found = []
    for q in solutions:
        hit = contact_scene.first_collision(q)
        if hit is not None:
            first_hit = first_hit or f"at the pose, {hit[0]} with {hit[1]}"
            continue
        # Back out along the approach line from the pose: the pre-pose on the same IK branch.
        try:
            retreat = approach.plan_cartesian(q, target.pre_pose)
        except PlanningFailed as exc:
            first_hit = first_hit or f"the straight approach from the pre-pose fails: {exc.reason}"
            continue
        hit = scene.first_collision(retreat.goal)
        if hit is not None:
            first_hit = first_hit or f"at the pre-pose, {hit[0]} with {hit[1]}"
            continue
        found.append((retreat.goal, q))
        if first_only:
            break
    if not found:
        raise TargetUnreachable(f"{len(solutions)} IK solution(s), none usable (first: {first_hit})")
    return found


def same_branch(configs: list[np.ndarray], tolerance: float = 1e-3) -> Callable[[np.ndarray], bool]:
    """A test for :meth:`Planner.plan_to_pose`'s ``accept``: whether a configuration is one of
    ``configs`` up to whole turns of each joint (the same IK branch, reached either way round)."""
    turn = 2 * np.pi
    refs = [np.asarray(c, dtype=float) for c in configs]

    def accept(q: np.ndarray) -> bool:
        for ref in refs:
            d = (np.asarray(q) - ref) / turn
            if np.max(np.abs(d - np.round(d))) * turn < tolerance:
                return True
        return False

    return accept


class TargetUnreachable(ValueError):
    """No usable IK solution for a target; the message says why."""


@dataclass(frozen=True)
class Reached:
    """A usable target: its pre-pose and pose joint configurations (same IK branch)."""

    target: Target
    q_pre: np.ndarray
    q: np.ndarray


def first_reachable(
    scene: CollisionScene,
    contact_scene: CollisionScene,
    targets: Iterable[Target],
    current: np.ndarray,
    resolution: float = 0.01,
) -> tuple[Reached | None, str]:
    """The first target with a usable (pre-pose, pose) pair of configurations, or None and the
    reason the first candidate fails."""
    reasons = []
    for t in targets:
        try:
            q_pre, q = reach_target(scene, contact_scene, t, current, resolution)
            return Reached(t, q_pre, q), ""
        except TargetUnreachable as exc:
            reasons.append(f"{t.label}: {exc}")
    if not reasons:
        return None, "no candidate pose"
    if len(reasons) == 1:
        return None, reasons[0]
    return None, f"{len(reasons)} candidates fail, first: {reasons[0]}"


def check_mission_reach(
    cfg: SceneConfig,
    mission: object,
    arms: Iterable[str] | None = None,
    widths: Mapping[str, float] | None = None,
) -> ReachReport:
    """Check every place and rivet step of ``mission`` (for the arms in ``arms``; all when None),
    a part held with the EE as wide as ``widths`` says for its kind (0 when not given), as while
    it is placed and its add rivet set."""
    widths = {} if widths is None else widths
    wanted = set(cfg.arm_names if arms is None else arms)
    report = ReachReport()
    placed: list[str] = []
    scenes: dict[tuple, tuple[CollisionScene, CollisionScene]] = {}
    resolution = cfg.planning["dense_check_resolution"]

    def scene_for(arm: str, bay: int, carrying: str | None, tower: tuple[str, ...], width: float):
        key = (arm, bay, carrying, tower, width)
        if key not in scenes:
            scenes.clear()  # one scene at a time: each step sees a different tower
            kw = dict(placed=tower, bay=bay, carrying=carrying, width=width)
            scenes[key] = tuple(build_scene(cfg, arm, mission, contact=c, **kw) for c in (False, True))
        return scenes[key]

    def check(member: object, arm: str, step: str, carrying: str | None, tower: tuple[str, ...],
              targets: Callable[[], list[Target]], width: float = 0.0) -> None:  # fmt: skip
        if arm not in wanted:
            return
        if arm not in cfg.arm_names:
            report.issues.append(ReachIssue(member.id, arm, step, f"no arm '{arm}' in {cfg.source}"))
            return
        full, contact = scene_for(arm, member.bay, carrying, tower, width)
        candidates = targets()
        found, reason = first_reachable(full, contact, candidates, cfg.home(arm), resolution)
        if found is None:
            where = f" (first candidate {describe_pose(candidates[0].pose)})" if candidates else ""
            report.issues.append(ReachIssue(member.id, arm, step, reason + where))
        else:
            report.reached[(member.id, arm, step)] = found.q

    for member in mission.members:
        before = tuple(placed)
        placed.append(member.id)
        if member.kind == "foundation_rivet":
            joint = member.joints[0][0]
            arm = member.add_ars
            check(member, arm, f"foundation rivet at {joint}", None, before,
                  lambda m=member, j=joint, a=arm: rivet_targets(cfg, mission, m, j, a))  # fmt: skip
            continue
        arm = member.add_ars
        width = float(widths.get(member.kind, 0.0))
        check(member, arm, "place", member.kind, before,
              lambda m=member, a=arm: placement_targets(cfg, mission, m, a), width)  # fmt: skip
        # Rivets go in with the member placed, but the gun engages it: leave it out of the obstacles.
        # The add rivet is set before the EE lets go of the member, at the member's width.
        for rivet in member.rivets:
            w = width if rivet.step == "add" else 0.0
            check(member, rivet.ars, f"{rivet.step} rivet at {rivet.joint}", None, before,
                  lambda m=member, r=rivet: rivet_targets(cfg, mission, m, r.joint, r.ars), w)  # fmt: skip
    return report


def require_reachable(
    cfg: SceneConfig,
    mission: object,
    arms: Iterable[str] | None = None,
    widths: Mapping[str, float] | None = None,
) -> ReachReport:
    """:func:`check_mission_reach`, raising :class:`UnreachableMember` when anything is out of reach."""
    report = check_mission_reach(cfg, mission, arms, widths)
    if not report.ok:
        raise UnreachableMember(getattr(mission, "name", "?"), report.issues)
    return report


__all__ = [
    "ReachIssue",
    "ReachReport",
    "Reached",
    "UnreachableMember",
    "check_mission_reach",
    "first_reachable",
    "require_reachable",
    "same_branch",
    "usable_approaches",
]
