"""An emulated Dynamixel chain (U2D2 + MX-106(2.0) servos) answering Protocol 2.0 on a pseudo-terminal.

What it reads: instruction packets the driver writes on the pty slave. What it writes: status
packets exactly as the servos would, one per addressed servo, honouring the Status Return Level.
Instructions: PING (unicast and broadcast), READ, WRITE, REG_WRITE, ACTION, REBOOT, SYNC_READ,
SYNC_WRITE, BULK_READ, BULK_WRITE. A packet with a bad CRC is answered with the CRC error number by
the addressed servo; an unknown instruction with the instruction error. The alert bit (0x80) of the
error byte is set while a servo has a hardware error latched.

Servo motion advances lazily to ``clock()`` whenever a packet arrives (inject a fake clock in tests,
or pass ``clock=None`` and call :meth:`advance` from the twin's physics step).

Injected faults (all thread-safe, all reversible): :meth:`silence` a servo (it stops answering),
:meth:`drop_link` (nothing answers, as with a pulled cable), :meth:`corrupt_next` (the next N
status packets carry a wrong CRC), hardware error bits and overload through the servo objects.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable, Iterable

from tlt_sim.emulators import dynamixel_protocol as proto
from tlt_sim.emulators.dynamixel_servo import DynamixelServo, ServoError
from tlt_sim.emulators.serial_chain import SerialChain


class DynamixelChain(SerialChain):
    """Servos on one bus; answer packets with :meth:`handle`, or serve them on a pty with :meth:`start`."""

    PTY_NAME = "dynamixel-chain"
    REBOOT_TIME_S = 0.05

    def __init__(
        self,
        servos: Iterable[DynamixelServo] | Iterable[int],
        *,
        clock: Callable[[], float] | None = time.monotonic,
    ) -> None:
        self.servos: dict[int, DynamixelServo] = {}
        for servo in servos:
            servo = servo if isinstance(servo, DynamixelServo) else DynamixelServo(int(servo))
            self.servos[servo.dxl_id] = servo
        super().__init__(clock)
        self._parser = proto.PacketParser()
        self._rebooting_until: dict[int, float] = {}
        self._pending_reboots: list[DynamixelServo] = []
        self._elapsed = 0.0
        self.packets_seen = 0
        self.crc_errors_seen = 0

    # --- physical side --------------------------------------------------------------------------------
    def servo(self, dxl_id: int) -> DynamixelServo:
        return self.servos[dxl_id]

    def advance(self, dt: float) -> None:
        """Step every servo by ``dt`` seconds (in sub-steps of at most 5 ms)."""
        with self._lock:
            steps = max(1, min(2000, int(dt / self.MAX_STEP_S + 0.999)))
            for k in range(steps):
                last = k == steps - 1  # the present-value registers only need the final state
                for servo in self.servos.values():
                    servo.step(dt / steps, refresh=last)
            self._elapsed += dt

    # --- protocol ---------------------------------------------------------------------------------
    def handle(self, data: bytes) -> bytes:
        """Bytes from the driver in, bytes of the status packets out."""
        with self._lock:
            self.catch_up()
            out = bytearray()
            for packet in self._parser.feed(data):
                self.packets_seen += 1
                for dxl_id, error, params in self._dispatch(packet):
                    if not self._answers(dxl_id):
                        continue
                    servo = self.servos[dxl_id]
                    if servo.alert:
                        error |= proto.ERR_ALERT
                    status = bytearray(proto.build_status(dxl_id, error, params))
                    if self._corrupt_remaining > 0:
                        self._corrupt_remaining -= 1
                        status[-1] ^= 0x5A
                    out += status
                for servo in self._pending_reboots:
                    servo.reboot()
                    self._rebooting_until[servo.dxl_id] = self._elapsed + self.REBOOT_TIME_S
                self._pending_reboots.clear()
            return bytes(out)

    def _answers(self, dxl_id: int) -> bool:
        if self._link_dropped or dxl_id in self._silenced or dxl_id not in self.servos:
            return False
        until = self._rebooting_until.get(dxl_id)
        return until is None or self._elapsed >= until

    def _replies(self, servo: DynamixelServo, instruction: int) -> bool:
        level = servo.get("status_return_level")
        return instruction == proto.PING or level >= 2 or (level == 1 and instruction == proto.READ)

    def _dispatch(self, packet: proto.Packet) -> list[tuple[int, int, bytes]]:
        """(id, error, params) of each status packet the servos send for ``packet``."""
        if not packet.crc_ok:
            self.crc_errors_seen += 1
            if packet.dxl_id in self.servos:
                return [(packet.dxl_id, proto.ERR_CRC, b"")]
            return []
        ins, params = packet.instruction, packet.params
        if packet.dxl_id == proto.BROADCAST_ID:
            return self._broadcast(ins, params)
        servo = self.servos.get(packet.dxl_id)
        if servo is None or not self._answers(packet.dxl_id):
            return []  # nobody with that id on the bus, or it cannot hear
        reply = self._unicast(servo, ins, params)
        if reply is None or not self._replies(servo, ins):
            return []
        return [(servo.dxl_id, *reply)]

    def _unicast(self, servo: DynamixelServo, ins: int, params: bytes) -> tuple[int, bytes] | None:
        try:
            if ins == proto.PING:
                return 0, struct.pack("<HB", servo.get("model_number"), servo.get("firmware_version"))
            if ins == proto.READ:
                if len(params) != 4:
                    return proto.ERR_DATA_LENGTH, b""
                address, length = struct.unpack("<HH", params)
                return 0, servo.read(address, length)
            if ins == proto.WRITE:
                if len(params) < 3:
                    return proto.ERR_DATA_LENGTH, b""
                servo.write(struct.unpack_from("<H", params)[0], params[2:])
                return 0, b""
            if ins == proto.REG_WRITE:
                if len(params) < 3:
                    return proto.ERR_DATA_LENGTH, b""
                address = struct.unpack_from("<H", params)[0]
                servo.check_write(address, params[2:])
                servo.registered = (address, params[2:])
                return 0, b""
            if ins == proto.ACTION:
                self._action(servo)
                return 0, b""
            if ins == proto.REBOOT:
                # The status goes out first; then the servo restarts and is deaf for a moment.
                self._pending_reboots.append(servo)
                return 0, b""
            return proto.ERR_INSTRUCTION, b""
        except ServoError as exc:
            return exc.code, b""

    @staticmethod
    def _action(servo: DynamixelServo) -> None:
        if servo.registered is not None:
            address, data = servo.registered
            servo.registered = None
            servo.write(address, data)

    def _broadcast(self, ins: int, params: bytes) -> list[tuple[int, int, bytes]]:
        replies: list[tuple[int, int, bytes]] = []
        if ins == proto.PING:
            for dxl_id in sorted(self.servos):
                if self._answers(dxl_id):
                    replies.append((dxl_id, *self._unicast(self.servos[dxl_id], ins, params)))
        elif ins == proto.ACTION:
            for dxl_id, servo in self.servos.items():
                if self._answers(dxl_id):
                    try:
                        self._action(servo)
                    except ServoError:
                        pass  # no status for a broadcast; the write just does not happen
        elif ins == proto.SYNC_READ and len(params) >= 4:
            address, length = struct.unpack_from("<HH", params)
            for dxl_id in params[4:]:
                servo = self.servos.get(dxl_id)
                if servo is None or not self._answers(dxl_id):
                    continue
                try:
                    replies.append((dxl_id, 0, servo.read(address, length)))
                except ServoError as exc:
                    replies.append((dxl_id, exc.code, b""))
        elif ins == proto.SYNC_WRITE and len(params) >= 4:
            address, length = struct.unpack_from("<HH", params)
            body = params[4:]
            for offset in range(0, len(body) - length, length + 1):
                self._silent_write(body[offset], address, body[offset + 1 : offset + 1 + length])
        elif ins == proto.BULK_READ:
            for offset in range(0, len(params) - 4, 5):
                dxl_id, address, length = struct.unpack_from("<BHH", params, offset)
                servo = self.servos.get(dxl_id)
                if servo is None or not self._answers(dxl_id):
                    continue
                try:
                    replies.append((dxl_id, 0, servo.read(address, length)))
                except ServoError as exc:
                    replies.append((dxl_id, exc.code, b""))
        elif ins == proto.BULK_WRITE:
            offset = 0
            while offset + 5 <= len(params):
                dxl_id, address, length = struct.unpack_from("<BHH", params, offset)
                self._silent_write(dxl_id, address, params[offset + 5 : offset + 5 + length])
                offset += 5 + length
        return replies

    def _silent_write(self, dxl_id: int, address: int, data: bytes) -> None:
        servo = self.servos.get(dxl_id)
        if servo is None or not self._answers(dxl_id):
            return
        try:
            servo.write(address, data)
        except ServoError:
            pass  # sync/bulk writes have no status packet; a refused write is simply not applied


__all__ = ["DynamixelChain"]
