"""Collision-free joint-space planning for one UR10e with OMPL (RRTConnect).

Reads a :class:`~tlt_ars.planning.collision_scene.CollisionScene` (the arm and its world, as they
stand when the request is made) and a start configuration; writes a :class:`Plan`: the waypoints
of a piecewise-linear joint path, each segment of which has been re-checked densely.

A request succeeds only with a path the arm may follow. The order of work:

1. The start and goal are checked against the joint limits and the scene; a start or goal in
   collision fails naming the colliding pair.
2. A Cartesian goal is turned into its IK solutions (nearest the start first). Solutions in
   collision are dropped; none left fails with the pose named.
3. If the joint-space straight line to a goal is free, it is the answer: no sampling.
4. Otherwise a few few-segment detours are tried (base first or last, arm raised straight up,
   arm folded, through home), then start -> via -> goal through each collision-free configured
   via configuration, then RRTConnect searches (to all collision-free IK solutions at once for a
   Cartesian goal) within the time limit.
5. Shortcuts are taken only where the dense check passes.
6. Every segment not already checked end to end at ``dense_check_resolution`` (finer than the
   planner's ``check_resolution``) is re-checked at it; a segment that fails is re-planned once at
   the dense resolution, and fails the request if that fails too. The arm never gets a path that
   was not checked.

Cartesian approaches (:meth:`Planner.plan_cartesian`) move the tool along a straight line
instead, through IK solutions that follow each other, with the same dense check.

:meth:`Planner.blended` turns a plan into the path the arm follows: its corners blended by arcs
within ``blend_deviation`` rad (``cartesian_blend_deviation`` for a Cartesian move, whose tool must
stay near its line), each arc checked at the dense resolution in the same scene
(``blended_path``).

Failures raise :class:`PlanningFailed` with ``kind`` (ik, start_collision, goal_collision,
limits, timeout, dense_check, collision, goal_rejected) and a reason a person can act on.

Kept as one module over 500 lines: one :class:`Planner` whose steps above share its scene, its
deadline and the set of segments already checked densely, each step a method in the order listed;
the time parameterisation that follows a plan is apart (``time_parameterisation``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from tlt_ars.planning.blended_path import BlendedPath, blend_corners
from tlt_ars.planning.collision_scene import CollisionScene
from tlt_common.geometry.transforms import describe_pose, pose_error
from tlt_common.geometry.ur10e import IkFailed, flange_batch

try:  # OMPL logs every solve at INFO on stdout; keep only its errors.
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LogLevel.LOG_ERROR)
except ImportError as exc:  # pragma: no cover - ompl is a declared dependency
    raise ImportError("tlt_ars.planning needs the 'ompl' package (OMPL 2 Python bindings)") from exc

# Searches for a segment the dense re-check found in collision, before the plan fails.
REPAIR_ATTEMPTS = 3


class PlanningFailed(RuntimeError):
    """A request that produced no checked path; ``kind`` classifies it, ``reason`` explains it."""

    def __init__(self, kind: str, reason: str) -> None:
        self.kind = kind
        self.reason = reason
        super().__init__(reason)


@dataclass
class Plan:
    """A checked piecewise-linear joint path from ``path[0]`` (the start) to ``path[-1]``."""

    path: list[np.ndarray]
    planning_time: float
    straight_line: bool
    checks: int = 0
    ik_solutions: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def goal(self) -> np.ndarray:
        return self.path[-1]


def _fmt(q: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in q) + "]"


class Planner:
    """Plans for the arm of ``scene``. Resolutions are the largest joint step (rad) between
    checked configurations; ``planning_time_s`` bounds the OMPL search of one request; ``home``
    is a via point of the detours; ``vias`` are joint configurations tried as start -> via -> goal
    after the detours; ``detours=False`` goes from the straight line to the search. The blend
    deviations (rad) bound how far :meth:`blended` cuts a plan's corners."""

    def __init__(
        self,
        scene: CollisionScene,
        *,
        check_resolution: float = 0.02,
        dense_check_resolution: float = 0.005,
        planning_time_s: float = 1.0,
        simplify_time_s: float = 0.1,
        max_ik_solutions: int = 8,
        home: Sequence[float] | None = None,
        repair_time_s: float = 0.2,
        detours: bool = True,
        vias: Sequence[Sequence[float]] = (),
        blend_deviation: float = 0.1,
        cartesian_blend_deviation: float = 0.005,
    ) -> None:
        if dense_check_resolution > check_resolution:
            raise ValueError("dense_check_resolution must not be coarser than check_resolution")
        self.scene = scene
        self.kin = scene.kin
        self.check_resolution = float(check_resolution)
        self.dense_check_resolution = float(dense_check_resolution)
        self.planning_time_s = float(planning_time_s)
        self.simplify_time_s = float(simplify_time_s)
        self.max_ik_solutions = int(max_ik_solutions)
        self.home = None if home is None else np.asarray(home, dtype=float)
        self.repair_time_s = float(repair_time_s)
        self.detours = bool(detours)
        self.vias = [np.asarray(v, dtype=float) for v in vias]
        self.blend_deviation = float(blend_deviation)
        self.cartesian_blend_deviation = float(cartesian_blend_deviation)
        for v in self.vias:
            if v.shape != (6,):
                raise ValueError(f"a via configuration must be six joint angles, got {v.tolist()!r}")

    @classmethod
    def from_config(
        cls, scene: CollisionScene, planning: dict, home: Sequence[float] | None = None
    ) -> Planner:
        """A planner with the ``planning`` section of the scene file."""
        return cls(
            scene,
            home=home,
            check_resolution=planning["check_resolution"],
            dense_check_resolution=planning["dense_check_resolution"],
            planning_time_s=planning["planning_time_s"],
            simplify_time_s=planning["simplify_time_s"],
            max_ik_solutions=planning["max_ik_solutions"],
            vias=planning.get("via_configurations", ()),
            blend_deviation=planning.get("blend_deviation", 0.1),
            cartesian_blend_deviation=planning.get("cartesian_blend_deviation", 0.005),
        )

    def blended(self, plan: Plan) -> BlendedPath:
        """The path the arm follows for ``plan``: its corners cut by arcs within the blend deviation
        (the Cartesian one for a Cartesian move), each arc free at the dense resolution in this
        planner's scene, else a stop at that corner."""
        deviation = self.cartesian_blend_deviation if "cartesian" in plan.notes else self.blend_deviation
        return blend_corners(
            plan.path,
            deviation,
            is_free=lambda q: not self.scene.in_collision(q),
            resolution=self.dense_check_resolution,
        )

    # ----- requests -----
    def plan_to_joints(
        self,
        start: Sequence[float],
        goal: Sequence[float],
        time_limit: float | None = None,
        *,
        any_turn: bool = False,
    ) -> Plan:
        """A checked path from ``start`` to the joint configuration ``goal``; with ``any_turn`` the
        goal's base joint may end a full turn away (same pose, e.g. "home" reached round a post)."""
        t0 = time.perf_counter()
        checks0 = self.scene.checks
        q_start = self._check_start(start)
        q_goal = self._as_config(goal, "goal")
        self._check_limits(q_goal, "goal")
        hit = self.scene.first_collision(q_goal)
        if hit is not None:
            raise PlanningFailed(
                "goal_collision", f"goal {_fmt(q_goal)} is in collision: {hit[0]} with {hit[1]}"
            )
        goals = [q_goal, *self.kin.turn_variants(q_goal)] if any_turn else [q_goal]
        plan = self._solve(q_start, goals, t0, time_limit)
        plan.checks = self.scene.checks - checks0
        return plan

    def plan_to_pose(
        self,
        start: Sequence[float],
        pose: np.ndarray,
        time_limit: float | None = None,
        *,
        accept: Callable[[np.ndarray], bool] | None = None,
    ) -> Plan:
        """A checked path from ``start`` to a configuration whose tool is at ``pose`` (world, 4x4).

        IK solutions are tried nearest the start first: the first whose straight line is free is
        taken; otherwise RRTConnect searches towards all collision-free solutions at once.
        ``accept`` further restricts the goal configurations (e.g. to those from which the
        Cartesian approach onto a part works); it is asked lazily, nearest first.
        """
        t0 = time.perf_counter()
        checks0 = self.scene.checks
        q_start = self._check_start(start)
        try:
            solutions = self.kin.inverse(pose, q_start)[: self.max_ik_solutions]
        except IkFailed as exc:
            raise PlanningFailed("ik", str(exc)) from exc
        free, hits = [], []
        for q in solutions:
            hit = self.scene.first_collision(q)
            if hit is None:
                free.append(q)
            else:
                hits.append(f"{hit[0]} with {hit[1]}")
        if not free:
            raise PlanningFailed(
                "goal_collision",
                f"every IK solution for pose {describe_pose(pose)} is in collision"
                f" ({'; '.join(sorted(set(hits)))})",
            )
        # The same solutions with the base joint a full turn away come last: they reach the pose by
        # turning the other way round, which is the only way past a post between arm and goal.
        variants = [v for q in free for v in self.kin.turn_variants(q)]
        variants.sort(key=lambda v: float(np.max(np.abs(v - q_start))))
        plan = self._solve(q_start, free + variants, t0, time_limit, accept)
        plan.ik_solutions = len(solutions)
        plan.checks = self.scene.checks - checks0
        return plan

    def plan_cartesian(
        self,
        start: Sequence[float],
        pose: np.ndarray,
        *,
        step: float = 0.02,
        tolerance: float = 0.002,
        max_joint_step: float = 0.3,
    ) -> Plan:
        """A checked path that moves the tool along the straight line from where it is at
        ``start`` to ``pose`` (position linear, orientation by the shortest rotation), as the
        approach onto a part or a joint.

        The line is cut every ``step`` m (or 0.05 rad of tool rotation); each cut gets the IK
        solution nearest the previous one. A jump of more than ``max_joint_step`` rad on any joint
        (a singularity or a change of branch) fails the request. Waypoints are then dropped where
        the joint-space line between their neighbours keeps the tool within ``tolerance`` m of the
        Cartesian line, and every remaining segment is densely checked.
        """
        t0 = time.perf_counter()
        checks0 = self.scene.checks
        q_start = self._check_start(start)
        pose = np.asarray(pose, dtype=float)
        try:
            self.kin.inverse(pose, q_start)  # an unreachable end fails at once, not after the walk
        except IkFailed as exc:
            raise PlanningFailed("ik", f"Cartesian path to {describe_pose(pose)}: {exc}") from exc
        t_start = self.kin.forward(q_start)
        dp, dr = pose_error(t_start, pose)
        n = max(1, int(np.ceil(max(dp / step, dr / 0.05))))
        line = [_interpolate_pose(t_start, pose, k / n) for k in range(n + 1)]
        qs = [q_start]
        for k in range(1, n + 1):
            try:
                q = self.kin.inverse(line[k], qs[-1])[0]
            except IkFailed as exc:
                raise PlanningFailed("ik", f"Cartesian path to {describe_pose(pose)}: {exc}") from exc
            jump = float(np.max(np.abs(q - qs[-1])))
            if jump > max_joint_step:
                raise PlanningFailed(
                    "ik",
                    f"Cartesian path to {describe_pose(pose)} jumps {jump:.3f} rad at"
                    f" {describe_pose(line[k])} (a singularity or an IK branch change)",
                )
            qs.append(q)
        keep = [0]
        for k in range(1, n + 1):
            if k == n or not self._follows_line(qs[keep[-1]], qs[k + 1], line[keep[-1] : k + 2], tolerance):
                keep.append(k)
        path = [qs[k] for k in keep]
        for a, b in pairwise(path):
            bad = self.scene.segment_collision(a, b, self.dense_check_resolution)
            if bad is not None:
                hit = self.scene.first_collision(bad)
                what = f"{hit[0]} with {hit[1]}" if hit else "a collision"
                raise PlanningFailed(
                    "collision", f"Cartesian path to {describe_pose(pose)} touches {what} at {_fmt(bad)}"
                )
        return Plan(path, time.perf_counter() - t0, False, self.scene.checks - checks0, notes=["cartesian"])

    def _follows_line(self, qa: np.ndarray, qb: np.ndarray, line: list[np.ndarray], tolerance: float) -> bool:
        """Whether the joint-space line qa..qb keeps the tool within ``tolerance`` of ``line``."""
        m = len(line) - 1
        if m < 2:
            return True
        u = np.arange(1, m)[:, None] / m
        flanges = flange_batch(qa + (qb - qa) * u)
        tools = np.einsum("ij,njk,kl->nil", self.kin.base, flanges, self.kin.tool)
        wanted = np.array([p[:3, 3] for p in line[1:m]])
        return bool(np.all(np.linalg.norm(tools[:, :3, 3] - wanted, axis=1) <= tolerance))

    # ----- checks -----
    def _as_config(self, q: Sequence[float], what: str) -> np.ndarray:
        arr = np.asarray(q, dtype=float)
        if arr.shape != (6,) or not np.all(np.isfinite(arr)):
            raise PlanningFailed("limits", f"{what} must be six finite joint angles, got {q!r}")
        return arr

    def _check_limits(self, q: np.ndarray, what: str) -> None:
        bad = [i for i in range(6) if not self.kin.lower[i] <= q[i] <= self.kin.upper[i]]
        if bad:
            i = bad[0]
            raise PlanningFailed(
                "limits",
                f"{what} joint {i + 1} at {q[i]:.4f} rad is outside"
                f" [{self.kin.lower[i]:.4f}, {self.kin.upper[i]:.4f}]",
            )

    def _check_start(self, start: Sequence[float]) -> np.ndarray:
        q = self._as_config(start, "start")
        self._check_limits(q, "start")
        hit = self.scene.first_collision(q)
        if hit is not None:
            raise PlanningFailed(
                "start_collision", f"start {_fmt(q)} is in collision: {hit[0]} with {hit[1]}"
            )
        return q

    # ----- search -----
    def _free(self, path: list[np.ndarray], verified: set[bytes] | None = None) -> bool:
        """Every segment free: all at four times the planner's resolution, then all at its
        resolution (cheap rejections: a detour whose second segment collides is rejected before
        its first is checked finely), then all at the dense resolution. Segments found free are
        added to ``verified``."""
        pairs = list(pairwise(path))
        for resolution in (4 * self.check_resolution, self.check_resolution, self.dense_check_resolution):
            if not all(self.scene.segment_free(a, b, resolution) for a, b in pairs):
                return False
        if verified is not None:
            verified.update(_segment_key(a, b) for a, b in pairs)
        return True

    def _detours(self, start: np.ndarray, goal: np.ndarray) -> list[tuple[str, list[np.ndarray]]]:
        """Few-segment paths a pick-and-place arm usually takes: turn the base first or last;
        raise the arm straight up, turn, lower; fold the arm (shoulder, elbow, wrist 1 to home),
        turn, unfold; through home."""
        out = []
        pan_first = start.copy()
        pan_first[0] = goal[0]
        pan_last = goal.copy()
        pan_last[0] = start[0]
        out.append([start, pan_first, goal])
        out.append([start, pan_last, goal])
        # Arm straight up (shoulder, elbow and wrist 1 in line): the links stay near the base axis,
        # so the base can turn past an obstacle standing close to the arm (a lifter post).
        up_start = start.copy()
        up_start[1:4] = (-math.pi / 2, 0.0, -math.pi / 2)
        up_goal = goal.copy()
        up_goal[1:4] = up_start[1:4]
        out.append([start, up_start, up_goal, goal])
        if self.home is not None:
            fold_start = start.copy()
            fold_start[1:4] = self.home[1:4]
            fold_goal = goal.copy()
            fold_goal[1:4] = self.home[1:4]
            out.append([start, fold_start, fold_goal, goal])
            out.append([start, self.home, goal])
        return [("detour", _drop_duplicates(p)) for p in out if all(self._within_limits(q) for q in p)]

    def _within_limits(self, q: np.ndarray) -> bool:
        return bool(np.all(q >= self.kin.lower) and np.all(q <= self.kin.upper))

    def _solve(
        self,
        start: np.ndarray,
        goals: list[np.ndarray],
        t0: float,
        time_limit: float | None,
        accept: Callable[[np.ndarray], bool] | None = None,
    ) -> Plan:
        limit = self.planning_time_s if time_limit is None else float(time_limit)
        verdicts: dict[bytes, bool] = {}

        def ok(goal: np.ndarray) -> bool:
            if accept is None:
                return True
            key = np.round(goal, 9).tobytes()
            if key not in verdicts:
                verdicts[key] = bool(accept(goal))
            return verdicts[key]

        for goal in goals:
            if self._free([start, goal]) and ok(goal):
                return Plan([start, goal], time.perf_counter() - t0, True)
        goals = [g for g in goals if ok(g)]
        if not goals:
            raise PlanningFailed("goal_rejected", "no collision-free goal configuration is acceptable")
        deadline = t0 + limit
        # Segments checked end to end at the dense resolution: the shortcuts keep them, and the
        # final re-check skips them.
        verified: set[bytes] = set()
        # Detours and via configurations get a quarter of the time; the search keeps the rest.
        detour_until = t0 + 0.25 * limit
        vias = [v for v in self.vias if self._within_limits(v) and not self.scene.in_collision(v)]
        for goal in goals[:4] if self.detours else []:
            for note, path in self._detours(start, goal) + self._via_paths(start, goal, vias):
                if time.perf_counter() > detour_until:
                    break
                if self._free(path, verified):
                    return self._finish(path, verified, t0, deadline, note)
        raw = self._rrt(start, goals, deadline - time.perf_counter(), self.check_resolution)
        return self._finish(raw, verified, t0, deadline, "rrt")

    def _finish(self, path: list[np.ndarray], verified: set[bytes], t0: float, deadline: float,
                note: str) -> Plan:  # fmt: skip
        """Shorten a path, then densely re-check every segment not already checked end to end
        (the search's own segments, and the pieces a shortcut leaves of a segment)."""
        path = self._shortcut(path, time.perf_counter() + self.simplify_time_s, verified)
        path = self._dense_recheck(path, deadline, verified)
        return Plan(path, time.perf_counter() - t0, False, notes=[note])

    def _via_paths(
        self, start: np.ndarray, goal: np.ndarray, vias: list[np.ndarray]
    ) -> list[tuple[str, list[np.ndarray]]]:
        """start -> via -> goal through each collision-free via configuration, shortest first."""

        def length(v: np.ndarray) -> float:
            return float(np.max(np.abs(v - start)) + np.max(np.abs(goal - v)))

        return [("via", [start, v, goal]) for v in sorted(vias, key=length)]

    def _shortcut(self, path: list[np.ndarray], until: float, verified: set[bytes]) -> list[np.ndarray]:
        """Shorten a path, accepting only densely checked shortcuts (added to ``verified``): first
        the farthest free waypoint from each one, then random shortcuts between points on the path
        until ``until``. Segments of ``path`` it keeps are not checked here."""
        dense = self.dense_check_resolution
        out = [path[0]]
        i = 0
        while i < len(path) - 1:
            # Farthest waypoint reachable in a straight line (coarse check first: a cheap rejection).
            j = len(path) - 1
            while j > i + 1 and not self._free([path[i], path[j]], verified):
                j -= 1
            out.append(path[j])
            i = j
        path = out
        rng = np.random.default_rng(len(path))
        tries = 0
        while len(path) > 2 and time.perf_counter() < until and tries < 30:
            tries += 1
            lengths = np.array([np.max(np.abs(b - a)) for a, b in pairwise(path)])
            cum = np.concatenate([[0.0], np.cumsum(lengths)])
            u, v = sorted(rng.uniform(0.0, cum[-1], 2))
            ku = int(np.searchsorted(cum, u, side="right") - 1)
            kv = int(np.searchsorted(cum, v, side="right") - 1)
            if ku == kv:
                continue
            pu = path[ku] + (path[ku + 1] - path[ku]) * ((u - cum[ku]) / lengths[ku])
            pv = path[kv] + (path[kv + 1] - path[kv]) * ((v - cum[kv]) / lengths[kv])
            old = cum[kv] - u + (v - cum[kv])
            if np.max(np.abs(pv - pu)) >= old - 1e-6:
                continue
            if self.scene.segment_free(pu, pv, dense):
                verified.add(_segment_key(pu, pv))
                path = [*path[: ku + 1], pu, pv, *path[kv + 1 :]]
                path = _drop_duplicates(path)
        return path

    def _rrt(
        self, start: np.ndarray, goals: list[np.ndarray], budget: float, resolution: float
    ) -> list[np.ndarray]:
        if budget <= 0:
            raise PlanningFailed(
                "timeout",
                "no path within the time limit: it ran out before the search (goals, detours, vias)",
            )
        space = ob.RealVectorStateSpace(6)
        bounds = ob.RealVectorBounds(6)
        for i in range(6):
            bounds.setLow(i, float(self.kin.lower[i]))
            bounds.setHigh(i, float(self.kin.upper[i]))
        space.setBounds(bounds)
        ss = og.SimpleSetup(space)
        scene = self.scene
        buf = np.empty(6)

        def valid(state) -> bool:
            for i in range(6):
                buf[i] = state[i]
            return not scene.in_collision(buf)

        ss.setStateValidityChecker(valid)
        si = ss.getSpaceInformation()
        # OMPL's resolution is a fraction of the space extent, measured in the L2 metric; an L2 step
        # of `resolution` bounds every joint's step by it too.
        si.setStateValidityCheckingResolution(resolution / space.getMaximumExtent())
        s = space.allocState()
        for i in range(6):
            s[i] = float(start[i])
        ss.setStartState(s)
        goal_states = ob.GoalStates(si)
        for g in goals:
            gs = space.allocState()
            for i in range(6):
                gs[i] = float(g[i])
            goal_states.addState(gs)
        ss.setGoal(goal_states)
        planner = og.RRTConnect(si)
        # A step of a quarter turn in joint space: long enough to cross the workspace in few
        # extensions, short enough that most extensions are free.
        planner.setRange(1.5)
        ss.setPlanner(planner)
        t_search = time.perf_counter()
        status = ss.solve(budget)
        if not ss.haveExactSolutionPath():
            spent = time.perf_counter() - t_search
            raise PlanningFailed(
                "timeout",
                f"no path within {budget:.3f} s from {_fmt(start)} to {len(goals)} goal configuration(s)"
                f" (searched {spent:.3f} s, OMPL: {status})",
            )
        p = ss.getSolutionPath()
        path = []
        for k in range(p.getStateCount()):
            st = p.getState(k)
            path.append(np.array([st[i] for i in range(6)]))
        path[0] = start.copy()
        return _drop_duplicates(path)

    def _dense_recheck(
        self, path: list[np.ndarray], deadline: float, verified: set[bytes]
    ) -> list[np.ndarray]:
        """Re-check every segment not in ``verified`` at the dense resolution; re-plan a failing
        one at that resolution (with what is left of the time, and at least ``repair_time_s``)."""
        out = [path[0]]
        for a, b in pairwise(path):
            if _segment_key(a, b) in verified:
                out.append(b)
                continue
            bad = self.scene.segment_collision(a, b, self.dense_check_resolution)
            if bad is None:
                out.append(b)
                continue
            out.extend(self._repaired(a, b, bad, deadline)[1:])
        return out

    def _repaired(self, a: np.ndarray, b: np.ndarray, bad: np.ndarray, deadline: float) -> list[np.ndarray]:
        """A path from ``a`` to ``b`` planned at the dense resolution whose every segment passes the
        dense re-check. OMPL checks a motion at points an L2 step apart, the re-check at points a
        joint step apart: a thin contact one set of points misses the other may find (a test's
        repair failed so, about one plan in a thousand), and another search, randomised, goes
        elsewhere. ``REPAIR_ATTEMPTS`` searches, each with what is left of the time (at least
        ``repair_time_s``)."""
        failed = ""
        for _ in range(REPAIR_ATTEMPTS):
            budget = max(deadline - time.perf_counter(), self.repair_time_s)
            try:
                repair = self._rrt(a, [b], budget, self.dense_check_resolution)
            except PlanningFailed as exc:
                hit = self.scene.first_collision(bad)
                what = f"{hit[0]} with {hit[1]}" if hit else "a collision"
                raise PlanningFailed(
                    "dense_check",
                    f"segment {_fmt(a)} -> {_fmt(b)} touches {what} at {_fmt(bad)} when re-checked at"
                    f" {self.dense_check_resolution} rad, and re-planning it failed: {exc.reason}",
                ) from exc
            failed = next(
                (
                    f"re-planned segment {_fmt(x)} -> {_fmt(y)} fails the dense re-check"
                    for x, y in pairwise(repair)
                    if self.scene.segment_collision(x, y, self.dense_check_resolution) is not None
                ),
                "",
            )
            if not failed:
                return repair
        raise PlanningFailed("dense_check", f"{failed} ({REPAIR_ATTEMPTS} searches)")


