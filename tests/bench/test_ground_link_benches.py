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
    assert "authenticated    n=20 lost=0  p50 " in out  # both directions signed and verified
    assert "unauthenticated  n=20 lost=0  p50 " in out  # the same exchange without security
    assert "ratio authenticated / unauthenticated: p50 " in out
    assert "goal p50 <= 5 ms and p99 <= 20 ms, both directions authenticated" in out
