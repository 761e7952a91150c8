"""The MX-106(2.0) control-table items the driver uses (addresses and sizes from the ROBOTIS e-manual)."""

from __future__ import annotations

MODEL_NUMBER_MX106_2 = 321
TICKS_PER_REV = 4096
VELOCITY_UNIT_RPM = 0.229  # Profile/Goal/Present Velocity
ACCELERATION_UNIT_RPM2 = 214.577  # Profile Acceleration
CURRENT_UNIT_MA = 3.36  # Goal/Present Current of the MX-106(2.0)

ADDR_OPERATING_MODE = 11  # 1 byte, EEPROM
ADDR_CURRENT_LIMIT = 38  # 2 bytes, EEPROM
ADDR_TORQUE_ENABLE = 64  # 1 byte
ADDR_HARDWARE_ERROR_STATUS = 70  # 1 byte, read-only
ADDR_GOAL_CURRENT = 102  # 2 bytes
ADDR_GOAL_VELOCITY = 104  # 4 bytes
ADDR_PROFILE_ACCELERATION = 108  # 4 bytes
ADDR_PROFILE_VELOCITY = 112  # 4 bytes
ADDR_GOAL_POSITION = 116  # 4 bytes

# One sync read each cycle covers Moving (122) .. Present Position (132..135).
ADDR_PRESENT_BLOCK = 122
LEN_PRESENT_BLOCK = 14
OFF_MOVING = 0
OFF_PRESENT_CURRENT = 4  # 126, 2 bytes signed
OFF_PRESENT_VELOCITY = 6  # 128, 4 bytes signed
OFF_PRESENT_POSITION = 10  # 132, 4 bytes signed

OPERATING_MODES = {
    "current": 0,
    "velocity": 1,
    "position": 3,
    "extended_position": 4,
    "current_based_position": 5,
}
POSITION_MODES = ("position", "extended_position", "current_based_position")

HARDWARE_ERROR_BITS = {
    0: "input voltage error",
    2: "overheating",
    3: "motor encoder error",
    4: "electrical shock",
    5: "overload",
}


def describe_hardware_error(bits: int) -> str:
    """'overload, overheating' for a Hardware Error Status byte; '' when 0."""
    names = [name for bit, name in HARDWARE_ERROR_BITS.items() if bits & (1 << bit)]
    unknown = bits & ~sum(1 << bit for bit in HARDWARE_ERROR_BITS)
    if unknown:
        names.append(f"unknown bits 0x{unknown:02x}")
    return ", ".join(names)
