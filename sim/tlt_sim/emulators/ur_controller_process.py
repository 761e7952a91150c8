"""Run a :class:`URControllerEmulator` in a child process and drive it from the parent.

``ur-rtde``'s interface constructors hold the Python interpreter lock while they block on the
socket handshake, so an emulator in the same process as a ur-rtde client would never get to
answer. Tests and benchmarks therefore run each emulated controller in its own process; this
class starts it and forwards calls (faults, joint state) over a pipe, each with a bounded timeout
(:mod:`~tlt_sim.emulators.piped_calls`).
"""

from __future__ import annotations

import logging
import multiprocessing as mp
from dataclasses import asdict
from typing import Any

from tlt_sim.emulators.piped_calls import PipedCalls, answer_one
from tlt_sim.emulators.ur_controller import URControllerEmulator
from tlt_sim.emulators.ur_controller_config import URControllerConfig

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

    def handle(name: str, args: tuple) -> Any:
        if name in _QUERIES:
            return _QUERIES[name](emulator)
        if name == "set_state":
            return emulator.arm.set_state(*args)
        if name in _ALLOWED:
            return getattr(emulator, name)(*args)
        raise AttributeError(f"no remote call {name!r}")

    pipe.send(("ok", None))
    try:
        while answer_one(pipe, handle):
            pass
    finally:
        emulator.close()


class URControllerProcess:
    """An emulated controller in a child process. Use as a context manager."""

    def __init__(self, config: URControllerConfig | None = None, *, log_level: int = logging.WARNING) -> None:
        self.config = config or URControllerConfig()
        ctx = mp.get_context("spawn")
        pipe, child = ctx.Pipe()
        process = ctx.Process(
            target=_serve, args=(asdict(self.config), child, log_level), daemon=True, name="ur-emulator"
        )
        self._calls = PipedCalls(process, pipe, "the UR emulator process")

    @property
    def pid(self) -> int | None:
        """The child's process id (None before :meth:`start`)."""
        return self._calls.process.pid

    def start(self, timeout: float = 20.0) -> URControllerProcess:
        self._calls.start(timeout)
        return self

    def call(self, name: str, *args: Any, timeout: float = 5.0) -> Any:
        """Call ``name`` on the emulator (a fault or a query) and return its result."""
        return self._calls.call(name, *args, timeout=timeout)

    def close(self) -> None:
        self._calls.close()

    def __enter__(self) -> URControllerProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
