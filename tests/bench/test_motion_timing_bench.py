"""The motion timing benchmark runs and prints old, new, bound and fine durations side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tlt_ars.planning.blended_path import blend_corners

ROOT = Path(__file__).resolve().parents[2]
VEL = np.array([2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416])
ACC = np.array([4.0, 4.0, 6.0, 6.0, 6.0, 6.0])


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("motion_timing")


def test_bench_times_a_few_moves_of_a_one_bay_mission(bench, capsys):
    args = ["--mission", str(ROOT / "missions" / "one_bay.yaml"), "--limit", "8"]
    assert bench.main(args) == 0
    out = capsys.readouterr().out
    assert "8 moves" in out
    assert "new/old" in out and "new/bound" in out and "new/fine" in out
    all_row = next(line for line in out.splitlines() if line.startswith("all "))
    old, new, bound, fine = (float(v) for v in all_row.split()[2:6])
    assert bound <= new <= old and bound <= fine <= new * 1.01
    assert "tool's largest distance from its straight line" in out


def test_the_bound_is_exact_on_a_straight_line_and_below_the_timing_round_a_corner(bench):
    from tlt_ars.planning.time_parameterisation import straight_line_duration, time_parameterise

    line = [np.zeros(6), np.array([1.5, 0.5, -1.0, 0.0, 0.2, 0.0])]
    exact = straight_line_duration(line[0], line[1], VEL, ACC)
    assert bench.lower_bound(blend_corners(line, 0.1), VEL, ACC) == pytest.approx(exact, rel=1e-3)
    corner = [np.zeros(6), np.array([1.0, 0, 0, 0, 0, 0]), np.array([1.0, 1.0, 0, 0, 0, 0])]
    path = blend_corners(corner, 0.1)
    assert bench.lower_bound(path, VEL, ACC) < time_parameterise(path, VEL, ACC).duration


def test_no_timing_beats_the_bound_on_random_blended_paths(bench):
    from tlt_ars.planning.time_parameterisation import time_parameterise

    rng = np.random.default_rng(3)
    for _ in range(20):
        path = [rng.uniform(-2.0, 2.0, 6)]
        for _ in range(int(rng.integers(1, 5))):
            path.append(path[-1] + rng.normal(0.0, 0.5, 6))
        blended = blend_corners(path, float(rng.choice([0.02, 0.1, 0.3])))
        new = time_parameterise(blended, VEL, ACC).duration
        bound = bench.lower_bound(blended, VEL, ACC)
        assert bound <= new * (1 + 1e-9)
        assert bound >= 0.7 * new  # and it is not a trivial one
