"""Hardware interface of one Dynamixel chain (U2D2 + MX-106(2.0) servos) over dynamixel-sdk, Protocol 2.0.

Lifecycle (see :mod:`tlt_drivers.hardware_interface`):

* ``configure`` opens the port, pings every servo and checks its model number, reads its Hardware
  Error Status and, when one is latched and ``comm.reboot_on_hardware_error`` is set, reboots the
  servo and waits (bounded) for it to answer again.
* ``activate`` sets each servo's operating mode *individually* (torque off first, since the mode
  lives in EEPROM), its profile velocity and goal current, holds the present position and turns
  torque on. One chain may thus mix trajectory-controlled and group-position-controlled joints.
* ``read`` is one SYNC_READ of Moving .. Present Position for all servos. The status error byte of
  each reply is checked: the alert bit leads to a read of Hardware Error Status, which is stored in
  :attr:`hardware_error` and raises (the interface goes to ERROR naming servo and bits).
* ``write`` is one SYNC_WRITE of Goal Position (and one of Goal Velocity for velocity-mode joints).

Every transfer is retried ``comm.retries_per_transfer`` times on timeouts, corrupt replies and CRC
errors reported by a servo; when the budget is spent the transfer raises, so the interface enters
ERROR within a bounded time (each attempt is bounded by the SDK's packet timeout). ``recover``
reopens the link, reboots servos with latched errors and reactivates.
"""

from __future__ import annotations

