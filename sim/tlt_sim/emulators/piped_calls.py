"""Named calls from a parent to an emulator in a child process, over a pipe, each with a timeout.

The parent sends ``(name, args)``; the child answers ``("ok", result)`` or ``("error", text)``
and keeps serving after an error, so a test's bad call never takes the emulator down. ``close``
ends the child's loop. The child's first message, once it serves, is ``("ok", None)`` or the error
that kept it from serving. Both ends live here so that the UR controller run beside tests
(:mod:`~tlt_sim.emulators.ur_controller_process`) and the one the twin clocks
(:mod:`tlt_sim.twin.ur_host`) speak the same protocol.
"""

from __future__ import annotations

from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any


def answer_one(pipe: Connection, handle: Callable[[str, tuple], Any]) -> bool:
    """In the child: receive one call and send ``handle(name, args)``'s result or its error.
    False when the child should stop serving (the parent asked ``close`` or has gone)."""
    try:
        name, args = pipe.recv()
    except EOFError:
        return False
    if name == "close":
        pipe.send(("ok", None))
        return False
    try:
        pipe.send(("ok", handle(name, args)))
    except Exception as exc:  # report to the caller, keep serving
        pipe.send(("error", f"{type(exc).__name__}: {exc}"))
    return True


class PipedCalls:
    """The parent's end: ``process`` (not yet started) serving calls on the far end of ``pipe``;
    ``who`` names it in errors."""

    def __init__(self, process: BaseProcess, pipe: Connection, who: str) -> None:
        self.process = process
        self.pipe = pipe
        self.who = who

    def start(self, timeout: float) -> None:
        """Start the child and wait until it serves (RuntimeError with its reason if it cannot)."""
        self.process.start()
        self.expect(timeout)

    def call(self, name: str, *args: Any, timeout: float = 5.0) -> Any:
        """``name(*args)`` in the child; its result, or TimeoutError / RuntimeError."""
        self.pipe.send((name, args))
        return self.expect(timeout)

    def expect(self, timeout: float) -> Any:
        """The child's next answer: its value, or RuntimeError with the child's error."""
        if not self.pipe.poll(timeout):
            raise TimeoutError(f"{self.who} did not answer")
        try:
            status, value = self.pipe.recv()
        except EOFError as exc:
            raise RuntimeError(f"{self.who} exited (code {self.process.exitcode})") from exc
        if status != "ok":
            raise RuntimeError(value)
        return value

    def close(self) -> None:
        """Ask the child to stop, then make sure it has: joined, killed if it will not end."""
        if self.process.is_alive():
            try:
                self.call("close", timeout=3.0)
            except (TimeoutError, RuntimeError, OSError, EOFError):
                pass
            self.process.join(timeout=3.0)
            if self.process.is_alive():
                self.process.kill()
                self.process.join(timeout=3.0)
