"""Motion-planning benchmark: planning queries drawn from building a 3-bay tower (issue 6, §V.D).

For every member of the mission, in build order, the arm that adds it plans the moves of its Add
Member (or Add Cross Frame) request, each from where the previous one ended:

  home -> over the dispenser -> onto the part (grasp) -> lift -> inspection pose (carrying the part)
  -> pre-place pose -> placement pose (straight Cartesian move; the EE may touch the tower)
  -> back to the pre-place pose (Cartesian) -> home

and for each rivet a gun is brought to its joint the same way (pre-pose, then onto the joint). The
tower in the scene is the tower as built before that member, the other arm stands at home.

Prints median and p95 planning time (goals 50 ms / 200 ms), the success rate over feasible
queries (start and goal collision-free; goal 99 %), and, where the joint-space straight line
from start to the planned goal is collision-free, the executed trajectory duration against the
time-optimal straight-line duration measured in the same run (goal ratio <= 1.3).

    .venv/bin/python bench/planning.py [--mission missions/three_bay.yaml] [--bays 3] [--limit N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tlt_ars.planning.planner import Planner, PlanningFailed
from tlt_ars.planning.reachability import TargetUnreachable, same_branch, usable_approaches
from tlt_ars.planning.targets import (
    Target,
    dispenser_targets,
    inspection_targets,
    placement_targets,
    rivet_targets,
)
from tlt_ars.planning.time_parameterisation import straight_line_duration, time_parameterise
from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common.geometry.ur10e import IkFailed
from tlt_common.mission import generate
from tlt_common.mission.schema import load_mission, parse_mission

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Query:
    label: str
    arm: str
    bay: int
    placed: tuple[str, ...]
    carrying: str | None
    contact: bool
    target: Target | None  # a pose goal (its .pose), or None for home
    pre: bool = False  # aim at the target's pre-pose instead of its pose
    cartesian: bool = False  # a straight tool move (approach, grasp, lift, retreat)
    # For a pre-pose: whether the Cartesian approach onto the pose works from a configuration.
    approach: Callable[[np.ndarray], bool] | None = None


def build_queries(cfg, mission, limit: int = 0, resolve: bool = True) -> list[Query]:
    """The fixed query list of one mission. Each step's target is the first candidate that the
    reachability check finds usable (as the ARS picks it); a step with none is kept with its
    first candidate and counts as infeasible. ``resolve=False`` skips that check (first
    candidates, no branch test): the shape of the query set only."""
    out: list[Query] = []
    placed: list[str] = []
    resolution = cfg.planning["dense_check_resolution"]
    cache: dict[tuple, tuple] = {}

    def choose(arm: str, bay: int, before: tuple[str, ...], carrying: str | None, targets: list[Target]):
        """The first usable target and a test of the pre-pose configurations that approach it."""
        key = (arm, bay, before, carrying)
        if resolve and key not in cache:
            cache.clear()
            cache[key] = tuple(
                build_scene(cfg, arm, mission, placed=before, bay=bay, carrying=carrying, contact=c)
                for c in (False, True)
            )
        if not resolve:
            return targets[0], None
        full, contact = cache[key]
        for target in targets:
            try:
                branches = usable_approaches(full, contact, target, cfg.home(arm), resolution)
            except TargetUnreachable:
                continue
            return target, same_branch([q_pre for q_pre, _ in branches])
        return targets[0], None

    def add(label: str, arm: str, bay: int, tower: tuple[str, ...], carrying: str | None, contact: bool,
            chosen: tuple[Target, np.ndarray | None] | None, kind: str) -> None:  # fmt: skip
        """kind: "pre" (plan to the pre-pose configuration), "pose" (plan to a pose), "line"
        (Cartesian move onto the pose), "back" (Cartesian move back to the pre-pose), "home"."""
        target = chosen[0] if chosen is not None else None
        out.append(
            Query(
                label,
                arm,
                bay,
                tower,
                carrying,
                contact,
                target,
                pre=kind in ("pre", "back"),
                cartesian=kind in ("line", "back"),
                approach=chosen[1] if kind == "pre" and chosen is not None else None,
            )
        )

    for member in mission.members:
        if limit and len(out) >= limit:
            break
        before = tuple(placed)
        bay, mid = member.bay, member.id
        if member.kind == "foundation_rivet":
            arm = member.add_ars
            joint = member.joints[0][0]
            t = choose(arm, bay, before, None, rivet_targets(cfg, mission, member, joint, arm))
            add(f"{mid} rivet pre", arm, bay, before, None, False, t, "pre")
            add(f"{mid} rivet", arm, bay, before, None, True, t, "line")
            add(f"{mid} rivet retreat", arm, bay, before, None, True, t, "back")
            add(f"{mid} home", arm, bay, before, None, False, None, "home")
            placed.append(mid)
            continue
        arm, kind = member.add_ars, member.kind
        pick = choose(arm, bay, before, None, dispenser_targets(cfg, mission, member.dispenser, arm))
        place = choose(arm, bay, before, kind, placement_targets(cfg, mission, member, arm))
        inspect = choose(arm, bay, before, kind, inspection_targets(cfg, arm))
        add(f"{mid} dispenser approach", arm, bay, before, None, False, pick, "pre")
        add(f"{mid} grasp", arm, bay, before, None, False, pick, "line")
        add(f"{mid} lift", arm, bay, before, kind, False, pick, "back")
        add(f"{mid} inspection", arm, bay, before, kind, False, inspect, "pose")
        add(f"{mid} pre-place", arm, bay, before, kind, False, place, "pre")
        add(f"{mid} place", arm, bay, before, kind, True, place, "line")
        add(f"{mid} retreat", arm, bay, before, None, True, place, "back")
        add(f"{mid} home", arm, bay, before, None, False, None, "home")
        placed.append(mid)
        for rivet in member.rivets:
            if rivet.step != "affix":
                continue  # an add rivet is set from the placement pose, while the member is held
            now = tuple(placed)
            # The gun engages the member it rivets: that member is not an obstacle to it.
            t = choose(
                rivet.ars, bay, before, None, rivet_targets(cfg, mission, member, rivet.joint, rivet.ars)
            )
            add(f"{mid} affix pre", rivet.ars, bay, now, None, False, t, "pre")
            add(f"{mid} affix", rivet.ars, bay, before, None, True, t, "line")
            add(f"{mid} affix retreat", rivet.ars, bay, before, None, True, t, "back")
            add(f"{mid} affix home", rivet.ars, bay, now, None, False, None, "home")
    return out


SELF_PAIRS = [(i, j) for i in range(6) for j in range(i + 3, 6)]


def segment_distances(p0, p1, q0, q1):
    """Distances between n segment pairs, vectorised (closest points clamped to both segments)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    b = np.einsum("ij,ij->i", d1, d2)
    c = np.einsum("ij,ij->i", d1, r)
    f = np.einsum("ij,ij->i", d2, r)
    denom = a * e - b * b
    s = np.where(denom > 1e-12, np.clip((b * f - c * e) / np.maximum(denom, 1e-12), 0.0, 1.0), 0.0)
    t = (b * s + f) / np.maximum(e, 1e-12)
    s = np.where(t < 0.0, np.clip(-c / np.maximum(a, 1e-12), 0.0, 1.0), s)
    s = np.where(t > 1.0, np.clip((b - c) / np.maximum(a, 1e-12), 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p0 + d1 * s[:, None] - q0 - d2 * t[:, None], axis=1)


def compare_collision_checkers(cfg, mission, n: int = 2000) -> None:
    """Time per configuration of the three ways to check the arm's links against the capsules of
    a mid-build scene (tower, posts, other arm): coal with the scene's broad phase (naive AABB
    manager), coal over every pair, and capsule-capsule distances in numpy (which cannot do the
    boxes: floor, racks, payload, EE)."""
    from tlt_ars.planning.collision_scene import Capsule, CollisionScene, arm_link_segments

    placed = [m.id for m in mission.members if m.bay == 1]
    full = build_scene(cfg, "ars_x", mission, placed=placed, bay=2)
    caps = [s for g in ("lifter", "tower", "other_arm") for s in full.group(g) if isinstance(s, Capsule)]
    scene = CollisionScene(full.kin, link_radii=cfg.raw["link_radii"], padding=cfg.padding, name="ars_x")
    scene.set_group("capsules", caps)
    radii = np.array(cfg.raw["link_radii"]) + cfg.padding
    q0 = np.array([c.p0 for c in caps])
    q1 = np.array([c.p1 for c in caps])
    qr = np.array([c.radius for c in caps]) + cfg.padding
    m = len(caps)

    def numpy_check(q: np.ndarray) -> bool:
        segs = arm_link_segments(scene.kin, q)
        p0 = np.repeat(np.array([s[0] for s in segs]), m, axis=0)
        p1 = np.repeat(np.array([s[1] for s in segs]), m, axis=0)
        d = segment_distances(p0, p1, np.tile(q0, (6, 1)), np.tile(q1, (6, 1)))
        if np.any(d < np.repeat(radii, m) + np.tile(qr, 6)):
            return True
        # The scene's self-collision pairs: links three or more apart in the chain.
        a = np.array([segs[i][0] for i, _ in SELF_PAIRS]), np.array([segs[i][1] for i, _ in SELF_PAIRS])
        b = np.array([segs[j][0] for _, j in SELF_PAIRS]), np.array([segs[j][1] for _, j in SELF_PAIRS])
        d = segment_distances(a[0], a[1], b[0], b[1])
        return bool(np.any(d < np.array([radii[i] + radii[j] for i, j in SELF_PAIRS])))

    rng = np.random.default_rng(0)
    qs = rng.uniform(-np.pi, np.pi, (n, 6))
    qs[:, 2] = rng.uniform(-np.pi, np.pi, n)
    results = {}
    for name, fn in (
        ("coal + broad phase", scene.in_collision),
        ("coal, every pair", scene.in_collision_all_pairs),
        ("numpy capsules", numpy_check),
    ):
        fn(qs[0])
        t0 = time.perf_counter()
        results[name] = [fn(q) for q in qs]
        per = (time.perf_counter() - t0) / n * 1e6
        print(f"  {name:18s} {per:7.1f} us per configuration ({m} obstacle capsules x 6 links)")
    agree = sum(a == b for a, b in zip(results["coal + broad phase"], results["numpy capsules"], strict=True))
    print(f"  numpy and coal agree on {agree}/{n} configurations")
    # The whole planning scene (boxes, end effector, a carried strut): where the broad phase pays.
    carrying = build_scene(cfg, "ars_x", mission, placed=placed, bay=2, carrying="vertical")
    free = [q for q in qs if not carrying.in_collision(q)][:300]
    for name, fn in (
        ("coal + broad phase", carrying.in_collision),
        ("coal, every pair", carrying.in_collision_all_pairs),
    ):
        t0 = time.perf_counter()
        for q in free:
            fn(q)
        per = (time.perf_counter() - t0) / max(len(free), 1) * 1e6
        print(
            f"  full scene, {name:18s} {per:7.1f} us per collision-free configuration ({len(free)} of them)"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mission", type=Path, help="mission file (default: a generated 3-bay mission)")
    parser.add_argument("--bays", type=int, default=3, help="bays of the generated mission")
    parser.add_argument("--limit", type=int, default=0, help="run only the first N queries")
    parser.add_argument("--verbose", action="store_true", help="print every query")
    parser.add_argument("--no-collision-compare", action="store_true", help="skip the checker comparison")
    args = parser.parse_args(argv)

    cfg = load_scene_config()
    if args.mission is not None:
        mission = load_mission(args.mission)
    else:
        mission = parse_mission(generate.build(f"{args.bays}_bay_bench", args.bays), "<generated>")
    queries = build_queries(cfg, mission, args.limit)
    if args.limit:
        queries = queries[: args.limit]
    lim = cfg.limits
    vel, acc = lim["velocity"], lim["acceleration"]

    scenes: dict[tuple, Planner] = {}
    current = {arm: cfg.home(arm) for arm in cfg.arm_names}
    times: list[float] = []
    cpu: list[float] = []
    ratios: list[float] = []
    cartesian_ratios: list[float] = []
    straight_used = 0
    infeasible: list[str] = []
    failures: list[str] = []
    detour: list[float] = []
    for q in queries:
        key = (q.arm, q.bay, q.placed, q.carrying, q.contact)
        if key not in scenes:
            if len(scenes) > 8:
                scenes.clear()
            scene = build_scene(
                cfg, q.arm, mission, placed=q.placed, bay=q.bay, carrying=q.carrying, contact=q.contact
            )
            scenes[key] = Planner.from_config(scene, cfg.planning, home=cfg.home(q.arm))
        planner = scenes[key]
        start = current[q.arm]
        if planner.scene.in_collision(start):
            infeasible.append(f"{q.label}: start in collision")
            current[q.arm] = cfg.home(q.arm)
            continue
        if q.target is None:
            goal_pose = None
            goal_free = not planner.scene.in_collision(cfg.home(q.arm))
            goal_q = cfg.home(q.arm)
        else:
            goal_pose = q.target.pre_pose if q.pre else q.target.pose
            try:
                free = [s for s in planner.kin.inverse(goal_pose, start) if not planner.scene.in_collision(s)]
            except IkFailed:
                free = []
            goal_free = bool(free)
            # Where a failed query leaves the chain: the goal the planner would have aimed at.
            usable = [f for f in free if q.approach is None or q.approach(f)]
            goal_q = usable[0] if usable else (free[0] if free else start)
        if not goal_free:
            infeasible.append(f"{q.label}: no collision-free goal configuration")
            continue
        t0 = time.perf_counter()
        c0 = time.process_time()
        try:
            if goal_pose is None:
                plan = planner.plan_to_joints(start, cfg.home(q.arm), any_turn=True)
            elif q.approach is not None:
                plan = planner.plan_to_pose(start, goal_pose, accept=q.approach)
            elif q.cartesian:
                plan = planner.plan_cartesian(start, goal_pose)
            else:
                plan = planner.plan_to_pose(start, goal_pose)
        except PlanningFailed as exc:
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            failures.append(f"{q.label}: {exc.kind}: {exc.reason}")
            if args.verbose:
                print(f"FAIL {q.label}: {exc.reason}")
            # Carry on from the goal as if it had been reached, so one failure does not make the
            # following queries start somewhere the assembly never goes.
            current[q.arm] = goal_q
            continue
        dt = time.perf_counter() - t0
        times.append(dt)
        cpu.append(time.process_time() - c0)
        traj = time_parameterise(planner.blended(plan), vel, acc)  # as the ARS executes it
        if plan.straight_line:
            straight_used += 1
        line_free = plan.straight_line or planner.scene.segment_free(
            start, plan.goal, cfg.planning["dense_check_resolution"]
        )
        optimal = straight_line_duration(start, plan.goal, vel, acc)
        if line_free and optimal > 0 and q.cartesian:
            cartesian_ratios.append(traj.duration / optimal)
        elif line_free and optimal > 0:
            ratios.append(traj.duration / optimal)
        elif optimal > 0:
            detour.append(traj.duration / optimal)
        if args.verbose:
            print(
                f"ok {q.label}: {dt * 1e3:.1f} ms, {len(plan.path)} waypoints,"
                f" straight={plan.straight_line}, {traj.duration:.2f} s"
            )
        current[q.arm] = plan.goal

    feasible = len(queries) - len(infeasible)
    ok = feasible - len(failures)
    ms = sorted(t * 1e3 for t in times)
    print(
        f"mission {mission.name}: {len(queries)} queries, {feasible} feasible, {len(infeasible)} infeasible"
    )
    if ms:
        p95 = ms[min(len(ms) - 1, int(np.ceil(0.95 * len(ms))) - 1)]
        print(
            f"planning time: median {statistics.median(ms):.1f} ms (goal <= 50),"
            f" p95 {p95:.1f} ms (goal <= 200), max {ms[-1]:.1f} ms"
        )
        cms = sorted(t * 1e3 for t in cpu)
        cpu95 = cms[min(len(cms) - 1, int(np.ceil(0.95 * len(cms))) - 1)]
        print(
            f"  as CPU time of this process (less sensitive to a loaded machine): median"
            f" {statistics.median(cms):.1f} ms, p95 {cpu95:.1f} ms; load average {os.getloadavg()[0]:.1f}"
            f" on {os.cpu_count()} CPUs"
        )
    rate = ok / feasible if feasible else 0.0
    print(f"success over feasible queries: {ok}/{feasible} = {rate * 100:.1f} % (goal >= 99 %)")
    print(f"straight line used without sampling: {straight_used} of {ok}")
    if ratios:
        print(f"duration ratio vs time-optimal straight line (line free, n={len(ratios)}):"
              f" median {statistics.median(ratios):.3f}, max {max(ratios):.3f} (goal <= 1.3)")  # fmt: skip
    if cartesian_ratios:
        print(
            f"Cartesian moves (tool on a straight line, corners blended, n={len(cartesian_ratios)}):"
            f" duration / joint straight line median {statistics.median(cartesian_ratios):.3f},"
            f" max {max(cartesian_ratios):.3f} (not planner output: the tool path is prescribed)"
        )
    if detour:
        print(
            f"detours (straight line blocked, n={len(detour)}): duration / blocked straight line"
            f" median {statistics.median(detour):.2f}, max {max(detour):.2f}"
            " (no goal: that line is not executable)"
        )
    for line in infeasible[:10]:
        print(f"  infeasible: {line}")
    for line in failures[:10]:
        print(f"  failed: {line}")
    if not args.no_collision_compare:
        print("collision checking, same scene, same configurations:")
        compare_collision_checkers(cfg, mission)
    return 0


if __name__ == "__main__":
    sys.exit(main())