import math
import select
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import serial
from dynamixel_sdk import (
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from tlt_drivers.dynamixel import control_table as ct
from tlt_drivers.dynamixel.joint_scale import JointScale
from tlt_drivers.hardware_interface import JointGroupInterface

ERRNUM_CRC = 3
ERRBIT_ALERT = 0x80


class _PortHandler(PortHandler):
    """dynamixel-sdk's PortHandler with the USB latency allowance from the config instead of 16 ms,
    and a receive wait that sleeps on the port instead of spinning.

    The SDK waits ``2 * latency + 2 ms`` (plus wire time) for a status packet; with an FTDI latency
    timer set to 1 ms the allowance can shrink, on a busy host it may need to grow.
    """

    def __init__(self, port_name: str, latency_ms: float) -> None:
        super().__init__(port_name)
        self.latency_ms = latency_ms

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + self.latency_ms * 2.0 + 2.0

    def readPort(self, length: int) -> bytes:
        # The SDK polls this in a loop until its packet timeout; when nothing has arrived yet, wait
        # on the file descriptor (bounded by the time left) instead of spinning on the CPU.
        data = self.ser.read(length)
        if not data:
            remaining_ms = self.packet_timeout - self.getTimeSinceStart()
            if remaining_ms > 0:
                select.select([self.ser.fileno()], [], [], min(remaining_ms, 5.0) / 1000.0)
                data = self.ser.read(length)
        return data


class DynamixelLinkError(RuntimeError):
    """A transfer failed after its retry budget was spent."""


class DynamixelHardwareError(RuntimeError):
    """A servo reported a latched hardware error (overload, overheating, electrical shock...)."""


@dataclass
class ServoJoint:
    """One servo and the joint it drives."""

    name: str
    dxl_id: int
    mode: str
    controller: str
    scale: JointScale
    lower: float
    upper: float
    max_velocity: float
    goal_current_ma: float | None = None
    engaged_above: float | None = None
    raw_ticks: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class DynamixelChainInterface(JointGroupInterface):
    """State: :attr:`position`, :attr:`velocity`, :attr:`effort`, :attr:`moving`, :attr:`hardware_error`
    per joint. Commands: :attr:`command` (joint units; position modes) and :attr:`command_velocity`
    (velocity mode). Controllers write commands between ``read`` and ``write``."""

    def __init__(self, config: dict[str, Any], *, sleep: Callable[[float], None] = time.sleep) -> None:
        super().__init__(config["component"])
        self.config = config
        self._sleep = sleep
        comm = config["comm"]
        self.retry_budget = int(comm["retries_per_transfer"])
        self.joints: list[ServoJoint] = [
            ServoJoint(
                name=j["name"],
                dxl_id=j["id"],
                mode=j["mode"],
                controller=j["controller"],
                scale=JointScale(
                    j["unit"], j["gear_ratio"], j["lead_m_per_rev"], j["zero_ticks"], j["direction"]
                ),
                lower=j["lower"],
                upper=j["upper"],
                max_velocity=j["max_velocity"],
                goal_current_ma=j["goal_current_ma"],
                engaged_above=j["engaged_above"],
            )
            for j in config["joints"]
        ]
        self.by_name = {j.name: j for j in self.joints}
        names = [j.name for j in self.joints]
        self.position = dict.fromkeys(names, 0.0)
        self.velocity = dict.fromkeys(names, 0.0)
        self.effort = dict.fromkeys(names, 0.0)
        self.moving = dict.fromkeys(names, False)
        self.hardware_error = dict.fromkeys(names, 0)
        self.command = dict.fromkeys(names, 0.0)
        self.command_velocity = dict.fromkeys(names, 0.0)
        #: joints whose commands are not clamped to the limits (the EE width joint while it seeks its switch)
        self.unclamped: set[str] = set()
        self.retries = 0  # retries since the last status report (the node resets it)
        self.link_ok = False
        self.have_state = False
        self._port: PortHandler | None = None
        self._packet = PacketHandler(2.0)
        self._sync_read: GroupSyncRead | None = None
        self._missing: ServoJoint | None = None  # the servo whose reply was missing in the last sync read

    # --- helpers -------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    def _label(self, joint: ServoJoint) -> str:
        return f"servo {joint.name!r} (id {joint.dxl_id})"

    def _describe(self, result: int, error: int) -> str:
        if result != COMM_SUCCESS:
            return self._packet.getTxRxResult(result)
        return self._packet.getRxPacketError(error)

    def _transfer(self, what: str, fn: Callable[[], tuple[int, int, Any]]) -> Any:
        """Run ``fn`` -> (result, error, value) with the retry budget; returns value or raises."""
        last = ""
        for attempt in range(self.retry_budget + 1):
            try:
                result, error, value = fn()
            except (OSError, serial.SerialException) as exc:
                # The device went away mid-transfer; the SDK would otherwise keep the port marked busy.
                if self._port is not None:
                    self._port.is_using = False
                self.link_ok = False
                raise DynamixelLinkError(f"{what}: serial port failed: {exc}") from exc
            retryable_error = (error & 0x7F) == ERRNUM_CRC
            if result == COMM_SUCCESS and not retryable_error:
                if error & 0x7F:
                    raise DynamixelLinkError(f"{what}: {self._describe(result, error & 0x7F)}")
                self.link_ok = True
                return value
            last = self._describe(result, error & 0x7F)
            if attempt < self.retry_budget:
                self.retries += 1
        self.link_ok = False
        raise DynamixelLinkError(f"{what}: {last} (after {self.retry_budget + 1} attempts)")

    def _write1(self, joint: ServoJoint, address: int, value: int, what: str) -> None:
        def go() -> tuple[int, int, None]:
            result, error = self._packet.write1ByteTxRx(self._port, joint.dxl_id, address, value)
            return result, error, None

        self._transfer(f"{self._label(joint)}: {what}", go)

    def _write2(self, joint: ServoJoint, address: int, value: int, what: str) -> None:
        def go() -> tuple[int, int, None]:
            result, error = self._packet.write2ByteTxRx(self._port, joint.dxl_id, address, value & 0xFFFF)
            return result, error, None

        self._transfer(f"{self._label(joint)}: {what}", go)

    def _write4(self, joint: ServoJoint, address: int, value: int, what: str) -> None:
        def go() -> tuple[int, int, None]:
            result, error = self._packet.write4ByteTxRx(self._port, joint.dxl_id, address, value & 0xFFFFFFFF)
            return result, error, None

        self._transfer(f"{self._label(joint)}: {what}", go)

    def _read1(self, joint: ServoJoint, address: int, what: str) -> int:
        def go() -> tuple[int, int, int]:
            value, result, error = self._packet.read1ByteTxRx(self._port, joint.dxl_id, address)
            return result, error & 0x7F, value

        return self._transfer(f"{self._label(joint)}: {what}", go)

    def _read4_signed(self, joint: ServoJoint, address: int, what: str) -> int:
        def go() -> tuple[int, int, int]:
            value, result, error = self._packet.read4ByteTxRx(self._port, joint.dxl_id, address)
            return result, error & 0x7F, value

        raw = self._transfer(f"{self._label(joint)}: {what}", go)
        return struct.unpack("<i", struct.pack("<I", raw & 0xFFFFFFFF))[0]

    def _ping(self, joint: ServoJoint) -> int:
        def go() -> tuple[int, int, int]:
            model, result, error = self._packet.ping(self._port, joint.dxl_id)
            return result, error & 0x7F, model

        return self._transfer(f"{self._label(joint)}: ping", go)

    # --- lifecycle hooks ---------------------------------------------------------------------------------
    def on_configure(self) -> None:
        port = _PortHandler(self.config["port"], self.config["comm"]["latency_timer_ms"])
        try:
            opened = port.openPort() and port.setBaudRate(self.config["baudrate"])
        except Exception as exc:  # pyserial raises SerialException/OSError for a missing device
            raise DynamixelLinkError(f"cannot open {self.config['port']}: {exc}") from exc
        if not opened:
            raise DynamixelLinkError(f"cannot open {self.config['port']} at {self.config['baudrate']} baud")
        self._port = port
        for joint in self.joints:
            model = self._ping(joint)
            if model != self.config["model_number"]:
                raise DynamixelLinkError(
                    f"{self._label(joint)} is model {model}, expected {self.config['model_number']}"
                )
            bits = self._read1(joint, ct.ADDR_HARDWARE_ERROR_STATUS, "read hardware error status")
            self.hardware_error[joint.name] = bits
            if bits and self.config["comm"]["reboot_on_hardware_error"]:
                self._reboot(joint)
                bits = self._read1(joint, ct.ADDR_HARDWARE_ERROR_STATUS, "read hardware error status")
                self.hardware_error[joint.name] = bits
            if bits:
                raise DynamixelHardwareError(
                    f"{self._label(joint)} hardware error: {ct.describe_hardware_error(bits)}"
                )
        self._sync_read = GroupSyncRead(self._port, self._packet, ct.ADDR_PRESENT_BLOCK, ct.LEN_PRESENT_BLOCK)
        for joint in self.joints:
            self._sync_read.addParam(joint.dxl_id)
        self.link_ok = True

    def _reboot(self, joint: ServoJoint) -> None:
        """REBOOT clears a latched hardware error; the servo is deaf for a moment afterwards."""
        self._log.warning("%s: rebooting %s to clear a hardware error", self.name, self._label(joint))

        def go() -> tuple[int, int, None]:
            result, error = self._packet.reboot(self._port, joint.dxl_id)
            return result, error & 0x7F, None

        self._transfer(f"{self._label(joint)}: reboot", go)
        deadline = time.monotonic() + self.config["comm"]["reboot_timeout_s"]
        while True:
            self._sleep(0.02)
            _model, result, _ = self._packet.ping(self._port, joint.dxl_id)
            if result == COMM_SUCCESS:
                return
            if time.monotonic() > deadline:
                raise DynamixelLinkError(f"{self._label(joint)} did not answer after reboot")

    def on_activate(self) -> None:
        for joint in self.joints:
            self._write1(joint, ct.ADDR_TORQUE_ENABLE, 0, "torque off")
            mode = ct.OPERATING_MODES[joint.mode]
            if self._read1(joint, ct.ADDR_OPERATING_MODE, "read operating mode") != mode:
                self._write1(joint, ct.ADDR_OPERATING_MODE, mode, f"set operating mode {joint.mode}")
            if joint.mode == "current_based_position":
                assert joint.goal_current_ma is not None  # the config schema requires it for this mode
                units = round(joint.goal_current_ma / ct.CURRENT_UNIT_MA)
                self._write2(joint, ct.ADDR_GOAL_CURRENT, units, "set goal current")
            profile = abs(joint.scale.velocity_to_raw(joint.max_velocity))
            self._write4(joint, ct.ADDR_PROFILE_VELOCITY, profile, "set profile velocity")
            ticks = self._read4_signed(
                joint, ct.ADDR_PRESENT_BLOCK + ct.OFF_PRESENT_POSITION, "read position"
            )
            joint.raw_ticks = ticks
            self.position[joint.name] = joint.scale.from_ticks(ticks)
            self.command[joint.name] = self.position[joint.name]
            self.command_velocity[joint.name] = 0.0
            if joint.mode in ct.POSITION_MODES:
                self._write4(joint, ct.ADDR_GOAL_POSITION, ticks, "hold present position")
            else:
                self._write4(joint, ct.ADDR_GOAL_VELOCITY, 0, "zero goal velocity")
            self._write1(joint, ct.ADDR_TORQUE_ENABLE, 1, "torque on")
        self.have_state = True

    def on_deactivate(self) -> None:
        problems = []
        for joint in self.joints:
            try:
                self._write1(joint, ct.ADDR_TORQUE_ENABLE, 0, "torque off")
            except DynamixelLinkError as exc:
                problems.append(str(exc))
        if problems:
            raise DynamixelLinkError("; ".join(problems))

    def on_cleanup(self) -> None:
        port, self._port = self._port, None
        self._sync_read = None
        self.link_ok = False
        if port is not None and port.is_open:
            port.closePort()

    # --- control cycle -----------------------------------------------------------------------------------
    def _sync_read_once(self) -> tuple[int, int, dict[int, tuple[bytes, int]]]:
        assert self._sync_read is not None  # called only while the port is open
        result = self._sync_read.txPacket()
        if result != COMM_SUCCESS:
            return result, 0, {}
        replies: dict[int, tuple[bytes, int]] = {}
        for joint in self.joints:
            data, result, error = self._packet.readRx(self._port, joint.dxl_id, ct.LEN_PRESENT_BLOCK)
            if result != COMM_SUCCESS:
                self._missing = joint
                return result, 0, {}
            if (error & 0x7F) == ERRNUM_CRC:
                return result, error, {}
            replies[joint.dxl_id] = (bytes(data), error)
        return COMM_SUCCESS, 0, replies

    def on_read(self, now: float) -> None:
        self._missing = None

        def go() -> tuple[int, int, dict[int, tuple[bytes, int]]]:
            return self._sync_read_once()

        try:
            replies = self._transfer("sync read", go)
        except DynamixelLinkError as exc:
            if self._missing is not None:
                raise DynamixelLinkError(f"{self._label(self._missing)} did not answer: {exc}") from exc
            raise
        alerts = []
        stall = self.config["stall_current_ma"]
        for joint in self.joints:
            data, error = replies[joint.dxl_id]
            moving, current, velocity, ticks = struct.unpack_from("<B3xhii", data)
            joint.raw_ticks = ticks
            self.position[joint.name] = joint.scale.from_ticks(ticks)
            self.velocity[joint.name] = joint.scale.velocity_from_raw(velocity)
            effort = joint.scale.direction * current * ct.CURRENT_UNIT_MA / stall
            self.effort[joint.name] = max(-1.0, min(1.0, effort))
            self.moving[joint.name] = bool(moving)
            if error & ERRBIT_ALERT:
                alerts.append(joint)
            else:
                self.hardware_error[joint.name] = 0
        self.have_state = True
        problems = []
        for joint in alerts:
            bits = self._read1(joint, ct.ADDR_HARDWARE_ERROR_STATUS, "read hardware error status")
            self.hardware_error[joint.name] = bits
            if bits:
                problems.append(f"{self._label(joint)} hardware error: {ct.describe_hardware_error(bits)}")
        if problems:
            raise DynamixelHardwareError("; ".join(problems))

    def on_write(self, now: float) -> None:
        goals = GroupSyncWrite(self._port, self._packet, ct.ADDR_GOAL_POSITION, 4)
        velocities = GroupSyncWrite(self._port, self._packet, ct.ADDR_GOAL_VELOCITY, 4)
        for joint in self.joints:
            if joint.mode in ct.POSITION_MODES:
                value = self.command[joint.name]
                if joint.name not in self.unclamped:
                    value = min(joint.upper, max(joint.lower, value))
                ticks = joint.scale.to_ticks(value)
                goals.addParam(joint.dxl_id, list(struct.pack("<i", ticks)))
            else:
                raw = joint.scale.velocity_to_raw(self.command_velocity[joint.name])
                velocities.addParam(joint.dxl_id, list(struct.pack("<i", raw)))
        for group, what in ((goals, "sync write goal position"), (velocities, "sync write goal velocity")):
            if group.data_dict:

                def go(group: GroupSyncWrite = group) -> tuple[int, int, None]:
                    return group.txPacket(), 0, None

                self._transfer(what, go)

    # --- calibration support -----------------------------------------------------------------------------
    def set_zero_here(self, name: str, value_here: float) -> None:
        """Declare that the joint's present position reads ``value_here`` (limit-switch calibration)."""
        joint = self.by_name[name]
        joint.scale.zero_ticks = (
            joint.raw_ticks - joint.scale.direction * value_here * joint.scale.ticks_per_unit
        )
        self.position[name] = value_here
        self.command[name] = value_here

    def within_limits(self, name: str, value: float) -> bool:
        joint = self.by_name[name]
        return joint.lower <= value <= joint.upper and math.isfinite(value)


__all__ = ["DynamixelChainInterface", "DynamixelHardwareError", "DynamixelLinkError", "ServoJoint"]
