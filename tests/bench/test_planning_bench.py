"""The motion-planning benchmark runs and prints the figures it promises."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("planning")


def test_bench_runs_a_few_queries_of_a_one_bay_mission(bench, capsys):
    args = ["--mission", str(ROOT / "missions" / "one_bay.yaml"), "--limit", "8", "--no-collision-compare"]
    assert bench.main(args) == 0
    out = capsys.readouterr().out
    assert "8 queries" in out
    assert "planning time: median" in out and "p95" in out
    assert "success over feasible queries" in out
    assert "duration ratio vs time-optimal straight line" in out


def expected_queries(mission) -> int:
    """8 moves per member, 4 per affix rivet and per foundation rivet (bench/planning.py)."""
    n = 0
    for m in mission.members:
        if m.kind == "foundation_rivet":
            n += 4
        else:
            n += 8 + 4 * sum(r.step == "affix" for r in m.rivets)
    return n


def test_query_set_covers_every_member_and_a_three_bay_mission_has_at_least_100(bench):
    from tlt_ars.planning.world import load_scene_config
    from tlt_common.mission import generate
    from tlt_common.mission.schema import load_mission, parse_mission

    one = load_mission(ROOT / "missions" / "one_bay.yaml")
    queries = bench.build_queries(load_scene_config(), one, resolve=False)
    assert len(queries) == expected_queries(one)
    labels = " ".join(q.label for q in queries)
    assert "dispenser approach" in labels and "inspection" in labels and "place" in labels
    assert expected_queries(parse_mission(generate.build("three", 3), "<three>")) >= 100
