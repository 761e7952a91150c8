"""Conversion between servo ticks and joint units (rad, or m through a lead screw)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from tlt_drivers.dynamixel.control_table import TICKS_PER_REV, VELOCITY_UNIT_RPM


@dataclass
class JointScale:
    """``ticks = zero_ticks + direction * value * ticks_per_unit``.

    ``gear_ratio`` is servo turns per joint turn (unit ``rad``) or per lead-screw turn (unit ``m``,
    with ``lead_m_per_rev`` of travel per lead-screw turn). ``zero_ticks`` is where the joint reads
    0; the end-effector calibration moves it.
    """

    unit: str
    gear_ratio: float = 1.0
    lead_m_per_rev: float | None = None
    zero_ticks: float = 0.0
    direction: int = 1

    @property
    def ticks_per_unit(self) -> float:
        if self.unit == "rad":
            return TICKS_PER_REV * self.gear_ratio / (2.0 * math.pi)
        if self.unit == "m":
            if not self.lead_m_per_rev:
                raise ValueError("a joint in metres needs lead_m_per_rev")
            return TICKS_PER_REV * self.gear_ratio / self.lead_m_per_rev
        raise ValueError(f"unknown joint unit {self.unit!r} (expected rad or m)")

    def to_ticks(self, value: float) -> int:
        return round(self.zero_ticks + self.direction * value * self.ticks_per_unit)

    def from_ticks(self, ticks: float) -> float:
        return self.direction * (ticks - self.zero_ticks) / self.ticks_per_unit

    def velocity_from_raw(self, raw: int) -> float:
        """Present Velocity (0.229 rpm units) to joint units per second."""
        ticks_per_s = raw * VELOCITY_UNIT_RPM / 60.0 * TICKS_PER_REV
        return self.direction * ticks_per_s / self.ticks_per_unit

    def velocity_to_raw(self, velocity: float) -> int:
        """Joint units per second to a velocity register value (0.229 rpm units), rounded up in size."""
        rpm = abs(velocity) * self.ticks_per_unit / TICKS_PER_REV * 60.0
        raw = math.ceil(rpm / VELOCITY_UNIT_RPM)
        return int(math.copysign(raw, velocity * self.direction)) if velocity else 0
