"""The ground-link benchmarks run end to end on a small load and report what they claim to."""

from __future__ import annotations


def test_ingest_bench_stores_everything(load_bench, capsys):
    assert load_bench("gsw_ingest").main(["--packets", "600", "--batch", "100"]) == 0
    out = capsys.readouterr().out
    assert "loss                       : 0 (packets stored 600/600" in out
    assert "with TM auth off 0" in out  # the unauthenticated run stored everything too
    assert "ratio archive / raw" in out and "ratio TM auth on / off" in out


def test_roundtrip_bench_gets_every_ack(load_bench, capsys):
    assert load_bench("ground_link_roundtrip").main(["--commands", "20", "--warmup", "2"]) == 0
    out = capsys.readouterr().out
    assert "commands: 20 measured after 2 warm-up, 0 without an accepted ack" in out
    assert "p50" in out and "p99" in out
