"""One emulated MX-106(2.0) servo: its control table and a simple motion model.

The control table holds the items the drivers use, at the addresses and sizes of the ROBOTIS
MX-106(2.0) e-manual. Reads and writes go through :meth:`read` / :meth:`write`, which answer the
Protocol 2.0 error numbers a real servo gives: Access Error for a read-only item or an EEPROM item
while torque is on, Data Limit Error for a goal position outside the position limits, Result Fail
for torque-on while a shutdown-class hardware error is latched.

Motion is a velocity-limited first-order approach to the goal, stepped by :meth:`step` with a
caller-supplied ``dt`` (the chain steps it from an injectable clock). The physical side is plain
state for the twin to drive and read: an optional obstacle interval that blocks motion (a grasp
shows up as a position that stops short of the goal and a present current at the limit) and an
external load current. Sustained current at the current limit latches the overload bit and
removes torque, as the real servo's shutdown does. Losing power or rebooting keeps the position
within one turn only (the absolute encoder covers one revolution), which is why the end effector
needs its limit-switch calibration.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from tlt_sim.emulators import dynamixel_protocol as proto

MODEL_NUMBER = 321  # MX-106(2.0)
FIRMWARE_VERSION = 45
TICKS_PER_REV = 4096
VELOCITY_UNIT_RPM = 0.229
CURRENT_UNIT_MA = 3.36

# Operating modes (address 11)
MODE_CURRENT = 0
MODE_VELOCITY = 1
MODE_POSITION = 3
MODE_EXTENDED_POSITION = 4
MODE_CURRENT_BASED_POSITION = 5
MODE_PWM = 16
MODES = (
    MODE_CURRENT,
    MODE_VELOCITY,
    MODE_POSITION,
    MODE_EXTENDED_POSITION,
    MODE_CURRENT_BASED_POSITION,
    MODE_PWM,
)

# Hardware Error Status bits (address 70)
HW_INPUT_VOLTAGE = 1 << 0
HW_OVERHEATING = 1 << 2
HW_MOTOR_ENCODER = 1 << 3
HW_ELECTRICAL_SHOCK = 1 << 4
HW_OVERLOAD = 1 << 5


@dataclass(frozen=True)
class Item:
    name: str
    address: int
    size: int
    eeprom: bool = False
    writable: bool = True
    signed: bool = False
    default: int = 0


ITEMS: tuple[Item, ...] = (
    Item("model_number", 0, 2, eeprom=True, writable=False, default=MODEL_NUMBER),
    Item("model_information", 2, 4, eeprom=True, writable=False),
    Item("firmware_version", 6, 1, eeprom=True, writable=False, default=FIRMWARE_VERSION),
    Item("id", 7, 1, eeprom=True, default=1),
    Item("baud_rate", 8, 1, eeprom=True, default=3),  # 3 = 1 Mbps
    Item("return_delay_time", 9, 1, eeprom=True, default=250),
    Item("drive_mode", 10, 1, eeprom=True),
    Item("operating_mode", 11, 1, eeprom=True, default=MODE_POSITION),
    Item("secondary_id", 12, 1, eeprom=True, default=255),
    Item("protocol_type", 13, 1, eeprom=True, default=2),
    Item("homing_offset", 20, 4, eeprom=True, signed=True),
    Item("moving_threshold", 24, 4, eeprom=True, default=10),
    Item("temperature_limit", 31, 1, eeprom=True, default=80),
    Item("max_voltage_limit", 32, 2, eeprom=True, default=160),
    Item("min_voltage_limit", 34, 2, eeprom=True, default=95),
    Item("pwm_limit", 36, 2, eeprom=True, default=885),
    Item("current_limit", 38, 2, eeprom=True, default=2047),
    Item("acceleration_limit", 40, 4, eeprom=True, default=32767),
    Item("velocity_limit", 44, 4, eeprom=True, default=210),
    Item("max_position_limit", 48, 4, eeprom=True, default=4095),
    Item("min_position_limit", 52, 4, eeprom=True, default=0),
    Item("shutdown", 63, 1, eeprom=True, default=HW_OVERHEATING | HW_ELECTRICAL_SHOCK | HW_OVERLOAD),
    Item("torque_enable", 64, 1),
    Item("led", 65, 1),
    Item("status_return_level", 68, 1, default=2),
    Item("registered_instruction", 69, 1, writable=False),
    Item("hardware_error_status", 70, 1, writable=False),
    Item("velocity_i_gain", 76, 2, default=1920),
    Item("velocity_p_gain", 78, 2, default=100),
    Item("position_d_gain", 80, 2),
    Item("position_i_gain", 82, 2),
    Item("position_p_gain", 84, 2, default=850),
    Item("bus_watchdog", 98, 1),
    Item("goal_pwm", 100, 2, signed=True, default=885),
    Item("goal_current", 102, 2, signed=True, default=2047),
    Item("goal_velocity", 104, 4, signed=True),
    Item("profile_acceleration", 108, 4),
    Item("profile_velocity", 112, 4),
    Item("goal_position", 116, 4, signed=True),
    Item("realtime_tick", 120, 2, writable=False),
    Item("moving", 122, 1, writable=False),
    Item("moving_status", 123, 1, writable=False),
    Item("present_pwm", 124, 2, writable=False, signed=True),
    Item("present_current", 126, 2, writable=False, signed=True),
    Item("present_velocity", 128, 4, writable=False, signed=True),
    Item("present_position", 132, 4, writable=False, signed=True),
    Item("velocity_trajectory", 136, 4, writable=False, signed=True),
    Item("position_trajectory", 140, 4, writable=False, signed=True),
    Item("present_input_voltage", 144, 2, writable=False, default=120),
    Item("present_temperature", 146, 1, writable=False, default=35),
)
ITEM_BY_NAME = {item.name: item for item in ITEMS}
TABLE_SIZE = 148
_ITEM_AT: dict[int, Item] = {}
for _item in ITEMS:
    for _a in range(_item.address, _item.address + _item.size):
        _ITEM_AT[_a] = _item


class ServoError(Exception):
    """A request the servo refuses; ``code`` is the Protocol 2.0 error number."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code


