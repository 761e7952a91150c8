"""An emulated GPIO chip: the twin's side of the EE driver's shared memory GPIO link.

The driver's lines and this chip map the same file (:mod:`tlt_drivers.gpio.shared_memory`, the
link's layout), so the driver process and the twin process see the same lines. The chip plays
the board: the twin drives the inputs (the limit switch) and is told of the outputs (the rivet
guns). In-process writes call the output callbacks at once; :meth:`EmulatedGpioChip.poll` finds
changes made by another process. A test or the twin hands the driver this chip in process by
building the driver's :class:`~tlt_drivers.gpio.shared_memory.SharedMemoryLines` on it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from tlt_drivers.gpio.shared_memory import SharedGpioState

OutputCallback = Callable[[int, bool, int], None]


class EmulatedGpioChip(SharedGpioState):
    """``num_lines`` lines of shared electrical state, and who is told when they change.
    Thread-safe within one process."""

    def __init__(self, state_file: str | Path | None = None, num_lines: int = 64) -> None:
        super().__init__(state_file, num_lines)
        self._callbacks: list[OutputCallback] = []
        self._seen = list(self.counts())

    def drive(self, line: int, level: bool) -> None:
        """Set the electrical level of ``line`` (the twin drives inputs, the driver outputs)."""
        self.check(line)
        with self._lock:
            count = self._write(line, level)
            if count is None:
                return
            self._seen[line] = count
            callbacks = list(self._callbacks)
        for callback in callbacks:
            callback(line, bool(level), 1)

    set_input = drive

    def add_output_callback(self, callback: OutputCallback) -> None:
        """``callback(line, level, edges)`` on every change: at once in-process, via ``poll`` otherwise."""
        with self._lock:
            self._callbacks.append(callback)

    def poll(self) -> list[tuple[int, bool, int]]:
        """Changes made since the last poll (by any process): (line, level now, edges seen)."""
        changes = []
        with self._lock:
            counts = self.counts()
            if counts != tuple(self._seen):
                for line, count in enumerate(counts):
                    if count != self._seen[line]:
                        changes.append((line, self.level(line), (count - self._seen[line]) & 0xFFFFFFFF))
                        self._seen[line] = count
            callbacks = list(self._callbacks)
        for change in changes:
            for callback in callbacks:
                callback(*change)
        return changes


__all__ = ["EmulatedGpioChip", "OutputCallback"]
