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
from pathlib import Path

from tlt_sim.emulators import rtde_wire as wire
from tlt_sim.emulators.rtde_session import (
    Connection,
    handle_message,
    output_values,
    runtime_state,
    safety_status_bits,
)
from tlt_sim.emulators.ur_arm import UR10eArm
from tlt_sim.emulators.ur_control_script import ControlScript, Registers
from tlt_sim.emulators.ur_controller_config import URControllerConfig, load_controller_config
from tlt_sim.emulators.ur_dashboard import dashboard_answer

log = logging.getLogger("tlt.sim.ur")

_OFFSET = re.compile(r"global\s+reg_offset_int\s*=\s*(\d+)")


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
        self._program_conn: Connection | None = None
        self._lock = threading.RLock()
        self._answering = threading.Event()
        self._answering.set()
        self._link_up = True
        self._stop = threading.Event()
        self._listeners: list[socket.socket] = []
        self._connections: list[Connection] = []
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
        return runtime_state(self.program_running)

    def safety_status_bits(self) -> int:
        return safety_status_bits(self.protective_stopped)

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
        return output_values(self.arm, self.timestamp(), self.program, self.protective_stopped)

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
            conn = Connection(sock, kind)
            with self._lock:
                self._connections.append(conn)
            handler = {
                "dashboard": self._serve_dashboard,
                "rtde": self._serve_rtde,
                "script": self._serve_script,
            }
            self._spawn(handler[kind], f"{kind}-conn", conn)

    def _drop(self, conn: Connection) -> None:
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

    def _serve_rtde(self, conn: Connection) -> None:
        try:
            while not self._stop.is_set() and not conn.closed:
                kind, payload = wire.read_message(conn.sock)
                self._wait_answering()
                handle_message(conn, kind, payload, self.config, self.registers, self.unknown_names)
        except (OSError, ConnectionError, wire.ProtocolError) as exc:
            log.debug("%s: RTDE client left: %s", self.config.host, exc)
        finally:
            self._drop(conn)

    def _serve_dashboard(self, conn: Connection) -> None:
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
        """The dashboard server's answer to one request line (:mod:`~tlt_sim.emulators.ur_dashboard`)."""
        return dashboard_answer(self, request)

    def play(self) -> bool:
        """The dashboard's ``play``: start the last program again on the script connection it came
        on; False when refused (a protective stop, no program, or its connection gone)."""
        if self.protective_stopped or not self.program_text or self._program_conn is None:
            return False
        self._start_program(self.program_text, self._program_conn)
        return True

    def _serve_script(self, conn: Connection) -> None:
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

    def _take_programs(self, text: str, conn: Connection) -> str:
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

    def _start_program(self, program: str, conn: Connection) -> None:
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

__all__ = ["URControllerEmulator", "main"]