def _pack(item: Item, value: int) -> bytes:
    fmt = {1: "b", 2: "h", 4: "i"}[item.size] if item.signed else {1: "B", 2: "H", 4: "I"}[item.size]
    return struct.pack("<" + fmt, int(value))


def _unpack(item: Item, data: bytes) -> int:
    fmt = {1: "b", 2: "h", 4: "i"}[item.size] if item.signed else {1: "B", 2: "H", 4: "I"}[item.size]
    return struct.unpack("<" + fmt, data)[0]


def _codec(item: Item) -> tuple[int, struct.Struct]:
    fmt = {1: "b", 2: "h", 4: "i"}[item.size] if item.signed else {1: "B", 2: "H", 4: "I"}[item.size]
    return item.address, struct.Struct("<" + fmt)


# name -> (address, compiled little-endian format): the twin reads and writes the table several
# times per servo every sync period, so the format is compiled once, not per access.
_CODEC = {item.name: _codec(item) for item in ITEMS}


class DynamixelServo:
    """An MX-106(2.0) at ``dxl_id``; positions are in ticks (4096 per turn) as the servo counts them."""

    #: proportional gain of the first-order approach (1/s); high enough to settle in well under 0.2 s
    APPROACH_GAIN = 30.0
    #: current (in 3.36 mA units) per tick of position error when blocked by an obstacle
    BLOCKED_CURRENT_PER_TICK = 8.0

    def __init__(self, dxl_id: int, *, position_ticks: float = 2048.0, overload_time_s: float = 1.0) -> None:
        self.table = bytearray(TABLE_SIZE)
        self.overload_time_s = overload_time_s
        self._eeprom_defaults: dict[str, int] = {}
        for item in ITEMS:
            self._set(item.name, item.default)
        self._set("id", dxl_id)
        self.position = float(position_ticks)  # physical shaft position, ticks, multi-turn
        self.velocity = 0.0  # ticks/s
        self.current = 0.0  # 3.36 mA units
        self.external_load = 0.0  # current units the load draws even at rest
        self.obstacle: tuple[float | None, float | None] = (None, None)
        self._at_limit_time = 0.0
        self._time = 0.0
        self.registered: tuple[int, bytes] | None = None
        self._reset_ram()

    # --- table access ----------------------------------------------------------------------------
    @property
    def dxl_id(self) -> int:
        return self.get("id")

    def get(self, name: str) -> int:
        address, codec = _CODEC[name]
        return codec.unpack_from(self.table, address)[0]

    def _set(self, name: str, value: int) -> None:
        address, codec = _CODEC[name]
        codec.pack_into(self.table, address, int(value))

    def read(self, address: int, length: int) -> bytes:
        """Bytes of the control table; Data Range Error past its end."""
        if length < 1 or address + length > TABLE_SIZE:
            raise ServoError(proto.ERR_DATA_RANGE, f"read {address}+{length} is past the control table")
        self._refresh_present()
        return bytes(self.table[address : address + length])

    def check_write(self, address: int, data: bytes) -> None:
        """Raise :class:`ServoError` if writing ``data`` at ``address`` would be refused."""
        if not data or address + len(data) > TABLE_SIZE:
            raise ServoError(proto.ERR_DATA_RANGE, f"write {address}+{len(data)} is past the control table")
        touched = {_ITEM_AT[a] for a in range(address, address + len(data)) if a in _ITEM_AT}
        for item in touched:
            if not item.writable:
                raise ServoError(proto.ERR_ACCESS, f"{item.name} is read-only")
            if item.eeprom and self.get("torque_enable"):
                raise ServoError(proto.ERR_ACCESS, f"{item.name} is in EEPROM and torque is on")
            if item.address < address or item.address + item.size > address + len(data):
                raise ServoError(proto.ERR_DATA_LENGTH, f"write covers part of {item.name}")
        scratch = bytearray(self.table)
        scratch[address : address + len(data)] = data
        for item in touched:
            value = _unpack(item, bytes(scratch[item.address : item.address + item.size]))
            if item.name == "operating_mode" and value not in MODES:
                raise ServoError(proto.ERR_DATA_RANGE, f"operating mode {value} does not exist")
            if item.name == "torque_enable" and value not in (0, 1):
                raise ServoError(proto.ERR_DATA_RANGE, f"torque enable {value} is not 0 or 1")
            if item.name == "torque_enable" and value == 1 and self.shutdown_latched:
                raise ServoError(proto.ERR_RESULT_FAIL, "torque is locked out by a hardware error; reboot")
            if item.name == "goal_position" and self.get("operating_mode") == MODE_POSITION:
                low, high = self.get("min_position_limit"), self.get("max_position_limit")
                if not low <= value <= high:
                    raise ServoError(proto.ERR_DATA_LIMIT, f"goal position {value} outside {low}..{high}")

    def write(self, address: int, data: bytes) -> None:
        """Write after :meth:`check_write`; side effects (torque on holds position) apply here."""
        self.check_write(address, data)
        was_torque = self.get("torque_enable")
        self.table[address : address + len(data)] = data
        goal_written = address <= ITEM_BY_NAME["goal_position"].address < address + len(data)
        if not was_torque and self.get("torque_enable") and not goal_written:
            # A servo holds where it stands when torque comes on.
            self._set("goal_position", round(self.position))

    @property
    def shutdown_latched(self) -> bool:
        return bool(self.get("hardware_error_status") & self.get("shutdown"))

    @property
    def alert(self) -> bool:
        return self.get("hardware_error_status") != 0

    # --- faults and power ------------------------------------------------------------------------
    def inject_hardware_error(self, bits: int) -> None:
        """Latch hardware error bits; shutdown-class bits remove torque, as on the real servo."""
        self._set("hardware_error_status", self.get("hardware_error_status") | bits)
        if self.shutdown_latched:
            self._set("torque_enable", 0)

    def reboot(self) -> None:
        """Power-cycle: RAM back to defaults, errors cleared, multi-turn count lost."""
        self._set("hardware_error_status", 0)
        self.position = self.position % TICKS_PER_REV
        self.velocity = 0.0
        self.current = 0.0
        self._at_limit_time = 0.0
        self._reset_ram()

    def _reset_ram(self) -> None:
        for item in ITEMS:
            if not item.eeprom and item.writable:
                self._set(item.name, item.default)
        self._set("goal_position", round(self.position))
        self.registered = None
        self._refresh_present()

    # --- physics -----------------------------------------------------------------------------------
    def set_obstacle(self, lower: float | None = None, upper: float | None = None) -> None:
        """Block the shaft below ``lower`` / above ``upper`` ticks (None: free)."""
        self.obstacle = (lower, upper)

    def _max_speed(self) -> float:
        """Ticks/s from the profile velocity, or the velocity limit when the profile is 0."""
        units = self.get("profile_velocity") or self.get("velocity_limit")
        units = min(units, self.get("velocity_limit")) or 1
        return units * VELOCITY_UNIT_RPM / 60.0 * TICKS_PER_REV

    def step(self, dt: float, refresh: bool = True) -> None:
        """Advance the shaft by ``dt`` seconds. ``refresh=False`` leaves the present-value registers
        for a later step to write (they depend only on the state the last step leaves)."""
        if dt <= 0:
            return
        self._time += dt
        mode = self.get("operating_mode")
        limit = float(self.get("current_limit"))
        if mode == MODE_CURRENT_BASED_POSITION:
            limit = min(limit, abs(self.get("goal_current")))
        if not self.get("torque_enable"):
            self.velocity = 0.0
            self.current = 0.0
            self._at_limit_time = 0.0
            if refresh:
                self._refresh_present()
            return
        vmax = self._max_speed()
        if mode == MODE_VELOCITY:
            cap = self.get("velocity_limit") * VELOCITY_UNIT_RPM / 60.0 * TICKS_PER_REV
            target_v = max(
                -cap, min(cap, self.get("goal_velocity") * VELOCITY_UNIT_RPM / 60.0 * TICKS_PER_REV)
            )
            goal = self.position + target_v * dt
        elif mode in (MODE_POSITION, MODE_EXTENDED_POSITION, MODE_CURRENT_BASED_POSITION):
            goal = float(self.get("goal_position"))
            target_v = max(-vmax, min(vmax, self.APPROACH_GAIN * (goal - self.position)))
        else:  # current and PWM modes: no commanded motion in this model
            goal = self.position
            target_v = 0.0
        new_position = self.position + target_v * dt
        if mode != MODE_VELOCITY and (goal - self.position) * (goal - new_position) < 0:
            new_position = goal  # never overshoot
        lower, upper = self.obstacle
        blocked = False
        if upper is not None and new_position > upper:
            new_position = self.position if self.position > upper else upper
            blocked = True
        if lower is not None and new_position < lower:
            new_position = self.position if self.position < lower else lower
            blocked = True
        self.velocity = (new_position - self.position) / dt
        self.position = new_position
        if blocked:
            # The position loop pushes against the obstacle harder the further the goal lies past it.
            push = (goal - new_position) if mode != MODE_VELOCITY else target_v * 0.05
            self.current = math.copysign(min(limit, abs(push) * self.BLOCKED_CURRENT_PER_TICK), push)
        else:
            self.current = max(-limit, min(limit, self.external_load + 0.02 * self.velocity))
        # The real servo trips its overload protection after sustained maximum output; in
        # current-based position mode the goal current caps the output below that.
        at_max = abs(self.current) >= 0.95 * self.get("current_limit")
        self._at_limit_time = self._at_limit_time + dt if at_max else 0.0
        if self._at_limit_time >= self.overload_time_s:
            self.inject_hardware_error(HW_OVERLOAD)
        if refresh:
            self._refresh_present()

    def _refresh_present(self) -> None:
        self._set("present_position", round(self.position))
        self._set("present_velocity", round(self.velocity * 60.0 / TICKS_PER_REV / VELOCITY_UNIT_RPM))
        self._set("present_current", round(max(-32768, min(32767, self.current))))
        moving = abs(self.velocity) * 60.0 / TICKS_PER_REV / VELOCITY_UNIT_RPM > self.get("moving_threshold")
        self._set("moving", int(moving))
        self._set("realtime_tick", int(self._time * 1000) % 32768)
        self._set("position_trajectory", self.get("goal_position"))


__all__ = [
    "HW_ELECTRICAL_SHOCK",
    "HW_INPUT_VOLTAGE",
    "HW_MOTOR_ENCODER",
    "HW_OVERHEATING",
    "HW_OVERLOAD",
    "ITEMS",
    "MODEL_NUMBER",
    "DynamixelServo",
    "ServoError",
]
