"""The token bucket that bounds rejection reports and log lines under a flood."""

from __future__ import annotations

from tlt_common.rate_limit import TokenBucket


def test_a_burst_then_the_rate_and_the_refused_are_counted():
    now = [0.0]
    bucket = TokenBucket(rate=2.0, burst=3.0, clock=lambda: now[0])
    assert [bucket.allow() for _ in range(5)] == [True, True, True, False, False]
    assert bucket.take_suppressed() == 2 and bucket.take_suppressed() == 0
    now[0] = 1.0  # two tokens back a second later, never more than the burst
    assert [bucket.allow() for _ in range(3)] == [True, True, False]
    now[0] = 100.0
    assert sum(bucket.allow() for _ in range(10)) == 3
