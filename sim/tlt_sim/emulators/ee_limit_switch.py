"""The end effector's calibration limit switch, closed by the width carriage (paper §V.B.4).

The width joint is a lead screw driven by an MX-106T; at one end of its travel the carriage
presses a limit switch wired to a GPIO input. Physically the switch is a property of the
mechanism, not of the servo: the servo's ticks after power-up say nothing about where the
carriage is, which is why the driver must calibrate. This model ties the two together: the
carriage position follows the servo's shaft from a home tick the driver does not know, the
switch closes at the end of travel, and a hard stop there keeps the shaft from going further.
The twin uses it with MuJoCo's width joint; the stand-alone chain emulator uses it on its own.
"""

from __future__ import annotations

from tlt_sim.emulators.dynamixel_servo import DynamixelServo
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip

TICKS_PER_REV = 4096
# The switch closes within this distance of the end of travel, m.
PRESS_DISTANCE_M = 0.0005


class WidthLimitSwitch:
    """Drive the EE limit-switch GPIO input from the width servo's shaft position.

    ``direction`` is the sign of shaft motion that moves the carriage towards the switch (the
    driver's ``calibration.direction``); the carriage starts ``start_m`` away from the switch.
    """

    def __init__(
        self,
        servo: DynamixelServo,
        chip: EmulatedGpioChip,
        line: int,
        *,
        active_low: bool,
        lead_m_per_rev: float,
        direction: int,
        start_m: float = 0.005,
    ) -> None:
        self.servo = servo
        self.chip = chip
        self.line = line
        self.active_low = active_low
        self.metres_per_tick = lead_m_per_rev / TICKS_PER_REV
        self.direction = 1 if direction >= 0 else -1
        self.home_ticks = servo.position + self.direction * start_m / self.metres_per_tick
        # The hard stop just past the switch: the shaft cannot drive the carriage through it.
        stop = self.home_ticks + self.direction * 0.002 / self.metres_per_tick
        servo.set_obstacle(**({"upper": stop} if self.direction > 0 else {"lower": stop}))
        self.update()

    def carriage_from_switch_m(self) -> float:
        """How far the carriage is from the switch, m (0 at the switch)."""
        return (self.home_ticks - self.servo.position) * self.direction * self.metres_per_tick

    @property
    def pressed(self) -> bool:
        return self.carriage_from_switch_m() <= PRESS_DISTANCE_M

    def update(self) -> None:
        """Set the GPIO line's electrical level from the carriage position."""
        self.chip.drive(self.line, not self.pressed if self.active_low else self.pressed)
