"""Emulated MightyZAP linear actuators daisy-chained on an IR-USB02 board, on a pseudo-terminal.

The IR serial protocol (MightyZAP manual):

* instruction ``FF FF FF | id | size | command | factors... | checksum`` with ``size`` = number of
  factors + 2 (command and checksum) and ``checksum = ~(id + size + command + factors) & 0xFF``;
* feedback ``FF FF FF | id | size | error | data... | checksum``, same size/checksum rules;
* commands: 0xF1 echo, 0xF2 load data (address, length), 0xF3 store data (address, data...),
  0xF4 send data (registered), 0xF5 execution, 0xF8 restart, 0x73 symmetric store (broadcast id
  0xFE: address, length per actuator, then ``id, data...`` per actuator).

Feedback Return Mode (address 0x10): 0 answers echo only, 1 answers echo and load data, 2 answers
every unicast command. Broadcasts are never answered. The error byte's bits: 0 input voltage,
1 stroke limit (goal outside the stroke limits), 4 checksum, 5 overload, 6 instruction.

Each actuator moves its rod towards Goal Position (0..4095 over the stroke) at a speed set by Goal
Speed (0..1023 of the maximum) while Force is on. An obstacle interval blocks the rod (the twin's
contact with the tower); pressing on it for ``overload_time_s`` latches the overload bit and
turns Force off, as the actuator's overload protection does. Faults for tests: :meth:`silence`,
:meth:`drop_link`, :meth:`corrupt_next` (wrong checksum on the next N replies).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

from tlt_sim.emulators.serial_chain import SerialChain

HEADER = b"\xff\xff\xff"
BROADCAST_ID = 0xFE
ECHO, LOAD, STORE, SEND, EXECUTE, RESTART, SYMMETRIC_STORE = 0xF1, 0xF2, 0xF3, 0xF4, 0xF5, 0xF8, 0x73

ERR_INPUT_VOLTAGE = 1 << 0
ERR_STROKE_LIMIT = 1 << 1
ERR_CHECKSUM = 1 << 4
ERR_OVERLOAD = 1 << 5
ERR_INSTRUCTION = 1 << 6

# Control table: address -> (name, size, writable)
ADDR_MODEL = 0x00
ADDR_FIRMWARE = 0x02
ADDR_ID = 0x03
ADDR_SHORT_LIMIT = 0x06
ADDR_LONG_LIMIT = 0x08
ADDR_RETURN_MODE = 0x10
ADDR_GOAL_SPEED = 0x15
ADDR_GOAL_CURRENT = 0x34
ADDR_FORCE = 0x80
ADDR_GOAL_POSITION = 0x86
ADDR_PRESENT_POSITION = 0x8C
ADDR_PRESENT_CURRENT = 0x8E
ADDR_MOVING = 0x96
TABLE = {
    ADDR_MODEL: ("model", 2, False),
    ADDR_FIRMWARE: ("firmware", 1, False),
    ADDR_ID: ("id", 1, True),
    ADDR_SHORT_LIMIT: ("short_limit", 2, True),
    ADDR_LONG_LIMIT: ("long_limit", 2, True),
    ADDR_RETURN_MODE: ("return_mode", 1, True),
    ADDR_GOAL_SPEED: ("goal_speed", 2, True),
    ADDR_GOAL_CURRENT: ("goal_current", 2, True),
    ADDR_FORCE: ("force", 1, True),
    ADDR_GOAL_POSITION: ("goal_position", 2, True),
    ADDR_PRESENT_POSITION: ("present_position", 2, False),
    ADDR_PRESENT_CURRENT: ("present_current", 2, False),
    ADDR_MOVING: ("moving", 1, False),
}
TABLE_SIZE = 0xA0


def checksum(body: bytes) -> int:
    """``~(sum of id, size, command/error and factors) & 0xFF``."""
    return ~sum(body) & 0xFF


def frame(dxl_id: int, first: int, factors: bytes = b"") -> bytes:
    """A packet: header, id, size, command (or error), factors, checksum."""
    body = bytes([dxl_id, len(factors) + 2, first]) + bytes(factors)
    return HEADER + body + bytes([checksum(body)])


class MightyZapActuator:
    """One actuator; positions in ticks (0..4095 over the stroke)."""

    MODEL = 0x0C1B  # an arbitrary model code this emulator reports
    FULL_SCALE = 4095

    def __init__(
        self,
        act_id: int,
        *,
        position: float = 0.0,
        full_speed_ticks_s: float = 4095 / 1.5,
        overload_time_s: float = 0.5,
    ) -> None:
        self.mem = bytearray(TABLE_SIZE)
        self.full_speed = full_speed_ticks_s
        self.overload_time_s = overload_time_s
        self.position = float(position)
        self.obstacle: tuple[float | None, float | None] = (None, None)
        self.error = 0
        self._pressing = 0.0
        self.registered: tuple[int, bytes] | None = None
        self._set(ADDR_MODEL, self.MODEL)
        self._set(ADDR_FIRMWARE, 13)
        self._set(ADDR_ID, act_id)
        self._set(ADDR_LONG_LIMIT, self.FULL_SCALE)
        self._set(ADDR_RETURN_MODE, 1)
        self._set(ADDR_GOAL_SPEED, 1023)
        self._set(ADDR_GOAL_CURRENT, 800)
        self._restart_ram()

    @property
    def act_id(self) -> int:
        return self.get(ADDR_ID)

    def get(self, address: int) -> int:
        size = TABLE[address][1]
        return int.from_bytes(self.mem[address : address + size], "little")

    def _set(self, address: int, value: int) -> None:
        size = TABLE[address][1]
        self.mem[address : address + size] = int(value).to_bytes(size, "little")

    def _restart_ram(self) -> None:
        self._set(ADDR_FORCE, 0)
        self._set(ADDR_GOAL_POSITION, round(self.position))
        self._refresh()

    def restart(self) -> None:
        self.error &= ~ERR_OVERLOAD
        self._pressing = 0.0
        self._restart_ram()

    def set_obstacle(self, lower: float | None = None, upper: float | None = None) -> None:
        self.obstacle = (lower, upper)

    def store(self, address: int, data: bytes) -> int:
        """Apply a write; returns error bits (0 when applied)."""
        if address not in TABLE or address + len(data) > TABLE_SIZE:
            return ERR_INSTRUCTION
        offset = 0
        while offset < len(data):
            entry = TABLE.get(address + offset)
            if entry is None or not entry[2] or offset + entry[1] > len(data):
                return ERR_INSTRUCTION
            value = int.from_bytes(data[offset : offset + entry[1]], "little")
            if address + offset == ADDR_GOAL_POSITION:
                low, high = self.get(ADDR_SHORT_LIMIT), self.get(ADDR_LONG_LIMIT)
                if not low <= value <= high:
                    return ERR_STROKE_LIMIT
            if address + offset == ADDR_FORCE and value and self.error & ERR_OVERLOAD:
                return ERR_OVERLOAD  # protection stays latched until a restart
            self._set(address + offset, value)
            offset += entry[1]
        return 0

    def load(self, address: int, length: int) -> bytes | None:
        if address + length > TABLE_SIZE or length < 1:
            return None
        self._refresh()
        return bytes(self.mem[address : address + length])

    def step(self, dt: float) -> None:
        if dt <= 0:
            return
        if not self.get(ADDR_FORCE):
            self._pressing = 0.0
            self._set(ADDR_PRESENT_CURRENT, 0)
            self._refresh()
            return
        goal = float(self.get(ADDR_GOAL_POSITION))
        speed = self.full_speed * max(1, self.get(ADDR_GOAL_SPEED)) / 1023.0
        move = max(-speed * dt, min(speed * dt, goal - self.position))
        target = self.position + move
        lower, upper = self.obstacle
        blocked = False
        if upper is not None and target > upper:
            target, blocked = (self.position if self.position > upper else upper), True
        if lower is not None and target < lower:
            target, blocked = (self.position if self.position < lower else lower), True
        self._set(ADDR_MOVING, int(abs(target - self.position) > 1e-6))
        self.position = target
        self._set(ADDR_PRESENT_CURRENT, self.get(ADDR_GOAL_CURRENT) if blocked else 60)
        self._pressing = self._pressing + dt if blocked else 0.0
        if self._pressing >= self.overload_time_s:
            self.error |= ERR_OVERLOAD
            self._set(ADDR_FORCE, 0)
        self._refresh()

    def _refresh(self) -> None:
        self._set(ADDR_PRESENT_POSITION, max(0, min(self.FULL_SCALE, round(self.position))))


class MightyZapChain(SerialChain):
    """Actuators on one IR-USB02 port; ``handle`` bytes in/out, ``start`` serves them on a pty."""

    PTY_NAME = "mightyzap-chain"

    def __init__(
        self,
        actuators: Iterable[MightyZapActuator] | Iterable[int],
        *,
        clock: Callable[[], float] | None = time.monotonic,
    ) -> None:
        self.actuators: dict[int, MightyZapActuator] = {}
        for act in actuators:
            act = act if isinstance(act, MightyZapActuator) else MightyZapActuator(int(act))
            self.actuators[act.act_id] = act
        super().__init__(clock)
        self._buf = bytearray()
        self.packets_seen = 0

    def actuator(self, act_id: int) -> MightyZapActuator:
        return self.actuators[act_id]

    def advance(self, dt: float) -> None:
        with self._lock:
            steps = max(1, min(2000, int(dt / self.MAX_STEP_S + 0.999)))
            for _ in range(steps):
                for act in self.actuators.values():
                    act.step(dt / steps)

    def handle(self, data: bytes) -> bytes:
        with self._lock:
            self.catch_up()
            self._buf.extend(data)
            out = bytearray()
            while True:
                start = self._buf.find(HEADER)
                if start < 0:
                    del self._buf[: max(0, len(self._buf) - 2)]
                    break
                del self._buf[:start]
                # skip extra FF bytes so "FF FF FF FF id" still finds the id
                while len(self._buf) > 3 and self._buf[3] == 0xFF:
                    del self._buf[:1]
                if len(self._buf) < 5:
                    break
                size = self._buf[4]
                total = 4 + size + 1
                if size < 2:
                    del self._buf[:1]
                    continue
                if len(self._buf) < total:
                    break
                packet = bytes(self._buf[:total])
                del self._buf[:total]
                self.packets_seen += 1
                reply = self._dispatch(packet)
                if reply is not None:
                    if self._corrupt_remaining > 0:
                        self._corrupt_remaining -= 1
                        reply = reply[:-1] + bytes([reply[-1] ^ 0x3C])
                    out += reply
            return bytes(out)

    def _answers(self, act_id: int) -> bool:
        return not self._link_dropped and act_id in self.actuators and act_id not in self._silenced

    def _dispatch(self, packet: bytes) -> bytes | None:
        act_id, command = packet[3], packet[5]
        factors = packet[6:-1]
        if act_id == BROADCAST_ID:
            if command == SYMMETRIC_STORE and checksum(packet[3:-1]) == packet[-1] and len(factors) >= 2:
                address, length = factors[0], factors[1]
                body = factors[2:]
                for offset in range(0, len(body) - length, length + 1):
                    if self._answers(body[offset]):
                        self.actuators[body[offset]].store(address, body[offset + 1 : offset + 1 + length])
            elif command == EXECUTE:
                for act in self.actuators.values():
                    self._execute(act)
            return None
        if not self._answers(act_id):
            return None
        act = self.actuators[act_id]
        mode = act.get(ADDR_RETURN_MODE)
        if checksum(packet[3:-1]) != packet[-1]:
            return frame(act_id, act.error | ERR_CHECKSUM) if mode == 2 else None
        error, data = 0, b""
        if command == ECHO:
            pass
        elif command == LOAD and len(factors) == 2:
            loaded = act.load(factors[0], factors[1])
            if loaded is None:
                error = ERR_INSTRUCTION
            else:
                data = loaded
        elif command == STORE and len(factors) >= 2:
            error = act.store(factors[0], factors[1:])
        elif command == SEND and len(factors) >= 2:
            act.registered = (factors[0], bytes(factors[1:]))
        elif command == EXECUTE:
            self._execute(act)
        elif command == RESTART:
            act.restart()
        else:
            error = ERR_INSTRUCTION
        answer = command == ECHO or (mode >= 1 and command == LOAD) or mode == 2
        return frame(act_id, act.error | error, data) if answer else None

    @staticmethod
    def _execute(act: MightyZapActuator) -> None:
        if act.registered is not None:
            address, data = act.registered
            act.registered = None
            act.store(address, data)


__all__ = ["ERR_OVERLOAD", "ERR_STROKE_LIMIT", "MightyZapActuator", "MightyZapChain", "checksum", "frame"]
