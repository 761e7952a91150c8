"""The link to one UR controller through ur-rtde, with bounded waits around it.

``URLink`` owns the library's ``RTDEReceiveInterface`` (state) and ``RTDEControlInterface``
(commands, through the control script ur-rtde uploads) and adds what the library does not give:

* a probe: a plain socket with a timeout asks the controller's RTDE server for its protocol
  version before the library is handed the link. ur-rtde's constructors block on handshake reads
  without a deadline and hold the interpreter lock meanwhile, so they are only called on a
  controller that has just answered;
* freshness: the link is judged by the controller's own ``timestamp`` advancing; no new data for
  ``link_timeout_s`` raises :class:`LinkDown`, whatever the library's ``isConnected`` says;
* reconnection: a dead interface is disconnected (which joins its receive thread) and replaced
  by a new one. The control interface also tries one reconnect by itself, in its own thread,
  when its data stops; its object must not be touched meanwhile, so it is replaced only after
  the control connection has been down for ``control_settle_s`` (longer than the library's own
  attempt can take: a 2 s dashboard connect plus a 2.5 s read deadline).

Every method either returns within a bounded time or raises; nothing here is called from a ROS
callback that must not block except :meth:`read`, which only reads memory.
"""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

RTDE_PORT = 30004
DASHBOARD_PORT = 29999
_PROTOCOL_VERSION = 2
SAFETY_BIT_PROTECTIVE_STOP = 1 << 2
SAFETY_BIT_EMERGENCY_STOP = 1 << 7
RUNTIME_PLAYING = 2
_RECEIVE_VARIABLES = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "actual_TCP_pose",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    "robot_status_bits",
    "safety_status_bits",
]


class LinkDown(ConnectionError):
    """The controller does not answer, or its data stopped arriving."""


def probe_rtde(host: str, timeout: float, port: int = RTDE_PORT) -> str | None:
    """Ask the RTDE server for protocol version 2; None if it accepts in time, else the reason."""
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            sock.sendall(struct.pack(">HBH", 5, ord("V"), _PROTOCOL_VERSION))
            header = _recv_exact(sock, 3)
            size, kind = struct.unpack(">HB", header)
            body = _recv_exact(sock, size - 3)
    except TimeoutError:
        return f"RTDE server on {host}:{port} did not answer within {timeout} s"
    except OSError as exc:
        return f"RTDE server on {host}:{port} unreachable: {exc.strerror or exc}"
    if kind != ord("V") or body[:1] != b"\x01":
        return f"RTDE server on {host}:{port} refused protocol version {_PROTOCOL_VERSION}"
    return None


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise OSError("connection closed by the controller")
        data += chunk
    return data


@dataclass(frozen=True)
class ArmReading:
    """One sample of the controller's state."""

    timestamp: float
    q: tuple[float, ...]
    qd: tuple[float, ...]
    target_q: tuple[float, ...]
    tcp_pose: tuple[float, ...]
    robot_mode: int
    safety_mode: int
    runtime_state: int
    safety_status_bits: int

    @property
    def protective_stopped(self) -> bool:
        return bool(self.safety_status_bits & SAFETY_BIT_PROTECTIVE_STOP)

    @property
    def emergency_stopped(self) -> bool:
        return bool(self.safety_status_bits & SAFETY_BIT_EMERGENCY_STOP)

    @property
    def program_running(self) -> bool:
        return self.runtime_state == RUNTIME_PLAYING


def _default_receive(host: str, frequency: float) -> Any:
    import rtde_receive

    return rtde_receive.RTDEReceiveInterface(host, frequency, _RECEIVE_VARIABLES)


def _default_control(host: str, frequency: float) -> Any:
    import rtde_control

    return rtde_control.RTDEControlInterface(host, frequency)


def _default_dashboard(host: str) -> Any:
    import dashboard_client

    client = dashboard_client.DashboardClient(host)
    client.connect(2000)
    return client


