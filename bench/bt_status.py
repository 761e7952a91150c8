"""Behaviour-tree core figures: status size, encode+decode time, tick time of our node types.

Builds a tree of the CRS's shape for a mission (paper Fig. 13 with the subtrees of Figs. 18-27:
Raise Payload, Lower Lifter, Build Bay with Add Cross Frame / Inspection Check / Far and Near
Verticals / Diagonals, Test Bay, Add Foundation Rivets), once with the project's Action and
Condition node types as leaves and once with bare py_trees behaviours in an identically shaped
tree, and measures both in the same run, interleaved.

Two tick figures are given: a mid-mission tick (bays before the current one done, one ARS request
RUNNING: what the CRS ticks in operation; the goal applies to it) and a worst-case tick in which
every condition is false and every node is visited.

    python bench/bt_status.py [--mission missions/ten_bay.yaml] [--repeat 300]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import py_trees
from py_trees.common import Status

from tlt_common.bt import status_codec as sc
from tlt_common.bt.nodes import Action, Condition
from tlt_common.mission.schema import Member, Mission, load_mission

GROOT2_BYTES_PER_NODE = 3.0
ROOT = Path(__file__).resolve().parents[1]


class BenchCondition(Condition):
    def __init__(self, name: str, truth: set[str]) -> None:
        super().__init__(name)
        self.truth = truth

    def evaluate(self) -> bool:
        return self.name in self.truth


class BenchAction(Action):
    def __init__(self, name: str, running: set[str]) -> None:
        super().__init__(name)
        self.running = running

    def update(self) -> Status:
        return Status.RUNNING if self.name in self.running else Status.SUCCESS


class BareCondition(py_trees.behaviour.Behaviour):
    def __init__(self, name: str, truth: set[str]) -> None:
        super().__init__(name)
        self.truth = truth

    def update(self) -> Status:
        return Status.SUCCESS if self.name in self.truth else Status.FAILURE


class BareAction(py_trees.behaviour.Behaviour):
    def __init__(self, name: str, running: set[str]) -> None:
        super().__init__(name)
        self.running = running

    def update(self) -> Status:
        return Status.RUNNING if self.name in self.running else Status.SUCCESS


Leaf = Callable[[str, str], py_trees.behaviour.Behaviour]  # (kind, name) -> leaf


def seq(name: str, children: list) -> py_trees.composites.Sequence:
    return py_trees.composites.Sequence(name, memory=False, children=children)


def fallback(name: str, children: list) -> py_trees.composites.Selector:
    return py_trees.composites.Selector(name, memory=False, children=children)


def ensure(leaf: Leaf, condition: str, action: str) -> py_trees.composites.Selector:
    """Fallback(condition, action): the usual "make it true" pattern of Figs. 18-27."""
    return fallback(f"{condition}?", [leaf("condition", condition), leaf("action", action)])


def inspection_check(leaf: Leaf, tag: str) -> py_trees.composites.Sequence:  # Fig. 22
    return seq(
        f"Inspection Check {tag}",
        [leaf("action", f"Request Inspection {tag}"), leaf("action", f"Forward Inspection {tag}")],
    )


def member_subtree(leaf: Leaf, m: Member) -> py_trees.behaviour.Behaviour:
    done = leaf("condition", f"{m.id} done")
    if m.kind == "cross_frame":  # Fig. 21
        work = seq(
            f"Add Cross Frame {m.id}",
            [
                leaf("action", f"Send Add Cross Frame {m.id}"),
                inspection_check(leaf, m.id),
                leaf("action", f"Wait Add Cross Frame {m.id}"),
                ensure(leaf, f"active engaged {m.id}", f"Engage Active Grippers {m.id}"),
            ],
        )
    elif m.group in ("far_vertical", "near_vertical"):  # Figs. 23, 24
        work = seq(
            f"Add Vertical {m.id}",
            [
                leaf("action", f"Send Add Member {m.id}"),
                inspection_check(leaf, m.id),
                leaf("action", f"Wait Add Member {m.id}"),
                leaf("action", f"Send Affix Member {m.id}"),
                leaf("action", f"Wait Affix Member {m.id}"),
            ],
        )
    else:  # Fig. 25
        work = seq(
            f"Add Diagonal {m.id}",
            [
                leaf("action", f"Send Add Member {m.id}"),
                inspection_check(leaf, m.id),
                leaf("action", f"Wait Add Member {m.id}"),
            ],
        )
    return fallback(f"{m.id}?", [done, work])


def lifter_steps(leaf: Leaf, name: str, steps: list[tuple[str, str]]) -> py_trees.composites.Sequence:
    return seq(name, [ensure(leaf, c, a) for c, a in steps])


def crs_tree(mission: Mission, leaf: Leaf) -> py_trees.behaviour.Behaviour:
    bays = []
    for bay in range(1, mission.bay_count + 1):
        members = mission.bay_members(bay)
        groups = {}
        for m in members:
            groups.setdefault(m.group, []).append(member_subtree(leaf, m))
        build_bay = seq(  # Fig. 20
            f"Build Bay {bay}",
            [
                seq(f"Cross Frame {bay}", groups["cross_frame"]),
                seq(f"Far Verticals {bay}", groups["far_vertical"]),
                seq(f"Near Verticals {bay}", groups["near_vertical"]),
                seq(f"Diagonals {bay}", groups["diagonal"]),
            ],
        )
        raise_payload = lifter_steps(  # Fig. 18
            leaf,
            f"Raise Payload {bay}",
            [
                (f"active engaged r{bay}", f"Engage Active r{bay}"),
                (f"top disengaged r{bay}", f"Disengage Top r{bay}"),
                (f"lifter crs control r{bay}", f"Lifter CRS Control r{bay}"),
                (f"lifter raised r{bay}", f"Raise Lifter r{bay}"),
            ],
        )
        lower = lifter_steps(  # Fig. 19
            leaf,
            f"Lower Lifter {bay}",
            [
                (f"top engaged l{bay}", f"Engage Top l{bay}"),
                (f"active disengaged l{bay}", f"Disengage Active l{bay}"),
                (f"lifter crs control l{bay}", f"Lifter CRS Control l{bay}"),
                (f"lifter lowered l{bay}", f"Lower Lifter l{bay}"),
            ],
        )
        test_bay = lifter_steps(  # Fig. 26
            leaf,
            f"Test Bay {bay}",
            [
                (f"top engaged t{bay}", f"Engage Top t{bay}"),
                (f"active engaged t{bay}", f"Engage Active t{bay}"),
                (f"lifter crs control t{bay}", f"Lifter CRS Control t{bay}"),
                (f"compressed t{bay}", f"Compression Test t{bay}"),
                (f"cameras inward t{bay}", f"Rotate Cameras In t{bay}"),
                (f"bay inspected t{bay}", f"Inspect Bay t{bay}"),
                (f"cameras outward t{bay}", f"Rotate Cameras Out t{bay}"),
            ],
        )
        bays.append(
            fallback(
                f"Bay {bay}?",
                [
                    leaf("condition", f"bay {bay} built"),
                    seq(f"Bay {bay}", [raise_payload, lower, build_bay, test_bay]),
                ],
            )
        )
    rivets = [  # Fig. 27
        fallback(
            f"{m.id}?",
            [
                leaf("condition", f"{m.id} done"),
                seq(
                    f"Rivet {m.id}",
                    [
                        leaf("action", f"Send Foundation Rivet {m.id}"),
                        leaf("action", f"Wait Foundation Rivet {m.id}"),
                    ],
                ),
            ],
        )
        for m in mission.members
        if m.kind == "foundation_rivet"
    ]
    build_tower = fallback(
        "Build Tower?",
        [leaf("condition", "tower_built"), seq("Build Tower", [*bays, seq("Add Foundation Rivets", rivets)])],
    )
    return seq(  # Fig. 13
        "CRS",
        [
            leaf("action", "Initialise Blackboard"),
            fallback(
                "Ground Command?", [leaf("condition", "no ground command"), leaf("action", "Process Command")]
            ),
            fallback("Fault?", [leaf("condition", "no fault"), leaf("action", "Wait For Help")]),
            leaf("condition", "started"),
            build_tower,
        ],
    )


def mid_mission_state(mission: Mission) -> tuple[set[str], set[str]]:
    """Conditions true and actions running when half the bays are built and one vertical is being added."""
    current = mission.bay_count // 2 + 1
    truth = {"no ground command", "no fault", "started"} | {f"bay {b} built" for b in range(1, current)}
    for prefix in ("r", "l"):
        truth |= {
            f"{c} {prefix}{current}"
            for c in (
                "active engaged",
                "top disengaged",
                "top engaged",
                "active disengaged",
                "lifter crs control",
            )
        }
        truth |= {f"lifter raised {prefix}{current}", f"lifter lowered {prefix}{current}"}
    members = mission.bay_members(current)
    busy = next(m for m in members if m.group == "near_vertical")
    truth |= {f"{m.id} done" for m in members[: members.index(busy)]}
    return truth, {f"Wait Add Member {busy.id}"}


def make_leaves(ours: bool, truth: set[str], running: set[str]) -> Leaf:
    condition, action = (BenchCondition, BenchAction) if ours else (BareCondition, BareAction)

    def leaf(kind: str, name: str) -> py_trees.behaviour.Behaviour:
        return condition(name, truth) if kind == "condition" else action(name, running)

    return leaf


def time_ticks(root: py_trees.behaviour.Behaviour, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        start = time.perf_counter()
        root.tick_once()
        out.append(time.perf_counter() - start)
    return out


def compare_ticks(
    mission: Mission, truth: set[str], running: set[str], repeat: int
) -> tuple[float, float, int]:
    """Median tick (s) of our tree and the bare tree, interleaved in rounds; and visited node count."""
    ours = crs_tree(mission, make_leaves(True, truth, running))
    bare = crs_tree(mission, make_leaves(False, truth, running))
    assert sc.TreeShape.of(ours).hash != 0 and len(sc.TreeShape.of(ours)) == len(sc.TreeShape.of(bare))
    ours_t: list[float] = []
    bare_t: list[float] = []
    rounds = 10
    for _ in range(rounds):
        ours_t += time_ticks(ours, repeat // rounds)
        bare_t += time_ticks(bare, repeat // rounds)
    visited = sum(1 for b in sc.TreeShape.of(ours).behaviours if b.status is not Status.INVALID)
    return statistics.median(ours_t), statistics.median(bare_t), visited


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mission", type=Path, default=ROOT / "missions" / "ten_bay.yaml")
    parser.add_argument("--repeat", type=int, default=300)
    parser.add_argument("--max-status-bytes", type=int, default=sc.DEFAULT_MAX_STATUS_BYTES)
    args = parser.parse_args(argv)
    mission = load_mission(args.mission)
    py_trees.logging.level = py_trees.logging.Level.WARN

    truth, running = mid_mission_state(mission)
    root = crs_tree(mission, make_leaves(True, truth, running))
    root.tick_once()
    shape = sc.TreeShape.of(root)
    n = len(shape)
    parts = sc.encode_bytes(shape, agent="crs", tick_count=123456, max_status_bytes=args.max_status_bytes)
    total = sum(len(p) for p in parts)
    header = sc.HEADER_BYTES + len("crs")
    print(f"mission {mission.name}: {mission.bay_count} bays, CRS-shaped tree of {n} nodes")
    print(f"status size: {total} bytes in {len(parts)} part(s) of <= {args.max_status_bytes} status bytes")
    print(
        f"  = {(total - len(parts) * header) / n:.3f} byte/node + {header} bytes header per part"
        f" ({total / n:.3f} byte/node all in)"
    )
    print(
        f"  Groot2 monitor format: {GROOT2_BYTES_PER_NODE:.0f} bytes/node"
        f" = {GROOT2_BYTES_PER_NODE * n:.0f} bytes"
        f" ({GROOT2_BYTES_PER_NODE * n / total:.1f}x larger)  goal <= 0.25 byte/node + header:"
        f" {'met' if total <= -(-n // 4) + len(parts) * header else 'NOT met'}"
    )

    reps = max(50, args.repeat)
    start = time.perf_counter()
    for i in range(reps):
        encoded = sc.encode_bytes(shape, agent="crs", tick_count=i, max_status_bytes=args.max_status_bytes)
        decoded = sc.decode(encoded, shape)
    per = (time.perf_counter() - start) / reps
    assert [s for _, s in decoded.nodes] == shape.statuses()
    print(f"encode+decode (to bytes and back, {n} nodes): {per * 1e3:.3f} ms")
    start = time.perf_counter()
    sc.TreeShape.of(root)
    print(f"tree shape + hash (once per tree definition): {(time.perf_counter() - start) * 1e3:.3f} ms")

    for label, (t, r) in (
        ("mid-mission tick", (truth, running)),
        ("worst-case tick (every node visited)", ({"no ground command", "no fault", "started"}, set())),
    ):
        ours, bare, visited = compare_ticks(mission, t, r, args.repeat)
        ratio = ours / bare
        goal = ""
        if label.startswith("mid"):
            verdict = "met" if ratio <= 1.2 and ours < 2e-3 else "NOT met"
            goal = f"  goal ratio <= 1.2 and < 2 ms: {verdict}"
        print(
            f"{label}: {visited} of {n} nodes ticked; Action/Condition {ours * 1e3:.3f} ms,"
            f" bare py_trees {bare * 1e3:.3f} ms, ratio {ratio:.2f}{goal}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
