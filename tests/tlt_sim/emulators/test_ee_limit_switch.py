"""The EE limit switch closes when the width carriage reaches the end of its travel, and the
hard stop there holds the shaft; the GPIO input reads it with its active-low wiring."""

from __future__ import annotations

from tlt_sim.emulators.dynamixel_servo import MODE_EXTENDED_POSITION, DynamixelServo
from tlt_sim.emulators.ee_limit_switch import TICKS_PER_REV, WidthLimitSwitch
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip

LEAD = 0.002  # m per turn


def make(direction: int, active_low: bool = True):
    servo = DynamixelServo(3, position_ticks=1000.0)
    servo.write(11, bytes([MODE_EXTENDED_POSITION]))
    servo.write(64, b"\x01")
    chip = EmulatedGpioChip()
    switch = WidthLimitSwitch(
        servo, chip, 2, active_low=active_low, lead_m_per_rev=LEAD, direction=direction, start_m=0.004
    )
    return servo, chip, switch


def drive_to(servo: DynamixelServo, switch: WidthLimitSwitch, goal_ticks: float, seconds: float = 20.0):
    servo.write(116, int(goal_ticks).to_bytes(4, "little", signed=True))
    for _ in range(int(seconds / 0.01)):
        servo.step(0.01)
        switch.update()


def test_the_switch_opens_away_from_the_end_and_closes_at_it():
    for direction in (-1, 1):
        servo, chip, switch = make(direction)
        assert switch.carriage_from_switch_m() == 0.004
        assert not switch.pressed and chip.level(2) is True  # active low: released reads high
        ticks_to_switch = 0.004 / LEAD * TICKS_PER_REV
        drive_to(servo, switch, 1000 + direction * (ticks_to_switch + 500))
        assert switch.pressed and chip.level(2) is False
        drive_to(servo, switch, 1000)
        assert not switch.pressed and chip.level(2) is True


def test_a_hard_stop_past_the_switch_holds_the_carriage():
    servo, _chip, switch = make(-1)
    drive_to(servo, switch, 1000 - 100000, seconds=15.0)
    assert -0.0021 < switch.carriage_from_switch_m() < -0.0019
    assert switch.pressed


def test_an_active_high_switch_reads_high_when_pressed():
    servo, chip, switch = make(-1, active_low=False)
    drive_to(servo, switch, 1000 - 20000)
    assert switch.pressed and chip.level(2) is True