class URLink:
    """The receive and control interfaces of one arm, opened, watched and reopened."""

    def __init__(
        self,
        host: str,
        *,
        frequency: float = 500.0,
        link_timeout: float = 0.5,
        probe_timeout: float = 0.5,
        program_timeout: float = 5.0,
        control_settle_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
        data_clock: Callable[[], float] | None = None,
        receive_factory: Callable[[str, float], Any] = _default_receive,
        control_factory: Callable[[str, float], Any] = _default_control,
        dashboard_factory: Callable[[str], Any] = _default_dashboard,
    ) -> None:
        self.host = host
        self.frequency = frequency
        self.link_timeout = link_timeout
        self.probe_timeout = probe_timeout
        self.program_timeout = program_timeout
        self.control_settle_s = control_settle_s
        self._control_down_since: float | None = None
        self._clock = clock
        # Staleness of the state stream counts in the control loop's time base (tlt_drivers.loop_time).
        self._data_clock = data_clock or clock
        self._receive_factory = receive_factory
        self._control_factory = control_factory
        self._dashboard_factory = dashboard_factory
        self.receive: Any = None
        self.control: Any = None
        self._last_stamp: float | None = None
        self._last_change = 0.0

    # --- opening -------------------------------------------------------------------------------
    def probe(self) -> str | None:
        return probe_rtde(self.host, self.probe_timeout)

    def open_receive(self) -> None:
        """Start (or restart) state streaming; raises :class:`LinkDown` if the controller is silent."""
        problem = self.probe()
        if problem:
            raise LinkDown(problem)
        try:
            if self.receive is not None and not self.receive.isConnected():
                self._discard("receive")
            if self.receive is None:
                self.receive = self._receive_factory(self.host, self.frequency)
        except RuntimeError as exc:
            raise LinkDown(f"ur-rtde receive interface: {exc}") from exc
        self._last_stamp, self._last_change = None, self._data_clock()
        self.read()

    def open_control(self) -> None:
        """Connect the control interface and make sure the control script runs."""
        problem = self.probe()
        if problem:
            raise LinkDown(problem)
        try:
            if self.control is not None and not self.control_connected:
                wait = self.control_wait()
                if wait > 0:
                    raise LinkDown(f"waiting {wait:.1f} s more for ur-rtde's own reconnect attempt to end")
                self._discard("control")
            if self.control is None:
                self.control = self._control_factory(self.host, self.frequency)
            if not self.read().program_running:
                self.control.reuploadScript()
        except RuntimeError as exc:
            raise LinkDown(f"ur-rtde control interface: {exc}") from exc
        deadline = self._clock() + self.program_timeout
        # Both streams must show the script running: ur-rtde refuses commands on the control
        # stream's view, which can be a cycle behind the receive stream's.
        while not (self.read().program_running and self.control.isProgramRunning()):
            if self._clock() > deadline:
                raise RuntimeError(f"the control script did not start within {self.program_timeout} s")
            time.sleep(0.01)

    def _discard(self, which: str) -> None:
        """Disconnect a dead interface (joining its thread) and drop it; a fresh one replaces it.

        ur-rtde's own ``reconnect`` on an object whose receive thread has died can abort the
        process (a C++ terminate); building a new object
        after ``disconnect`` has joined the old thread goes through the library's well-trodden
        constructor instead.
        """
        client = getattr(self, which)
        setattr(self, which, None)
        if which == "control":
            self._control_down_since = None
        try:
            client.disconnect()
        except RuntimeError:  # it is being thrown away because its connection is gone
            pass

    def close(self) -> None:
        """Stop the control script and disconnect both interfaces (for shutdown)."""
        if self.control is not None:
            try:
                if self.control.isConnected():
                    self.control.stopScript()
                self.control.disconnect()
            finally:
                self.control = None
        if self.receive is not None:
            try:
                self.receive.disconnect()
            finally:
                self.receive = None

    # --- state -----------------------------------------------------------------------------------
    def read(self) -> ArmReading:
        """The latest controller state; :class:`LinkDown` if the link is gone or the data is stale."""
        _ = self.control_connected  # keeps the down-time of the control connection current
        r = self.receive
        if r is None or not r.isConnected():
            raise LinkDown(f"no RTDE connection to {self.host}")
        now = self._data_clock()
        stamp = r.getTimestamp()
        if stamp != self._last_stamp:
            self._last_stamp, self._last_change = stamp, now
        elif now - self._last_change > self.link_timeout:
            raise LinkDown(f"no data from the controller at {self.host} for {now - self._last_change:.2f} s")
        q = r.getActualQ()
        if len(q) != 6:
            raise LinkDown(f"no joint state from the controller at {self.host} yet")
        return ArmReading(
            timestamp=stamp,
            q=tuple(q),
            qd=tuple(r.getActualQd()),
            target_q=tuple(r.getTargetQ()),
            tcp_pose=tuple(r.getActualTCPPose()),
            robot_mode=int(r.getRobotMode()),
            safety_mode=int(r.getSafetyMode()),
            runtime_state=int(r.getRuntimeState()),
            safety_status_bits=int(r.getSafetyStatusBits()),
        )

    def control_wait(self) -> float:
        """Seconds before :meth:`open_control` may call ur-rtde's reconnect (0 when it may)."""
        if self.control is None or self.control_connected:
            return 0.0
        down_since = self._control_down_since
        assert down_since is not None  # control_connected has just timed the outage
        return max(0.0, self.control_settle_s - (self._clock() - down_since))

    @property
    def control_connected(self) -> bool:
        """Whether the control interface is connected (also times how long it has been down)."""
        connected = self.control is not None and bool(self.control.isConnected())
        if connected:
            self._control_down_since = None
        elif self._control_down_since is None:
            self._control_down_since = self._clock()
        return connected

    # --- commands (ur-rtde releases the interpreter lock while these wait) -------------------------
    def _control(self) -> Any:
        if not self.control_connected:
            raise LinkDown(f"no control connection to {self.host}")
        return self.control

    def move_joints(
        self, q: Sequence[float], velocity: float, acceleration: float, asynchronous: bool
    ) -> bool:
        return bool(self._control().moveJ(list(q), velocity, acceleration, asynchronous))

    def servo(self, q: Sequence[float], period: float, lookahead: float, gain: float) -> bool:
        return bool(self._control().servoJ(list(q), 0.0, 0.0, period, lookahead, gain))

    def servo_stop(self, deceleration: float) -> bool:
        return bool(self._control().servoStop(deceleration))

    def stop_joints(self, deceleration: float) -> bool:
        return bool(self._control().stopJ(deceleration, False))

    def motion_running(self) -> bool:
        """Whether an asynchronous move is still running (ur-rtde's progress word, bit 15)."""
        return self._control().getAsyncOperationProgress() >= 0

    def unlock_protective_stop(self) -> str:
        """Ask the dashboard server to release a protective stop; returns its answer."""
        if self.probe():
            raise LinkDown(f"controller at {self.host} does not answer")
        client = self._dashboard_factory(self.host)
        try:
            client.unlockProtectiveStop()
            return "Protective stop releasing"
        except RuntimeError as exc:  # the dashboard's refusal text (e.g. within 5 s of the stop)
            return str(exc)
        finally:
            client.disconnect()


__all__ = ["ArmReading", "LinkDown", "URLink", "probe_rtde"]
