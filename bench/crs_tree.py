"""Tick time of the real CRS tree of a 10-bay mission against bare py_trees behaviours in the same shape.

    python bench/crs_tree.py [--mission missions/ten_bay.yaml] [--ticks 2000]
                             [--readiness-period S] [--profile N]

The CRS tree is the one ``tlt-crs`` runs (``tlt_crs.tree.build_crs_tree``), on a real rclpy node,
with no driver, ARS or vision running: its ROS behaviours are idle or waiting for a server. Two
states are measured:

* ``start``: started, nothing built; bay 1 is indexed at start, so the tick waits on the cross
  frame request of bay 1 (Send ARS Request, no ARS server).
* ``mid``: bays 1-5 built in the tower model; the tick skips them (one condition each) and waits
  at the first step of bay 6's Raise Payload (an Active Grippers goal, no driver server).

The bare tree copies the shape node for node (Sequence/Selector with the same memory flags, a
PassThrough for each decorator) with leaves that return the status the real leaf returned, so both
trees walk the same nodes. They are ticked alternately in one run; the figure is the median over
blocks of ticks. Goals: ratio <= 1.2 and < 2 ms per tick. The same blocks are also timed in the
thread's CPU time, printed on a second line: on a loaded machine the wall time includes waiting for
a core, which hits the two trees' blocks unevenly.

A waiting behaviour asks rclpy whether its server is there at most every
``tlt_common.bt.server_readiness.READINESS_PERIOD_S`` seconds; ticked back to back here, that is
almost never. ``--readiness-period 0`` makes it ask on every tick, the cost it has in a node ticking
slower than the period. ``--profile N`` then prints where N ticks of the CRS tree spend their time.
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

import py_trees
import rclpy
from py_trees.common import Status

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from tlt_common.bt import server_readiness  # noqa: E402
from tlt_common.mission.tower_model import INSPECTED  # noqa: E402
from tlt_crs.config import Timeouts, load_config  # noqa: E402
from tlt_crs.node import build_node  # noqa: E402


class _Fixed(py_trees.behaviour.Behaviour):
    def __init__(self, name: str, status: Status) -> None:
        super().__init__(name)
        self.fixed = Status.FAILURE if status == Status.INVALID else status

    def update(self) -> Status:
        return self.fixed


def bare_copy(node: py_trees.behaviour.Behaviour) -> py_trees.behaviour.Behaviour:
    """Same shape and composite semantics, leaves answering the status the real leaf last had."""
    if isinstance(node, py_trees.composites.Selector):
        return py_trees.composites.Selector(node.name, node.memory, [bare_copy(c) for c in node.children])
    if isinstance(node, py_trees.composites.Sequence):
        return py_trees.composites.Sequence(node.name, node.memory, [bare_copy(c) for c in node.children])
    if isinstance(node, py_trees.decorators.Decorator):
        return py_trees.decorators.PassThrough(node.name, bare_copy(node.decorated))
    return _Fixed(node.name, node.status)


def tick(root: py_trees.behaviour.Behaviour, clock=None) -> None:
    """One tick as the CRS node does it (ROS time read once per tick for the real tree)."""
    if clock is not None:
        clock.begin_tick()
    for _ in root.tick():
        pass
    if clock is not None:
        clock.end_tick()


def visited(root: py_trees.behaviour.Behaviour) -> int:
    return sum(1 for n in root.iterate() if n.status != Status.INVALID)


def measure(
    real: py_trees.behaviour.Behaviour, bare: py_trees.behaviour.Behaviour, ticks: int, clock
) -> tuple:
    """Median ms per tick of each tree: (real, bare) in wall time, then (real, bare) in this thread's
    CPU time (the same blocks; CPU time leaves out the time the thread waited for a core)."""
    block = max(1, ticks // 20)
    real_ms, bare_ms, real_cpu, bare_cpu = [], [], [], []
    for _ in range(20):
        for root, out, cpu, root_clock in ((real, real_ms, real_cpu, clock), (bare, bare_ms, bare_cpu, None)):
            start, start_cpu = time.perf_counter(), time.thread_time()
            for _ in range(block):
                tick(root, root_clock)
            out.append((time.perf_counter() - start) / block * 1e3)
            cpu.append((time.thread_time() - start_cpu) / block * 1e3)
    return (
        statistics.median(real_ms),
        statistics.median(bare_ms),
        statistics.median(real_cpu),
        statistics.median(bare_cpu),
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mission", type=Path, default=REPO / "missions" / "ten_bay.yaml")
    parser.add_argument("--ticks", type=int, default=2000)
    parser.add_argument(
        "--readiness-period",
        type=float,
        default=server_readiness.READINESS_PERIOD_S,
        help="seconds a server's readiness answer is kept (0: rclpy is asked on every tick)",
    )
    parser.add_argument("--profile", type=int, default=0, metavar="N", help="profile N ticks of the CRS tree")
    args = parser.parse_args(argv)
    server_readiness.READINESS_PERIOD_S = args.readiness_period
    print(f"server readiness kept {args.readiness_period:g} s")
    rclpy.init()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for state in ("start", "mid"):
                py_trees.blackboard.Blackboard.clear()
                config = load_config(
                    REPO / "config" / "crs" / "crs.yaml",
                    mission=args.mission,
                    state_file=Path(tmp) / f"{state}.json",
                )
                # Waits never time out here: the measured tick is one that keeps waiting.
                never = {name: 1e9 for name in Timeouts.__dataclass_fields__}
                config = dataclasses.replace(config, timeouts=Timeouts(**never))
                node = build_node(config, node_name=f"crs_bench_{state}")
                model = node.ctx.model
                if state == "mid":
                    for bay in range(1, 6):
                        for m in node.ctx.mission.bay_members(bay):
                            model.override(m.id, INSPECTED)
                node.ctx.board.set("started", True)
                for _ in range(3):  # reach the steady state: waiting on a server that is not there
                    tick(node.root)
                assert node.ctx.fault == "", node.ctx.fault
                bare = bare_copy(node.root)
                tick(bare)
                total = sum(1 for _ in node.root.iterate())
                real_ms, bare_ms, real_cpu, bare_cpu = measure(node.root, bare, args.ticks, node.ctx.clock)
                print(
                    f"{state:5s}: {total} nodes, {visited(node.root)} visited per tick;"
                    f" CRS tree {real_ms:.3f} ms/tick, bare py_trees {bare_ms:.3f} ms/tick,"
                    f" ratio {real_ms / bare_ms:.2f} (goals: < 2 ms, <= 1.2)"
                )
                print(
                    f"       thread CPU time: CRS tree {real_cpu:.3f} ms/tick, bare py_trees {bare_cpu:.3f}"
                    f" ms/tick, ratio {real_cpu / bare_cpu:.2f}"
                )
                if args.profile > 0:
                    profile = cProfile.Profile()
                    profile.enable()
                    for _ in range(args.profile):
                        tick(node.root, node.ctx.clock)
                    profile.disable()
                    pstats.Stats(profile, stream=sys.stdout).sort_stats("tottime").print_stats(15)
                node.interrupt()
                node.destroy_node()
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
