"""The Dynamixel cycle benchmark runs end to end (figures printed, never asserted on speed)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("dynamixel_cycle")


def test_bench_prints_its_figures(bench, capsys):
    assert bench.main(["--seconds", "0.3", "--servos", "2"]) == 0
    out = capsys.readouterr().out
    for figure in ("achieved rate", "cycle time p50", "cycle time p99", "overruns", "retries"):
        assert figure in out
    assert "30 cycles" in out


def test_percentile(bench):
    values = [float(v) for v in range(1, 101)]
    assert bench.percentile(values, 0.99) == 99.0 and bench.percentile(values, 0.5) == 50.0
