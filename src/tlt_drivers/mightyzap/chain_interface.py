"""Hardware interface of the Top Grippers: MightyZAP actuators daisy-chained on one IR-USB02 port (pyserial).

* ``configure`` opens the port, sends Echo to every actuator, sets its Feedback Return Mode (read
  back to confirm), goal speed and goal current, and restarts an actuator whose overload
  protection is latched.
* ``activate`` holds the present position and turns Force on (confirmed by reading it back).
* ``read`` loads Present Position and Present Current from each actuator; the feedback's error
  byte is kept per actuator in :attr:`hardware_error`; an overload or input-voltage error raises.
* ``write`` is one Symmetric Store of Goal Position to all actuators (broadcast, no feedback).

Every request that expects feedback waits at most ``comm.response_timeout_s`` and is retried
``comm.retries_per_transfer`` times on a timeout or a bad checksum before it raises, so the
interface enters ERROR within a bounded time. Positions are metres of stroke.
"""

from __future__ import annotations

import struct
import time
from typing import Any

import serial

from tlt_drivers.hardware_interface import JointGroupInterface
from tlt_drivers.mightyzap import protocol as mz


class MightyZapLinkError(RuntimeError):
    """A request got no valid feedback within its retry budget, or the port failed."""


class MightyZapFault(RuntimeError):
    """An actuator reported an error that stops it (overload, input voltage)."""


