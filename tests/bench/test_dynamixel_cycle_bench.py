"""The Dynamixel cycle benchmark runs end to end (figures printed, never asserted on speed)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load_bench():
    spec = importlib.util.spec_from_file_location(
        "dynamixel_cycle_bench", ROOT / "bench" / "dynamixel_cycle.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_prints_its_figures(capsys):
    bench = load_bench()
    assert bench.main(["--seconds", "0.3", "--servos", "2"]) == 0
    out = capsys.readouterr().out
    for figure in ("achieved rate", "cycle time p50", "cycle time p99", "overruns", "retries"):
        assert figure in out
    assert "30 cycles" in out


def test_percentile():
    bench = load_bench()
    values = [float(v) for v in range(1, 101)]
    assert bench.percentile(values, 0.99) == 99.0 and bench.percentile(values, 0.5) == 50.0