def _interpolate_pose(a: np.ndarray, b: np.ndarray, u: float) -> np.ndarray:
    """Pose a fraction ``u`` of the way from ``a`` to ``b`` (linear position, geodesic rotation)."""
    r = a[:3, :3].T @ b[:3, :3]
    angle = math.atan2(
        math.hypot(r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]) / 2.0, (np.trace(r) - 1.0) / 2.0
    )
    out = np.eye(4)
    out[:3, 3] = a[:3, 3] + (b[:3, 3] - a[:3, 3]) * u
    if angle < 1e-12:
        out[:3, :3] = a[:3, :3]
        return out
    if math.pi - angle < 1e-6:
        # Half a turn: the axis is the eigenvector of r for eigenvalue 1.
        w, v = np.linalg.eig(r)
        axis = np.real(v[:, np.argmin(np.abs(w - 1.0))])
    else:
        axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2 * math.sin(angle))
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    th = angle * u
    rot = np.eye(3) + math.sin(th) * k + (1 - math.cos(th)) * (k @ k)
    out[:3, :3] = a[:3, :3] @ rot
    return out


def _segment_key(a: np.ndarray, b: np.ndarray) -> bytes:
    """Identifies the segment a -> b exactly (the same end points, bit for bit)."""
    return np.asarray(a, dtype=float).tobytes() + np.asarray(b, dtype=float).tobytes()


def _drop_duplicates(path: list[np.ndarray]) -> list[np.ndarray]:
    out = [path[0]]
    for q in path[1:]:
        if np.max(np.abs(q - out[-1])) > 1e-9:
            out.append(q)
    if len(out) == 1:
        out.append(path[-1])
    return out


__all__ = ["Plan", "Planner", "PlanningFailed"]
