"""The behaviour-tree benchmark runs and its CRS-shaped tree really has the shape it claims."""

from __future__ import annotations

from pathlib import Path

import pytest
from py_trees.common import Status

from tlt_common.bt import status_codec as sc
from tlt_common.mission.schema import load_mission

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("bt_status")


def test_bench_runs_on_one_bay(bench, capsys):
    assert bench.main(["--mission", str(ROOT / "missions" / "one_bay.yaml"), "--repeat", "20"]) == 0
    out = capsys.readouterr().out
    assert "byte/node" in out and "ratio" in out


def test_identically_shaped_trees_and_mid_mission_state(bench):
    mission = load_mission(ROOT / "missions" / "two_bay.yaml")
    truth, running = bench.mid_mission_state(mission)
    ours = bench.crs_tree(mission, bench.make_leaves(True, truth, running))
    bare = bench.crs_tree(mission, bench.make_leaves(False, truth, running))
    ours_shape, bare_shape = sc.TreeShape.of(ours), sc.TreeShape.of(bare)
    assert [n.path for n in ours_shape.nodes] == [n.path for n in bare_shape.nodes]
    ours.tick_once()
    bare.tick_once()
    assert ours.status is Status.RUNNING
    assert ours_shape.statuses() == bare_shape.statuses()
    running_leaves = [
        n.name
        for n, s in zip(ours_shape.nodes, ours_shape.statuses(), strict=True)
        if s is Status.RUNNING and not n.kind.endswith(("sequence", "fallback"))
    ]
    assert running_leaves == ["Wait Add Member bay2/vertical/x0_y0"]
