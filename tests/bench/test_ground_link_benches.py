"""The ground-link benchmarks run end to end on a small load and report what they claim to."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load(name: str):
    spec = importlib.util.spec_from_file_location(f"{name}_bench", ROOT / "bench" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_ingest_bench_stores_everything(capsys):
    assert load("gsw_ingest").main(["--packets", "600", "--batch", "100"]) == 0
    out = capsys.readouterr().out
    assert "loss                       : 0 (packets stored 600/600" in out
    assert "ratio archive / raw" in out


def test_roundtrip_bench_gets_every_ack(capsys):
    assert load("ground_link_roundtrip").main(["--commands", "20", "--warmup", "2"]) == 0
    out = capsys.readouterr().out
    assert "commands: 20 measured after 2 warm-up, 0 without an accepted ack" in out
    assert "p50" in out and "p99" in out
