"""Tick <-> joint unit conversion (rad and lead-screw metres)."""

from __future__ import annotations

import math

import pytest

from tlt_drivers.dynamixel.joint_scale import JointScale


def test_radians_with_gear_ratio_and_direction():
    scale = JointScale("rad", gear_ratio=2.0, zero_ticks=2048, direction=-1)
    assert scale.to_ticks(math.pi / 2) == 2048 - 2048  # a quarter joint turn is half a servo turn
    assert scale.from_ticks(0) == pytest.approx(math.pi / 2)


def test_metres_through_lead_screw():
    scale = JointScale("m", lead_m_per_rev=0.002, zero_ticks=100)
    assert scale.to_ticks(0.01) == 100 + 5 * 4096
    assert scale.from_ticks(100 + 4096) == pytest.approx(0.002)


def test_velocity_units_round_trip_and_round_up():
    scale = JointScale("rad")
    raw = scale.velocity_to_raw(1.0)  # 9.55 rpm / 0.229 = 41.7 -> 42
    assert raw == 42
    assert scale.velocity_from_raw(raw) == pytest.approx(42 * 0.229 * 2 * math.pi / 60)
    assert JointScale("rad", direction=-1).velocity_to_raw(1.0) == -42


def test_metres_need_a_lead():
    with pytest.raises(ValueError, match="lead_m_per_rev"):
        JointScale("m").to_ticks(0.1)
