"""The pacer holds sim time to the real-time factor of an (injected) wall clock, without bursts."""

from __future__ import annotations

import pytest
from tlt_sim.twin.pacing import Pacer


class FakeWall:
    def __init__(self) -> None:
        self.now = 100.0
        self.slept: list[float] = []

    def clock(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.slept.append(s)
        self.now += s


@pytest.mark.parametrize("rtf", [0.5, 1.0, 4.0])
def test_sim_time_runs_at_the_factor(rtf):
    wall = FakeWall()
    pacer = Pacer(rtf, clock=wall.clock, sleep=wall.sleep)
    pacer.rebase(0.0)
    t = 0.0
    for _ in range(500):
        t += 0.01
        wall.now += 0.001  # the step itself costs 1 ms
        pacer.wait(t)
    assert t / (wall.now - 100.0) == pytest.approx(rtf, rel=1e-6)


def test_zero_runs_as_fast_as_possible():
    wall = FakeWall()
    pacer = Pacer(0.0, clock=wall.clock, sleep=wall.sleep)
    for i in range(100):
        pacer.wait(i * 0.01)
    assert wall.slept == []


def test_a_minimum_sleep_yields_to_the_device_threads_at_any_factor():
    wall = FakeWall()
    pacer = Pacer(0.0, clock=wall.clock, sleep=wall.sleep, min_sleep_s=0.0005)
    for i in range(10):
        pacer.wait(i * 0.01)
    assert wall.slept == [0.0005] * 10
    behind = Pacer(1.0, clock=wall.clock, sleep=wall.sleep, min_sleep_s=0.0005)
    behind.rebase(0.0)
    wall.now += 1.0
    wall.slept.clear()
    behind.wait(0.01)  # far behind: no pacing sleep, but still the yield
    assert wall.slept == [0.0005]


def test_falling_behind_does_not_cause_a_burst_later():
    wall = FakeWall()
    pacer = Pacer(1.0, clock=wall.clock, sleep=wall.sleep, max_lag_s=0.2)
    pacer.rebase(0.0)
    wall.now += 5.0  # a 5 s stall
    pacer.wait(0.01)
    assert pacer.rebases == 1
    wall.slept.clear()
    pacer.wait(0.02)  # from here on it paces again, 10 ms per 10 ms
    assert wall.slept == [pytest.approx(0.01)]


def test_negative_factor_is_refused():
    with pytest.raises(ValueError, match="real-time factor"):
        Pacer(-1.0)
