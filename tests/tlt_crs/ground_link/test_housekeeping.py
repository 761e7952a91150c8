"""Housekeeping packets come due at their configured rates (fake clock, no sleeping)."""

from __future__ import annotations

import pytest

from tlt_common.ccsds.definitions import load_definitions
from tlt_crs.ground_link.housekeeping import HousekeepingSchedule

DEFS = load_definitions()


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_rates_from_definitions_and_overrides():
    clock = Clock()
    schedule = HousekeepingSchedule(DEFS, {"hk_lifter": 10.0, "hk_tower": 0}, clock=clock)
    assert "link_stats" not in schedule.periods and "hk_tower" not in schedule.periods
    assert schedule.periods["hk_lifter"] == pytest.approx(0.1)
    assert schedule.periods["hk_arm_joints"] == pytest.approx(1 / DEFS.packet("hk_arm_joints").rate_hz)
    assert set(schedule.due()) == set(schedule.periods)  # everything once at start
    counts = dict.fromkeys(schedule.periods, 0)
    for _ in range(1000):  # 10 s in 10 ms steps
        clock.now += 0.01
        for name in schedule.due():
            counts[name] += 1
    assert counts["hk_lifter"] == pytest.approx(100, abs=1)
    assert counts["hk_arm_joints"] == pytest.approx(50, abs=1)
    assert counts["hk_mission"] == pytest.approx(10, abs=1)


def test_late_caller_gets_one_packet_not_a_burst():
    clock = Clock()
    schedule = HousekeepingSchedule(DEFS, clock=clock)
    schedule.due()
    clock.now += 60.0
    assert schedule.due().count("hk_lifter") == 1
    assert "hk_lifter" not in schedule.due()
    assert schedule.next_due() > clock.now


def test_bad_overrides_are_refused():
    with pytest.raises(KeyError, match="no housekeeping packet"):
        HousekeepingSchedule(DEFS, {"hk_warp": 1.0})
    with pytest.raises(ValueError, match=">= 0"):
        HousekeepingSchedule(DEFS, {"hk_lifter": -1.0})
