"""A UR controller emulator in a child process of the twin, clocked by the twin's sim time.

The controller's RTDE stream must reach the driver every 2 ms and the driver declares the link dead
after 0.5 s of silence. Inside the twin process its threads share one interpreter lock with the
simulation loop and six pty threads, and on a loaded machine they would be starved past that limit. So
each :class:`URControllerHost` runs one :class:`URControllerEmulator` (``clock="external"``) in its
own process and shares two things with the twin through shared memory, with no round trip per step:

* the sim time, which the twin raises with :meth:`advance`; the child steps the arm by the
  difference (in steps of at most 2 ms) as soon as it sees it;
* the arm's six joint positions, which the child writes after each step and :meth:`positions` reads.

Faults and the few commands tests need go over a pipe (:meth:`call`), each with a bounded timeout
(:mod:`tlt_sim.emulators.piped_calls`).
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import signal
from dataclasses import asdict
from typing import Any

from tlt_sim.emulators.piped_calls import PipedCalls, answer_one
from tlt_sim.emulators.ur_controller import URControllerEmulator
from tlt_sim.emulators.ur_controller_config import URControllerConfig

MAX_STEP_S = 0.002
_CALLS = {
    "drop_link": lambda e, *a: e.drop_link(),
    "restore_link": lambda e, *a: e.restore_link(),
    "protective_stop": lambda e, *a: e.protective_stop(*a),
    "move_joints": lambda e, *a: e.arm.move_joints(*a),
    "program_running": lambda e, *a: e.program_running,
    "sim_time": lambda e, *a: e._sim_time,
}


def _serve(config: dict[str, Any], pipe, sim_time, positions, log_level: int) -> None:
    # A Ctrl-C or a launcher's SIGINT reaches the whole process group: the twin closes its
    # controllers itself, in order, so the child must not die of it first.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.basicConfig(level=log_level, format="twin: %(message)s")
    try:
        emulator = URControllerEmulator(URControllerConfig(**config)).start()
    except OSError as exc:
        pipe.send(("error", f"cannot serve on {config['host']}: {exc}"))
        return

    def handle(name: str, args: tuple) -> Any:
        if name not in _CALLS:
            raise AttributeError(f"no remote call {name!r}")
        return _CALLS[name](emulator, *args)

    seen = sim_time.value
    positions[:] = emulator.arm.positions()
    pipe.send(("ok", None))
    try:
        while True:
            now = sim_time.value
            while now - seen > 1e-12:
                dt = min(MAX_STEP_S, now - seen)
                emulator.advance(dt)
                seen += dt
            positions[:] = emulator.arm.positions()
            if pipe.poll(0.001) and not answer_one(pipe, handle):
                return
    finally:
        emulator.close()


class URControllerHost:
    """One emulated UR controller in a child process; see the module docstring."""

    def __init__(self, config: URControllerConfig, *, log_level: int = logging.INFO) -> None:
        if config.clock != "external":
            raise ValueError("the twin clocks its UR controllers: config.clock must be 'external'")
        self.config = config
        ctx = mp.get_context("spawn")
        self._time = ctx.Value("d", 0.0, lock=False)
        self._positions = ctx.Array("d", list(config.q0), lock=False)
        pipe, child = ctx.Pipe()
        process = ctx.Process(
            target=_serve,
            args=(asdict(config), child, self._time, self._positions, log_level),
            daemon=True,
            name=f"ur-controller-{config.host}",
        )
        self._calls = PipedCalls(process, pipe, f"the UR controller at {config.host}")
        self._started = False

    def start(self, timeout: float = 30.0) -> URControllerHost:
        """Start the child; returns once it serves (OSError when its address is taken)."""
        self._started = True
        try:
            self._calls.start(timeout)
        except RuntimeError as exc:
            raise OSError(str(exc)) from exc
        return self

    def advance(self, dt: float) -> None:
        """Raise the controller's sim time by ``dt``; the child steps the arm to it."""
        self._time.value += dt

    def positions(self) -> list[float]:
        """The arm's joint positions as the child last stepped them."""
        return list(self._positions)

    def call(self, name: str, *args: Any, timeout: float = 5.0) -> Any:
        """Call ``name`` (a fault or a command of ``_CALLS``) in the child and return its result."""
        return self._calls.call(name, *args, timeout=timeout)

    def drop_link(self) -> None:
        self.call("drop_link")

    def restore_link(self) -> None:
        self.call("restore_link")

    def close(self) -> None:
        if not self._started:
            return
        self._started = False
        self._calls.close()


__all__ = ["URControllerHost"]
