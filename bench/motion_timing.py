"""Motion timing benchmark: the mission's arm moves timed the old way and the new way, side by side.

Plans the moves of building a tower (the query list of bench/planning.py: for each member in
build order, dispenser approach, grasp, lift, inspection, pre-place, place, retreat, home, and each
rivet likewise, each move starting where the previous one ended) and times every plan:

* old: the trapezoid per segment, stopping at every waypoint (``time_parameterise(plan.path)``);
* new: the plan's corners blended where the arcs are collision-free (``Planner.blended``) and the
  blended path timed by reachability analysis (``time_parameterise(blended)``), as the ARS does;
* bound: a lower bound on the duration of any motion along the path the new timing follows,
  under the same limits: the larger of (a) the slowest joint alone, from rest to rest over each
  stretch it moves one way (it must stop where it turns back), and (b) a phase-plane bound: on
  short intervals along the path, upper bounds on the path speed (joint velocities, acceleration
  normal to the path) and on the path acceleration, integrated from rest at both ends
  (``_phase_plane_bound``). No timing along that path can beat it;
* fine: the same reachability analysis on a grid ten times finer along the path (and four times
  finer round the arcs), which converges to the time-optimal duration along the path: what the
  grid of the new timing costs.

Prints, per kind of move and in total, the sum of durations old / new / bound / fine and the ratios, the
corners blended and kept as stops, the tool's largest distance from its straight line on the
Cartesian moves (polyline and blended), and the time the blending and timing take.

    .venv/bin/python bench/motion_timing.py [--mission missions/two_bay.yaml] [--bays 3] [--limit N]
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import statistics
import sys
import time
from pathlib import Path
from types import ModuleType

import numpy as np

from tlt_ars.planning import time_parameterisation
from tlt_ars.planning.blended_path import Arc, BlendedPath, blend_corners
from tlt_ars.planning.planner import Planner, PlanningFailed
from tlt_ars.planning.time_parameterisation import time_parameterise
from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common.geometry.ur10e import IkFailed
from tlt_common.mission import generate
from tlt_common.mission.schema import load_mission, parse_mission


def _planning_bench() -> ModuleType:
    """bench/planning.py, whose query list this bench times (benches are scripts, not a package)."""
    name = "planning_bench"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("planning.py"))
        assert spec is not None and spec.loader is not None
        sys.modules[name] = importlib.util.module_from_spec(spec)  # its dataclasses look it up there
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


def rest_to_rest(distance: np.ndarray, v: float, a: float) -> np.ndarray:
    """Least time to move ``distance`` from rest to rest at speed <= v, acceleration <= a."""
    cruise = distance >= v * v / a
    return np.where(cruise, distance / v + v / a, 2.0 * np.sqrt(distance / a))


def lower_bound(path: BlendedPath, vel: np.ndarray, acc: np.ndarray, resolution: float = 1e-3) -> float:
    """A lower bound (s) on the duration of any motion along ``path`` under the limits (module doc),
    each section blended or stopping at its waypoints (time_parameterise takes the faster)."""
    return sum(
        min(_bound(BlendedPath([section], [wps]), vel, acc, resolution),
            _bound(blend_corners(wps, 0.0), vel, acc, resolution))
        for section, wps in zip(path.sections, path.waypoints, strict=True)
    )  # fmt: skip


def _bound(path: BlendedPath, vel: np.ndarray, acc: np.ndarray, resolution: float) -> float:
    total = 0.0
    for section in path.sections:
        qs = BlendedPath([section], [[]]).configurations(resolution)
        dq = np.diff(qs, axis=0)
        by_joint = 0.0
        for i in range(qs.shape[1]):
            steps = dq[:, i][np.abs(dq[:, i]) > 1e-12]
            if steps.size == 0:
                continue
            turns = np.flatnonzero(np.sign(steps[1:]) != np.sign(steps[:-1])) + 1
            runs = np.abs(np.array([r.sum() for r in np.split(steps, turns)]))
            by_joint = max(by_joint, float(np.sum(rest_to_rest(runs, vel[i], acc[i]))))
        total += max(by_joint, _phase_plane_bound(section, vel, acc, resolution))
    return total


def _phase_plane_bound(section: list, vel: np.ndarray, acc: np.ndarray, resolution: float) -> float:
    """A lower bound on a rest-to-rest motion along ``section`` from the phase plane: on each short
    interval, an upper bound ``cap`` on x = (ds/dt)^2 from the joint velocities and the
    acceleration normal to the path, and ``U`` on |d2s/dt2|; no motion's x exceeds the curves
    that accelerate at U from rest at the start and to rest at the end, capped by ``cap``, so its
    duration is at least the integral of ds / sqrt of their minimum. Bounds over an interval of an
    arc widen the values at its ends by how far a sinusoid of the turn can bulge in between."""
    deltas, caps, limits = [], [], []
    for piece in section:
        m = max(1, int(np.ceil(piece.length / resolution)))
        edges = np.linspace(0.0, piece.length, m + 1)
        _, t, k = piece.evaluate(edges)
        t0, t1 = t[:-1], t[1:]
        if isinstance(piece, Arc):
            radius = piece.radius
            n = k * radius  # unit normal
            bulge = ((np.diff(edges) / radius) ** 2 / 8.0)[:, None] * np.hypot(piece.tangent, piece.normal)
        else:
            radius, n, bulge = np.inf, np.zeros_like(t), np.zeros_like(t0)
        same_sign = np.sign(t0) == np.sign(t1)
        t_min = np.where(same_sign, np.maximum(np.minimum(np.abs(t0), np.abs(t1)) - bulge, 0.0), 0.0)
        t_max = np.maximum(np.abs(t0), np.abs(t1)) + bulge
        n_max = np.maximum(np.abs(n[:-1]), np.abs(n[1:])) + bulge
        with np.errstate(divide="ignore"):
            cap = np.min(np.where(t_min > 0, (vel / np.where(t_min > 0, t_min, 1.0)) ** 2, np.inf), axis=1)
            if isinstance(piece, Arc):  # the acceleration normal to the path
                cap = np.minimum(cap, radius * (n_max @ acc))
            # Along the path: each joint's |t_i u| <= a_i + |n_i| x / radius, and u <= sum |t_i| a_i.
            along = (acc + n_max * (cap / radius)[:, None]) / np.where(t_min > 0, t_min, np.nan)
            limit = np.minimum(np.nanmin(np.where(t_min > 0, along, np.inf), axis=1), t_max @ acc)
        deltas.append(np.diff(edges))
        caps.append(cap)
        limits.append(limit)
    delta, cap, limit = (np.concatenate(v).tolist() for v in (deltas, caps, limits))
    count = len(delta)
    forward = [0.0] * (count + 1)
    for j in range(count):
        forward[j + 1] = min(forward[j] + 2.0 * limit[j] * delta[j], cap[j])
    backward = [0.0] * (count + 1)
    for j in range(count - 1, -1, -1):
        backward[j] = min(backward[j + 1] + 2.0 * limit[j] * delta[j], cap[j])
    total = 0.0
    for j in range(count):
        d, u = delta[j], limit[j]
        # On the interval x <= cap, <= forward[j] + 2 u (s - s_j), <= backward[j + 1] + 2 u (s_j+1 - s).
        best = d / math.sqrt(min(cap[j], forward[j + 1], backward[j]))
        best = max(best, (math.sqrt(forward[j] + 2 * u * d) - math.sqrt(forward[j])) / u)
        best = max(best, (math.sqrt(backward[j + 1] + 2 * u * d) - math.sqrt(backward[j + 1])) / u)
        total += best
    return total


def fine_duration(path: BlendedPath, vel: np.ndarray, acc: np.ndarray) -> float:
    """The new timing's duration on a grid ten times finer (four times round arcs)."""
    tp = time_parameterisation
    saved = tp.GRID_STEP, tp.ARC_GRID_TURN, tp.PIECE_INTERVALS
    tp.GRID_STEP, tp.ARC_GRID_TURN, tp.PIECE_INTERVALS = saved[0] / 10, saved[1] / 4, saved[2] * 10
    try:
        return time_parameterise(path, vel, acc).duration
    finally:
        tp.GRID_STEP, tp.ARC_GRID_TURN, tp.PIECE_INTERVALS = saved