class MightyZapChainInterface(JointGroupInterface):
    """State: :attr:`position` (m), :attr:`current` (raw), :attr:`hardware_error` per actuator.
    Command: :attr:`command` (m)."""

    def __init__(self, config: dict[str, Any]) -> None:
        super().__init__(config["component"])
        self.config = config
        self.actuators = list(config["actuators"])
        self.by_name = {a["name"]: a for a in self.actuators}
        names = [a["name"] for a in self.actuators]
        self.position = dict.fromkeys(names, 0.0)
        self.current = dict.fromkeys(names, 0)
        self.hardware_error = dict.fromkeys(names, 0)
        self.command = dict.fromkeys(names, 0.0)
        self.retries = 0
        self.link_ok = False
        self.have_state = False
        self._serial: serial.Serial | None = None
        self._return_mode: dict[int, int] = {}
        self._ticks_per_m = config["full_stroke_ticks"] / config["stroke_m"]

    @property
    def joint_names(self) -> list[str]:
        return [a["name"] for a in self.actuators]

    def to_ticks(self, metres: float) -> int:
        return max(0, min(self.config["full_stroke_ticks"], round(metres * self._ticks_per_m)))

    def from_ticks(self, ticks: int) -> float:
        return ticks / self._ticks_per_m

    @staticmethod
    def _label(act: dict[str, Any]) -> str:
        return f"actuator {act['name']!r} (id {act['id']})"

    # --- transport ------------------------------------------------------------------------------------
    def _exchange(self, packet: bytes, data_len: int | None) -> mz.Feedback | None:
        """Send one packet; when ``data_len`` is not None, wait for feedback with that much data."""
        ser = self._serial
        if ser is None:
            raise MightyZapLinkError("port is not open")
        try:
            ser.reset_input_buffer()
            ser.write(packet)
            ser.flush()
            if data_len is None:
                return None
            need = 7 + data_len
            deadline = time.monotonic() + self.config["comm"]["response_timeout_s"]
            buf = bytearray()
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError(
                        "no feedback" if not buf else f"incomplete feedback {bytes(buf).hex(' ')}"
                    )
                ser.timeout = remaining
                chunk = ser.read(max(1, need - len(buf)))
                buf += chunk
                start = buf.find(mz.HEADER)
                if start > 0:
                    del buf[:start]
                if len(buf) >= need and buf[:3] == mz.HEADER:
                    return mz.parse_feedback(bytes(buf[:need]))
        except serial.SerialException as exc:
            raise MightyZapLinkError(f"serial port failed: {exc}") from exc

    def _request(self, act: dict[str, Any], command: int, factors: bytes, data_len: int | None, what: str):
        packet = mz.instruction(act["id"], command, factors)
        last = ""
        budget = self.config["comm"]["retries_per_transfer"]
        for attempt in range(budget + 1):
            try:
                feedback = self._exchange(packet, data_len)
            except (TimeoutError, mz.FeedbackError) as exc:
                last = str(exc)
                if attempt < budget:
                    self.retries += 1
                continue
            if feedback is not None:
                if feedback.act_id != act["id"]:
                    last = f"feedback from id {feedback.act_id}"
                    continue
                if feedback.error & (1 << 4) and attempt < budget:  # our packet was garbled on the way
                    self.retries += 1
                    continue
                self.hardware_error[act["name"]] = feedback.error
            self.link_ok = True
            return feedback
        self.link_ok = False
        raise MightyZapLinkError(f"{self._label(act)}: {what}: {last} (after {budget + 1} attempts)")

    def _load(self, act: dict[str, Any], address: int, length: int, what: str) -> mz.Feedback:
        return self._request(act, mz.CMD_LOAD_DATA, bytes([address, length]), length, what)

    def _store(self, act: dict[str, Any], address: int, data: bytes, what: str) -> None:
        expect = 0 if self._return_mode.get(act["id"], 0) == 2 else None
        feedback = self._request(act, mz.CMD_STORE_DATA, bytes([address]) + data, expect, what)
        if feedback is not None and feedback.error & ~mz.FAULT_BITS:
            raise MightyZapFault(f"{self._label(act)}: {what} refused: {mz.describe_error(feedback.error)}")

    # --- lifecycle hooks -------------------------------------------------------------------------------
    def on_configure(self) -> None:
        try:
            self._serial = serial.Serial(self.config["port"], self.config["baudrate"], timeout=0.01)
        except (serial.SerialException, OSError) as exc:
            raise MightyZapLinkError(f"cannot open {self.config['port']}: {exc}") from exc
        self._return_mode = {}
        want = self.config["feedback_return_mode"]
        for act in self.actuators:
            self._request(act, mz.CMD_ECHO, b"", 0, "echo")
            if self.hardware_error[act["name"]] & mz.FAULT_BITS:
                self._log.warning(
                    "%s: restarting %s: %s",
                    self.name,
                    self._label(act),
                    mz.describe_error(self.hardware_error[act["name"]]),
                )
                self._request(act, mz.CMD_RESTART, b"", None, "restart")
                self._request(act, mz.CMD_ECHO, b"", 0, "echo after restart")
                if self.hardware_error[act["name"]] & mz.FAULT_BITS:
                    raise MightyZapFault(
                        f"{self._label(act)}: {mz.describe_error(self.hardware_error[act['name']])}"
                    )
            try:
                mode = self._load(act, mz.ADDR_FEEDBACK_RETURN_MODE, 1, "read feedback return mode").data[0]
            except MightyZapLinkError:
                mode = 0  # mode 0 answers only Echo, so a silent read after a good echo means mode 0
            self._return_mode[act["id"]] = mode
            if mode != want:
                self._store(act, mz.ADDR_FEEDBACK_RETURN_MODE, bytes([want]), "set feedback return mode")
                self._return_mode[act["id"]] = want
                got = self._load(act, mz.ADDR_FEEDBACK_RETURN_MODE, 1, "read feedback return mode").data[0]
                if got != want:
                    raise MightyZapLinkError(f"{self._label(act)}: feedback return mode stays {got}")
            self._store(
                act, mz.ADDR_GOAL_SPEED, struct.pack("<H", self.config["goal_speed"]), "set goal speed"
            )
            self._store(
                act, mz.ADDR_GOAL_CURRENT, struct.pack("<H", self.config["goal_current"]), "set goal current"
            )
        self.link_ok = True

    def on_activate(self) -> None:
        for act in self.actuators:
            ticks = struct.unpack("<H", self._load(act, mz.ADDR_PRESENT_POSITION, 2, "read position").data)[0]
            self.position[act["name"]] = self.from_ticks(ticks)
            self.command[act["name"]] = self.position[act["name"]]
            self._store(act, mz.ADDR_GOAL_POSITION, struct.pack("<H", ticks), "hold present position")
            self._store(act, mz.ADDR_FORCE_ON_OFF, b"\x01", "force on")
            force = self._load(act, mz.ADDR_FORCE_ON_OFF, 1, "read force").data[0]
            if force != 1:
                raise MightyZapFault(
                    f"{self._label(act)}: force stays off: "
                    f"{mz.describe_error(self.hardware_error[act['name']])}"
                )
        self.have_state = True

    def on_deactivate(self) -> None:
        for act in self.actuators:
            self._store(act, mz.ADDR_FORCE_ON_OFF, b"\x00", "force off")

    def on_cleanup(self) -> None:
        ser, self._serial = self._serial, None
        self.link_ok = False
        if ser is not None:
            ser.close()

    def on_read(self, now: float) -> None:
        problems = []
        for act in self.actuators:
            feedback = self._load(act, mz.ADDR_PRESENT_POSITION, 4, "read present position")
            ticks, current = struct.unpack("<HH", feedback.data)
            self.position[act["name"]] = self.from_ticks(ticks)
            self.current[act["name"]] = current
            if feedback.error & mz.FAULT_BITS:
                problems.append(f"{self._label(act)}: {mz.describe_error(feedback.error)}")
        self.have_state = True
        if problems:
            raise MightyZapFault("; ".join(problems))

    def on_write(self, now: float) -> None:
        body = bytearray([mz.ADDR_GOAL_POSITION, 2])
        for act in self.actuators:
            value = min(act["upper"], max(act["lower"], self.command[act["name"]]))
            body += bytes([act["id"]]) + struct.pack("<H", self.to_ticks(value))
        try:
            self._exchange(mz.instruction(mz.BROADCAST_ID, mz.CMD_SYMMETRIC_STORE, bytes(body)), None)
        except OSError as exc:
            raise MightyZapLinkError(f"symmetric store failed: {exc}") from exc


__all__ = ["MightyZapChainInterface", "MightyZapFault", "MightyZapLinkError"]
