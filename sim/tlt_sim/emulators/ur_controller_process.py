"""Run a :class:`URControllerEmulator` in a child process and drive it from the parent.

``ur-rtde``'s interface constructors hold the Python interpreter lock while they block on the
socket handshake, so an emulator in the same process as a ur-rtde client would never get to
answer. Tests and benchmarks therefore run each emulated controller in its own process; this
class starts it and forwards calls (faults, joint state) over a pipe, each with a bounded timeout.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
from dataclasses import asdict
from typing import Any

from tlt_sim.emulators.ur_controller import URControllerConfig, URControllerEmulator

_ALLOWED = {
    "protective_stop",
    "unlock_protective_stop",
    "drop_link",
    "restore_link",
    "set_no_answer",
    "stop_program",
}
_QUERIES = {
    "positions": lambda e: e.arm.positions(),
    "velocities": lambda e: e.arm.velocities(),
    "tcp_pose": lambda e: e.arm.tcp_pose(),
    "runtime_state": lambda e: e.runtime_state,
    "program_running": lambda e: e.program_running,
    "protective_stopped": lambda e: e.protective_stopped,
    "scripts_received": lambda e: e.scripts_received,
    "unknown_names": lambda e: list(e.unknown_names),
    "arm_mode": lambda e: e.arm.mode,
}


def _serve(config: dict[str, Any], pipe, log_level: int) -> None:
    logging.basicConfig(level=log_level, format="%(asctime)s ur-emu %(name)s %(message)s")
    try:
        emulator = URControllerEmulator(URControllerConfig(**config)).start()
    except OSError as exc:
        pipe.send(("error", f"cannot serve on {config['host']}: {exc}"))
        return
    pipe.send(("ok", None))
    try:
        while True:
            try:
                name, args = pipe.recv()
            except EOFError:
                return
            if name == "close":
                pipe.send(("ok", None))
                return
            try:
                if name in _QUERIES:
                    result = _QUERIES[name](emulator)
                elif name == "set_state":
                    result = emulator.arm.set_state(*args)
                elif name in _ALLOWED:
                    result = getattr(emulator, name)(*args)
                else:
                    raise AttributeError(f"no remote call {name!r}")
                pipe.send(("ok", result))
            except Exception as exc:  # report to the caller, keep serving
                pipe.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        emulator.close()


class URControllerProcess:
    """An emulated controller in a child process. Use as a context manager."""

    def __init__(self, config: URControllerConfig | None = None, *, log_level: int = logging.WARNING) -> None:
        self.config = config or URControllerConfig()
        ctx = mp.get_context("spawn")
        self._pipe, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve, args=(asdict(self.config), child, log_level), daemon=True, name="ur-emulator"
        )
        self._log_level = log_level

    def start(self, timeout: float = 20.0) -> URControllerProcess:
        self._proc.start()
        self._expect(timeout)
        return self

    def call(self, name: str, *args: Any, timeout: float = 5.0) -> Any:
        """Call ``name`` on the emulator (a fault or a query) and return its result."""
        self._pipe.send((name, args))
        return self._expect(timeout)

    def _expect(self, timeout: float) -> Any:
        if not self._pipe.poll(timeout):
            raise TimeoutError("the UR emulator process did not answer")
        try:
            status, value = self._pipe.recv()
        except EOFError as exc:
            raise RuntimeError(f"the UR emulator process exited (code {self._proc.exitcode})") from exc
        if status != "ok":
            raise RuntimeError(value)
        return value

    def close(self) -> None:
        if self._proc.is_alive():
            try:
                self.call("close", timeout=3.0)
            except (TimeoutError, RuntimeError, OSError, EOFError):
                pass
            self._proc.join(timeout=3.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(timeout=3.0)

    def __enter__(self) -> URControllerProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