def tool_offset(planner: Planner, qs: np.ndarray) -> float:
    """Largest distance (m) of the tool at ``qs`` from the straight line between its first and last."""
    points = np.array([planner.kin.forward(q)[:3, 3] for q in qs])
    a, b = points[0], points[-1]
    ab = b - a
    u = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return float(np.max(np.linalg.norm(points - (a + u[:, None] * ab), axis=1)))


RATIOS = ("new/old", "old/bound", "new/bound", "new/fine")


def _row(label: str, n: int, sums: np.ndarray) -> str:
    old, new, bound, fine = sums
    ratios = (new / old, old / bound, new / bound, new / fine)
    figures = f"{old:>9.1f}{new:>9.1f}{bound:>9.1f}{fine:>9.1f}"
    return f"{label:<17}{n:>4}" + figures + "".join(f"{r:>10.3f}" for r in ratios)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mission", type=Path, help="mission file (default: a generated 3-bay mission)")
    parser.add_argument("--bays", type=int, default=3, help="bays of the generated mission")
    parser.add_argument("--limit", type=int, default=0, help="run only the first N queries")
    parser.add_argument("--blend", type=float, help="blend deviation of joint-space moves, rad (scene file)")
    parser.add_argument("--cartesian-blend", type=float, help="blend deviation of Cartesian moves, rad")
    parser.add_argument("--verbose", action="store_true", help="print every move")
    args = parser.parse_args(argv)

    cfg = load_scene_config()
    if args.mission is not None:
        mission = load_mission(args.mission)
    else:
        mission = parse_mission(generate.build(f"{args.bays}_bay_bench", args.bays), "<generated>")
    queries = _planning_bench().build_queries(cfg, mission, args.limit)
    if args.limit:
        queries = queries[: args.limit]
    vel = np.asarray(cfg.limits["velocity"], dtype=float)
    acc = np.asarray(cfg.limits["acceleration"], dtype=float)
    planning = dict(cfg.planning)
    if args.blend is not None:
        planning["blend_deviation"] = args.blend
    if args.cartesian_blend is not None:
        planning["cartesian_blend_deviation"] = args.cartesian_blend

    kinds = ("straight line", "detour / search", "Cartesian")
    sums = {k: np.zeros(4) for k in kinds}
    ratios: dict[str, list[float]] = {k: [] for k in kinds}
    fine_ratios: dict[str, list[float]] = {k: [] for k in kinds}
    counts = dict.fromkeys(kinds, 0)
    blended = stops = stopped = skipped = 0
    offsets_old: list[float] = []
    offsets_new: list[float] = []
    cpu: list[float] = []
    current = {arm: cfg.home(arm) for arm in cfg.arm_names}
    for q in queries:
        scene = build_scene(
            cfg, q.arm, mission, placed=q.placed, bay=q.bay, carrying=q.carrying, contact=q.contact
        )
        planner = Planner.from_config(scene, planning, home=cfg.home(q.arm))
        start = current[q.arm]
        try:
            if scene.in_collision(start):
                raise PlanningFailed("start_collision", "start in collision")
            if q.target is None:
                plan = planner.plan_to_joints(start, cfg.home(q.arm), any_turn=True)
            else:
                pose = q.target.pre_pose if q.pre else q.target.pose
                if q.cartesian:
                    plan = planner.plan_cartesian(start, pose)
                else:
                    plan = planner.plan_to_pose(start, pose, accept=q.approach)
        except (PlanningFailed, IkFailed):
            skipped += 1
            current[q.arm] = cfg.home(q.arm)
            continue
        current[q.arm] = plan.goal
        old = time_parameterise(plan.path, vel, acc).duration
        c0 = time.process_time()
        path = planner.blended(plan)
        timed = time_parameterise(path, vel, acc)
        new = timed.duration
        cpu.append(time.process_time() - c0)
        if old <= 0.0:
            continue
        bound = lower_bound(path, vel, acc)
        fine = fine_duration(path, vel, acc)
        kind = "Cartesian" if q.cartesian else ("straight line" if plan.straight_line else "detour / search")
        sums[kind] += (old, new, bound, fine)
        ratios[kind].append(new / bound)
        fine_ratios[kind].append(new / fine)
        counts[kind] += 1
        blended += path.blended
        stops += path.stops
        stopped += len(timed.stops()) - 2
        if q.cartesian:
            offsets_old.append(tool_offset(planner, blend_corners(plan.path, 0.0).configurations(0.002)))
            offsets_new.append(tool_offset(planner, path.configurations(0.002)))
        if args.verbose:
            print(
                f"{q.label}: {len(plan.path)} waypoints, old {old:.2f} s, new {new:.2f} s, bound {bound:.2f}"
            )

    print(
        f"mission {mission.name}: {len(queries)} moves, {sum(counts.values())} timed, {skipped} not planned"
    )
    heads = ("old s", "new s", "bound s", "fine s")
    print(f"{'moves':<17}{'n':>4}" + "".join(f"{h:>9}" for h in heads) + "".join(f"{h:>10}" for h in RATIOS))
    total = np.zeros(4)
    for kind in kinds:
        if counts[kind]:
            total += sums[kind]
            print(_row(kind, counts[kind], sums[kind]))
    if total[0] > 0:
        print(_row("all", sum(counts.values()), total))
    for kind in kinds:
        if ratios[kind]:
            r = sorted(ratios[kind])
            f = sorted(fine_ratios[kind])
            print(
                f"  {kind}: per move new/bound median {statistics.median(r):.3f}, max {r[-1]:.3f};"
                f" new/fine median {statistics.median(f):.4f}, max {f[-1]:.4f}"
            )
    print(
        f"interior corners: {blended} blended, {stops} not (the arc collides, or a near reversal);"
        f" the arm stops at {stopped} (where stopping is faster than the arc, it stops)"
    )
    if offsets_new:
        print(
            f"Cartesian moves, tool's largest distance from its straight line: polyline"
            f" {max(offsets_old) * 1e3:.1f} mm, blended {max(offsets_new) * 1e3:.1f} mm"
        )
    if cpu:
        ms = sorted(c * 1e3 for c in cpu)
        print(
            "blending (arcs collision-checked) and timing, CPU per move:"
            f" median {statistics.median(ms):.1f} ms, max {ms[-1]:.1f} ms"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
