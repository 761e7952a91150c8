"""An emulated UR10e controller on TCP that the real ``ur-rtde`` library talks to.

It serves the three ports ``ur-rtde`` uses, on one host address:

* dashboard (29999): a banner on connect, then one text line answered per request line
  (``PolyscopeVersion``, ``get serial number``, ``is in remote control``, ``stop``, ``play``,
  ``unlock protective stop``, ``robotmode``, ``safetymode``, ``programState``, ...);
* RTDE (30004): protocol version, URControl version, output and input recipes answered with
  types from :mod:`tlt_sim.emulators.rtde_wire`, START/PAUSE, and once started a data package
  per client at the frequency the client asked for (500 Hz for an e-Series);
* script (30003): a URScript program arrives as text; its closing top-level ``end`` starts it.
  The program is modelled by :class:`ControlScript` (ur-rtde's register command protocol). It
  runs while the socket it came on stays open: closing that socket stops the program.

One controller thread runs at ``tick_hz``: it advances the arm (with the wall clock, or not at
all when ``clock="external"`` and the twin calls :meth:`advance`), runs one cycle of the program,
and streams. Two arms need two emulators on two loopback addresses (127.0.0.2, 127.0.0.3): the
ports are fixed by the protocol.

Injected faults: :meth:`set_no_answer` (every port goes silent: nothing is read or sent until
cleared, so a pending request is answered late, not lost), :meth:`protective_stop`,
:meth:`drop_link` (all sockets closed and new connections refused until :meth:`restore_link`),
:meth:`stop_program`.

Its configuration (address, version, initial joints, faults present from the start) is
``config/sim/ur_x_controller.yaml`` / ``ur_y_controller.yaml``; run one from a shell with
``python -m tlt_sim.emulators.ur_controller --config config/sim/ur_x_controller.yaml``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import re
import socket
import struct
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from tlt_common.config_schema import Field, load_validated, opt
from tlt_sim.emulators import rtde_wire as wire
from tlt_sim.emulators.ur_arm import HOME, UR10eArm
from tlt_sim.emulators.ur_control_script import ControlScript, Registers

log = logging.getLogger("tlt.sim.ur")

# RTDE enumerations (UR RTDE guide).
ROBOT_MODE_RUNNING = 7
JOINT_MODE_RUNNING = 253
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
SAFETY_BIT_NORMAL = 1 << 0
SAFETY_BIT_PROTECTIVE_STOP = 1 << 2
SAFETY_BIT_STOPPED_DUE_TO_SAFETY = 1 << 10
ROBOT_BIT_POWER_ON = 1 << 0
ROBOT_BIT_PROGRAM_RUNNING = 1 << 1


def _zero(kind: str) -> object:
    if kind.startswith("VECTOR"):
        return [0.0 if kind.endswith("D") else 0] * int(kind[6])
    return 0.0 if kind == "DOUBLE" else (False if kind == "BOOL" else 0)


# Variables the emulator has no model for read as zero of their type, never NOT_FOUND.
_DEFAULTS = {name: _zero(kind) for name, kind in wire.OUTPUT_TYPES.items()}

_OFFSET = re.compile(r"global\s+reg_offset_int\s*=\s*(\d+)")


@dataclass
class URControllerConfig:
    """Where and what the emulated controller is."""

    host: str = "127.0.0.1"
    dashboard_port: int = 29999
    rtde_port: int = 30004
    script_port: int = 30003
    version: tuple[int, int, int, int] = (5, 11, 0, 108249)
    serial_number: str = "20235500001"
    remote_control: bool = True
    unlock_delay_s: float = 5.0  # the controller refuses an unlock this soon after the stop
    tick_hz: float = 500.0
    clock: str = "internal"  # "internal": wall time steps the arm; "external": advance(dt) does
    q0: Sequence[float] = field(default_factory=lambda: list(HOME))
    # Faults present from the start (tests inject more through the emulator's methods).
    fault_no_answer: bool = False
    fault_protective_stop: bool = False
    fault_link_down: bool = False


CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "sim"


def _six(values: list) -> str | None:
    return None if len(values) == 6 else f"expected 6 joint values, got {len(values)}"


CONFIG_SCHEMA = {
    "host": Field("str", doc="loopback address of this arm's controller"),
    "version": opt(
        "list",
        [5, 11, 0, 108249],
        item=Field("int", minimum=0),
        check=lambda v: None if len(v) == 4 else "expected [major, minor, bugfix, build]",
    ),
    "serial_number": opt("str", "20235500001"),
    "remote_control": opt("bool", True),
    "unlock_delay_s": opt("float", 5.0, minimum=0.0),
    "tick_hz": opt("float", 500.0, minimum=10.0, maximum=1000.0),
    "clock": opt("str", "internal", choices=("internal", "external")),
    "q0": opt("list", list(HOME), item=Field("float"), check=_six),
    "faults": opt(
        "dict",
        {"no_answer": False, "protective_stop": False, "link_down": False},
        schema={
            "no_answer": opt("bool", False),
            "protective_stop": opt("bool", False),
            "link_down": opt("bool", False),
        },
    ),
}


def load_controller_config(path: str | Path) -> URControllerConfig:
    """Load ``config/sim/ur_<arm>_controller.yaml``; ``ConfigError`` names file, key and reason."""
    doc = load_validated(path, CONFIG_SCHEMA)
    faults = doc.pop("faults")
    return URControllerConfig(
        **{k: v for k, v in doc.items() if k != "version"},
        version=tuple(doc["version"][:4]),
        fault_no_answer=faults["no_answer"],
        fault_protective_stop=faults["protective_stop"],
        fault_link_down=faults["link_down"],
    )


class _Connection:
    """One accepted socket with a send lock (replies and streamed data share it)."""

    def __init__(self, sock: socket.socket, kind: str) -> None:
        self.sock = sock
        self.kind = kind
        self.send_lock = threading.Lock()
        self.closed = False
        # RTDE only
        self.output: wire.Recipe | None = None
        self.inputs: dict[int, wire.Recipe] = {}
        self.period = 0.002
        self.next_send = 0.0
        self.started = False

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self.sock.sendall(data)

    def close(self) -> None:
        self.closed = True
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self.sock.close()


class URControllerEmulator:
    """A UR controller: dashboard, RTDE and script servers around one :class:`UR10eArm`.

    Use as a context manager or call :meth:`start` / :meth:`close`. ``arm`` is the plain joint
    state the twin reads and drives.
    """

    def __init__(self, config: URControllerConfig | None = None, arm: UR10eArm | None = None) -> None:
        self.config = config or URControllerConfig()
        self.arm = arm or UR10eArm(self.config.q0)
        self.registers = Registers()
        self.program: ControlScript | None = None
        self.program_text = ""
        self.scripts_received = 0
        self.unknown_names: list[str] = []
        self.protective_stopped = False
        self.protective_stop_reason = ""
        self._protective_since = 0.0
        self._program_conn: _Connection | None = None
        self._lock = threading.RLock()
        self._answering = threading.Event()
        self._answering.set()
        self._link_up = True
        self._stop = threading.Event()
        self._listeners: list[socket.socket] = []
        self._connections: list[_Connection] = []
        self._threads: list[threading.Thread] = []
        self._t0 = time.monotonic()
        self._sim_time = 0.0
        self._last_step = time.monotonic()

    # --- lifecycle ---------------------------------------------------------------------------
    def start(self) -> URControllerEmulator:
        c = self.config
        if c.fault_link_down:
            self._link_up = False
        else:
            self._open_listeners()
        self.set_no_answer(c.fault_no_answer)
        if c.fault_protective_stop:
            self.protective_stop("configured fault")
        self._spawn(self._tick_loop, "tick")
        return self

    def close(self) -> None:
        self._stop.set()
        self._answering.set()
        self._close_all()
        for t in self._threads:
            t.join(timeout=2.0)

    def __enter__(self) -> URControllerEmulator:
        return self if self._threads else self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _spawn(self, target, name: str, *args) -> None:
        t = threading.Thread(target=target, args=args, name=f"ur-emu-{self.config.host}-{name}", daemon=True)
        self._threads = [x for x in self._threads if x.is_alive()]
        self._threads.append(t)
        t.start()

    def _open_listeners(self) -> None:
        c = self.config
        for port, kind in ((c.dashboard_port, "dashboard"), (c.rtde_port, "rtde"), (c.script_port, "script")):
            srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            deadline = time.monotonic() + 2.0
            while True:
                try:
                    srv.bind((c.host, port))
                    break
                except OSError:
                    # After drop_link the old listener is released once its accept() returns.
                    if time.monotonic() > deadline:
                        srv.close()
                        raise
                    time.sleep(0.05)
            srv.listen(8)
            srv.settimeout(0.2)
            self._listeners.append(srv)
            self._spawn(self._accept_loop, f"accept-{kind}", srv, kind)

    def _close_all(self) -> None:
        for srv in self._listeners:
            with contextlib.suppress(OSError):
                srv.close()
        self._listeners = []
        with self._lock:
            conns, self._connections = self._connections, []
        for conn in conns:
            conn.close()

    # --- faults ----------------------------------------------------------------------------------
    def set_no_answer(self, silent: bool) -> None:
        """Go silent on every port (``True``) or answer again (``False``)."""
        if silent:
            self._answering.clear()
        else:
            self._answering.set()

    def protective_stop(self, reason: str = "injected protective stop") -> None:
        """Enter a protective stop: the arm halts and the program stops."""
        with self._lock:
            if not self.protective_stopped:
                log.warning("%s: protective stop: %s", self.config.host, reason)
            self.protective_stopped = True
            self.protective_stop_reason = reason
            self._protective_since = time.monotonic()
            self.arm.halt()
            if self.program is not None:
                self.program.abort(f"protective stop: {reason}")

    def unlock_protective_stop(self) -> str:
        """What the dashboard's ``unlock protective stop`` does; returns its answer."""
        with self._lock:
            if not self.protective_stopped:
                return "Protective stop releasing"
            if time.monotonic() - self._protective_since < self.config.unlock_delay_s:
                return (
                    "Cannot unlock protective stop until 5s after occurrence. "
                    "Always inspect cause of protective stop before unlocking"
                )
            self.protective_stopped = False
            self.protective_stop_reason = ""
            return "Protective stop releasing"

    def drop_link(self) -> None:
        """Close every socket and refuse connections until :meth:`restore_link`."""
        self._link_up = False
        self._close_all()
        self.stop_program("link dropped")

    def restore_link(self) -> None:
        if not self._link_up:
            self._link_up = True
            self._open_listeners()

    def stop_program(self, reason: str = "program stopped") -> None:
        with self._lock:
            if self.program is not None:
                self.program.abort(reason)
                self.arm.stop(10.0)

    # --- state ---------------------------------------------------------------------------------
    @property
    def program_running(self) -> bool:
        prog = self.program
        return prog is not None and prog.running

    @property
    def runtime_state(self) -> int:
        return RUNTIME_PLAYING if self.program_running else RUNTIME_STOPPED

    def safety_status_bits(self) -> int:
        if self.protective_stopped:
            return SAFETY_BIT_PROTECTIVE_STOP | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
        return SAFETY_BIT_NORMAL

    def advance(self, dt: float) -> None:
        """Step the arm by ``dt`` seconds of simulated time (``clock="external"``)."""
        self._sim_time += dt
        self.arm.step(dt)

    def timestamp(self) -> float:
        if self.config.clock == "external":
            return self._sim_time
        return time.monotonic() - self._t0

    def _outputs(self) -> dict[str, object]:
        """Every output variable's current value, by RTDE name."""
        arm = self.arm
        q, qd = arm.positions(), arm.velocities()
        tcp = arm.tcp_pose()
        target_q = arm.target_q.tolist()
        robot_bits = ROBOT_BIT_POWER_ON | (ROBOT_BIT_PROGRAM_RUNNING if self.program_running else 0)
        zeros6 = [0.0] * 6
        values: dict[str, object] = dict(_DEFAULTS)
        values.update(
            {
                "timestamp": self.timestamp(),
                "target_q": target_q,
                "target_qd": qd,
                "target_qdd": zeros6,
                "target_current": zeros6,
                "target_moment": zeros6,
                "actual_q": q,
                "actual_qd": qd,
                "actual_qdd": zeros6,
                "actual_current": zeros6,
                "actual_current_window": zeros6,
                "actual_moment": zeros6,
                "joint_control_output": zeros6,
                "actual_TCP_pose": tcp,
                "actual_TCP_speed": zeros6,
                "actual_TCP_force": zeros6,
                "target_TCP_pose": tcp,
                "target_TCP_speed": zeros6,
                "actual_digital_input_bits": 0,
                "joint_temperatures": [30.0] * 6,
                "actual_execution_time": 0.2,
                "robot_mode": ROBOT_MODE_RUNNING,
                "joint_mode": [JOINT_MODE_RUNNING] * 6,
                "safety_mode": SAFETY_MODE_PROTECTIVE_STOP if self.protective_stopped else SAFETY_MODE_NORMAL,
                "safety_status": SAFETY_MODE_PROTECTIVE_STOP
                if self.protective_stopped
                else SAFETY_MODE_NORMAL,
                "actual_tool_accelerometer": [0.0, 0.0, 9.81],
                "speed_scaling": 1.0,
                "target_speed_fraction": 1.0,
                "actual_momentum": 0.0,
                "actual_main_voltage": 48.0,
                "actual_robot_voltage": 48.0,
                "actual_robot_current": 0.5,
                "actual_joint_voltage": [48.0] * 6,
                "actual_digital_output_bits": 0,
                "runtime_state": self.runtime_state,
                "elbow_position": [0.0, 0.0, 0.0],
                "elbow_velocity": [0.0, 0.0, 0.0],
                "robot_status_bits": robot_bits,
                "safety_status_bits": self.safety_status_bits(),
                "payload": self.program.payload[0] if self.program else 0.0,
                "payload_cog": self.program.payload[1] if self.program else [0.0, 0.0, 0.0],
                "payload_inertia": zeros6,
                "ft_raw_wrench": zeros6,
                "script_control_line": 0,
            }
        )
        return values

    # --- controller cycle ------------------------------------------------------------------------
    def _tick_loop(self) -> None:
        period = 1.0 / self.config.tick_hz
        next_tick = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now < next_tick:
                time.sleep(next_tick - now)
                continue
            next_tick += period
            if next_tick < now - 10 * period:  # fell far behind (loaded machine): do not burst
                next_tick = now + period
            try:
                self._cycle(now)
            except Exception:  # the controller must keep running whatever a cycle hit
                log.exception("%s: controller cycle failed", self.config.host)

    def _cycle(self, now: float) -> None:
        if self.config.clock == "internal":
            self.arm.step(min(now - self._last_step, 0.05))
        self._last_step = now
        if self.arm.fault:
            fault, self.arm.fault = self.arm.fault, ""
            if self.program is not None:
                self.program.abort(fault)
        if self.program is not None:
            self.program.tick()
        if not self._answering.is_set():
            return
        with self._lock:
            streaming = [c for c in self._connections if c.kind == "rtde" and c.started and not c.closed]
        if not streaming:
            return
        values = None
        for conn in streaming:
            if now < conn.next_send:
                continue
            conn.next_send = max(conn.next_send + conn.period, now - conn.period)
            if values is None:
                values = self._outputs()
                with self.registers.lock:
                    for i in range(48):
                        values[f"output_int_register_{i}"] = self.registers.out_int[i]
                        values[f"output_double_register_{i}"] = self.registers.out_double[i]
                        values[f"input_int_register_{i}"] = self.registers.in_int[i]
                        values[f"input_double_register_{i}"] = self.registers.in_double[i]
            try:
                conn.send(wire.frame(wire.DATA_PACKAGE, conn.output.pack(values)))
            except (OSError, KeyError, struct.error) as exc:
                log.info("%s: stream to a client ended: %s", self.config.host, exc)
                self._drop(conn)

    # --- connections ---------------------------------------------------------------------------
    def _accept_loop(self, srv: socket.socket, kind: str) -> None:
        while not self._stop.is_set():
            try:
                sock, _ = srv.accept()
            except TimeoutError:
                continue
            except OSError:
                return  # listener closed (link dropped or emulator closed)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.settimeout(None)
            # A client that stops reading must not stall the controller thread's sends: after
            # 1 s a send fails (reads stay blocking) and that client is dropped.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, struct.pack("ll", 1, 0))
            conn = _Connection(sock, kind)
            with self._lock:
                self._connections.append(conn)
            handler = {
                "dashboard": self._serve_dashboard,
                "rtde": self._serve_rtde,
                "script": self._serve_script,
            }
            self._spawn(handler[kind], f"{kind}-conn", conn)

    def _drop(self, conn: _Connection) -> None:
        conn.close()
        with self._lock:
            if conn in self._connections:
                self._connections.remove(conn)
            if conn is self._program_conn and self.program is not None:
                self._program_conn = None
                self.program.abort("the script connection closed")
                self.arm.stop(10.0)

    def _wait_answering(self) -> None:
        while not self._answering.wait(0.1):
            if self._stop.is_set():
                return

    def _serve_rtde(self, conn: _Connection) -> None:
        try:
            while not self._stop.is_set() and not conn.closed:
                kind, payload = wire.read_message(conn.sock)
                self._wait_answering()
                self._handle_rtde(conn, kind, payload)
        except (OSError, ConnectionError, wire.ProtocolError) as exc:
            log.debug("%s: RTDE client left: %s", self.config.host, exc)
        finally:
            self._drop(conn)

    def _handle_rtde(self, conn: _Connection, kind: int, payload: bytes) -> None:
        if kind == wire.REQUEST_PROTOCOL_VERSION:
            conn.send(wire.frame(kind, b"\x01"))
        elif kind == wire.GET_URCONTROL_VERSION:
            conn.send(wire.frame(kind, struct.pack(">IIII", *self.config.version)))
        elif kind == wire.SETUP_OUTPUTS:
            (frequency,) = struct.unpack(">d", payload[:8])
            recipe = wire.Recipe(1, wire.parse_names(payload[8:]), wire.OUTPUT_TYPES)
            if recipe.unknown:
                log.error("%s: unknown output names %s", self.config.host, recipe.unknown)
                self.unknown_names.extend(recipe.unknown)
            conn.output = recipe
            conn.period = 1.0 / frequency if frequency > 0 else 1.0 / self.config.tick_hz
            conn.send(wire.frame(kind, recipe.answer()))
        elif kind == wire.SETUP_INPUTS:
            recipe = wire.Recipe(len(conn.inputs) + 1, wire.parse_names(payload), wire.INPUT_TYPES)
            if recipe.unknown:
                self.unknown_names.extend(recipe.unknown)
            conn.inputs[recipe.recipe_id] = recipe
            conn.send(wire.frame(kind, recipe.answer()))
        elif kind == wire.START:
            ok = conn.output is not None and conn.output.valid
            conn.send(wire.frame(kind, b"\x01" if ok else b"\x00"))
            conn.next_send = time.monotonic()
            conn.started = ok
        elif kind == wire.PAUSE:
            conn.started = False
            conn.send(wire.frame(kind, b"\x01"))
        elif kind == wire.DATA_PACKAGE:
            recipe = conn.inputs.get(payload[0]) if payload else None
            if recipe is None or not recipe.valid:
                log.warning("%s: data package for unknown input recipe", self.config.host)
                return
            self._apply_inputs(recipe.unpack(payload))
        else:
            log.warning("%s: unknown RTDE message type %d", self.config.host, kind)

    def _apply_inputs(self, values: dict[str, object]) -> None:
        with self.registers.lock:
            for name, value in values.items():
                reg = wire.register_index(name)
                if reg is None:
                    continue
                kind, index = reg
                if kind == "int":
                    self.registers.in_int[index] = int(value)
                else:
                    self.registers.in_double[index] = float(value)

    def _serve_dashboard(self, conn: _Connection) -> None:
        try:
            self._wait_answering()
            conn.send(b"Connected: Universal Robots Dashboard Server\n")
            buffer = b""
            while not self._stop.is_set() and not conn.closed:
                chunk = conn.sock.recv(1024)
                if not chunk:
                    break
                buffer += chunk
                while b"\n" in buffer:
                    line, buffer = buffer.split(b"\n", 1)
                    self._wait_answering()
                    request = line.decode("utf-8", errors="replace").strip()
                    conn.send((self.dashboard_answer(request) + "\n").encode())
                    if request == "quit":
                        return
        except OSError as exc:
            log.debug("%s: dashboard client left: %s", self.config.host, exc)
        finally:
            self._drop(conn)

    def dashboard_answer(self, request: str) -> str:
        """The dashboard server's answer to one request line."""
        major, minor, bugfix, build = self.config.version
        req = request.strip()
        low = req.lower()
        running = self.program_running
        if req == "PolyscopeVersion":
            return f"URSoftware {major}.{minor}.{bugfix}.{build} (Jan 01 2023)"
        if low == "get serial number":
            return self.config.serial_number
        if low == "is in remote control":
            return "true" if self.config.remote_control else "false"
        if low == "get robot model":
            return "UR10"
        if low == "robotmode":
            return "Robotmode: RUNNING"
        if low == "safetymode":
            return "Safetymode: PROTECTIVE_STOP" if self.protective_stopped else "Safetymode: NORMAL"
        if low == "safetystatus":
            return "Safetystatus: PROTECTIVE_STOP" if self.protective_stopped else "Safetystatus: NORMAL"
        if low == "programstate":
            return "PLAYING rtde_control" if running else "STOPPED rtde_control"
        if low == "running":
            return f"Program running: {'true' if running else 'false'}"
        if low == "stop":
            self.stop_program("stopped from the dashboard")
            return "Stopped"
        if low == "pause":
            return "Failed to execute: pause"
        if low == "play":
            if self.protective_stopped or not self.program_text or self._program_conn is None:
                return "Failed to execute: play"
            self._start_program(self.program_text, self._program_conn)
            return "Starting program"
        if low == "unlock protective stop":
            return self.unlock_protective_stop()
        if low == "close safety popup":
            return "closing safety popup"
        if low == "close popup":
            return "closing popup"
        if low.startswith("popup "):
            return "showing popup"
        if low == "power on":
            return "Powering on"
        if low == "power off":
            return "Powering off"
        if low == "brake release":
            return "Brake releasing"
        if low == "restart safety":
            return "Restarting safety"
        if low == "get loaded program":
            return "Loaded program: rtde_control" if self.program_text else "No program loaded"
        if low == "isprogramsaved":
            return "true rtde_control"
        if low.startswith("addtolog "):
            return "Added log message"
        if low.startswith("setuserrole "):
            return f"Setting user role: {req.split(' ', 1)[1]}"
        if low == "quit":
            return "Disconnected"
        return f"could not understand: '{req}'"

    def _serve_script(self, conn: _Connection) -> None:
        text = ""
        try:
            while not self._stop.is_set() and not conn.closed:
                chunk = conn.sock.recv(65536)
                if not chunk:
                    break
                self._wait_answering()
                text += chunk.decode("utf-8", errors="replace")
                text = self._take_programs(text, conn)
        except OSError as exc:
            log.debug("%s: script client left: %s", self.config.host, exc)
        finally:
            self._drop(conn)

    def _take_programs(self, text: str, conn: _Connection) -> str:
        """Start every complete top-level program in ``text``; return the unfinished rest."""
        lines = text.split("\n")
        rest_start = 0
        in_program = False
        for i, line in enumerate(lines[:-1]):  # the last element is an unfinished line
            if not in_program:
                if line.startswith("def ") or line.startswith("sec "):
                    in_program = True
                    rest_start = i
                elif line.strip():
                    log.warning("%s: ignoring top-level script line %r", self.config.host, line[:60])
                    rest_start = i + 1
            elif line.rstrip() == "end":
                program = "\n".join(lines[rest_start : i + 1]) + "\n"
                self._start_program(program, conn)
                in_program = False
                rest_start = i + 1
        return "\n".join(lines[rest_start:])

    def _start_program(self, program: str, conn: _Connection) -> None:
        self.scripts_received += 1
        if "rtde_cmd" not in program:
            log.error("%s: a program other than ur-rtde's control script is not executed", self.config.host)
            return
        match = _OFFSET.search(program)
        offset = int(match.group(1)) if match else 0
        with self._lock:
            if self.protective_stopped:
                log.warning("%s: program refused during a protective stop", self.config.host)
                return
            if self.program is not None:
                self.program.abort("replaced by a new program")
            with self.registers.lock:
                self.registers.out_int[offset] = 0
            self.program_text = program
            self._program_conn = conn
            self.program = ControlScript(
                self.arm,
                self.registers,
                offset=offset,
                step_time=1.0 / self.config.tick_hz,
                on_protective_stop=self.protective_stop,
            )
            log.info("%s: control program started (%d bytes)", self.config.host, len(program))


def main(argv: list[str] | None = None) -> int:
    """Run one emulated controller until interrupted."""
    parser = argparse.ArgumentParser(description="Emulated UR10e controller for ur-rtde")
    parser.add_argument("--config", type=Path, help="emulator YAML, e.g. config/sim/ur_x_controller.yaml")
    parser.add_argument("--host", help="address to serve on (one per arm), overriding the config")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    try:
        config = load_controller_config(args.config) if args.config else URControllerConfig()
    except ValueError as exc:
        print(f"ur_controller: {exc}", file=sys.stderr)
        return 2
    if args.host:
        config.host = args.host
    try:
        emulator = URControllerEmulator(config).start()
    except OSError as exc:
        print(f"ur_controller: cannot serve on {config.host}: {exc}", file=sys.stderr)
        return 1
    with emulator:
        log.info("UR controller emulator on %s (dashboard 29999, RTDE 30004, script 30003)", config.host)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

__all__ = ["CONFIG_DIR", "URControllerConfig", "URControllerEmulator", "load_controller_config", "main"]
