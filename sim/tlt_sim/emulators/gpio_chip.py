"""An emulated GPIO chip whose line levels the twin and the EE driver share.

The chip's state is a small memory-mapped file (or private memory when no file is given), so
the driver process and the twin process see the same lines:

* header ``TLTGPIO1``, the number of lines;
* one byte per line: its electrical level (0/1);
* one uint32 per line: how many times its level changed (so a short pulse between two polls,
  a rivet gun firing, is still seen).

Each line has one writer: the driver writes outputs (rivet guns), the twin writes inputs (the
limit switch), so no lock is needed across processes. In-process writes call the output
callbacks at once; :meth:`EmulatedGpioChip.poll` finds changes made by another process.

:class:`EmulatedLines` is the driver-side view with the same ``get``/``set``/``close`` calls as
the character-device backend: lines by request index, active-low applied as the kernel does,
outputs set to their initial level when requested, undriven inputs at their bias level.
"""

from __future__ import annotations

import mmap
import os
import struct
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

MAGIC = b"TLTGPIO1"
_HEADER = struct.Struct("<8sII")
OutputCallback = Callable[[int, bool, int], None]


class EmulatedGpioChip:
    """``num_lines`` lines of shared electrical state. Thread-safe within one process."""

    def __init__(self, state_file: str | Path | None = None, num_lines: int = 64) -> None:
        self.num_lines = num_lines
        size = _HEADER.size + num_lines + 4 * num_lines
        self._lock = threading.Lock()
        self._callbacks: list[OutputCallback] = []
        self.path = Path(state_file) if state_file else None
        if self.path is None:
            self._map = mmap.mmap(-1, size)
            self._map[: _HEADER.size] = _HEADER.pack(MAGIC, num_lines, 0)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                if os.fstat(fd).st_size < size:
                    os.ftruncate(fd, size)
                self._map = mmap.mmap(fd, size)
            finally:
                os.close(fd)
            magic, lines, _ = _HEADER.unpack(self._map[: _HEADER.size])
            if magic != MAGIC:
                self._map[: _HEADER.size] = _HEADER.pack(MAGIC, num_lines, 0)
            elif lines != num_lines:
                raise ValueError(f"{self.path} holds {lines} lines, not {num_lines}")
        # Every line's change counter in one read (poll runs every sync period of the twin).
        self._counters = struct.Struct(f"<{num_lines}I")
        self._seen = list(self._counters.unpack_from(self._map, self._count_at(0)))

    def _check(self, line: int) -> None:
        if not 0 <= line < self.num_lines:
            raise ValueError(f"line {line} is not on this chip (0..{self.num_lines - 1})")

    def _count_at(self, line: int) -> int:
        return _HEADER.size + self.num_lines + 4 * line

    # --- shared state ----------------------------------------------------------------------------
    def level(self, line: int) -> bool:
        """Electrical level of ``line``."""
        self._check(line)
        return bool(self._map[_HEADER.size + line])

    def edges(self, line: int) -> int:
        """How many times ``line`` changed level since the state was created."""
        self._check(line)
        at = self._count_at(line)
        return struct.unpack("<I", self._map[at : at + 4])[0]

    def drive(self, line: int, level: bool) -> None:
        """Set the electrical level of ``line`` (the twin drives inputs, the driver outputs)."""
        self._check(line)
        with self._lock:
            if self.level(line) == bool(level):
                return
            self._map[_HEADER.size + line] = 1 if level else 0
            at = self._count_at(line)
            count = self.edges(line) + 1
            self._map[at : at + 4] = struct.pack("<I", count & 0xFFFFFFFF)
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
            counts = self._counters.unpack_from(self._map, self._count_at(0))
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

    def close(self) -> None:
        self._map.close()


class _Spec(Protocol):
    line: int
    direction: str
    active_low: bool
    bias: str
    initial: bool


class EmulatedLines:
    """Driver-side lines on an :class:`EmulatedGpioChip`, by index into ``specs``."""

    def __init__(self, chip: EmulatedGpioChip, specs: Sequence[_Spec], *, owns_chip: bool = False) -> None:
        self.chip = chip
        self._owns_chip = owns_chip
        self.specs = list(specs)
        for spec in self.specs:
            chip._check(spec.line)
        for index, spec in enumerate(self.specs):
            if spec.direction == "output":
                self.set(index, spec.initial)
            elif chip.edges(spec.line) == 0 and spec.bias in ("pull_up", "pull_down"):
                # A line nothing has driven yet sits where its bias pulls it, as on the board.
                chip.drive(spec.line, spec.bias == "pull_up")

    def get(self, index: int) -> bool:
        spec = self.specs[index]
        return self.chip.level(spec.line) != spec.active_low

    def set(self, index: int, level: bool) -> None:
        spec = self.specs[index]
        self.chip.drive(spec.line, bool(level) != spec.active_low)

    def close(self) -> None:
        """Release the mapping (if this view opened the chip); the shared state file stays."""
        if self._owns_chip:
            self.chip.close()


__all__ = ["EmulatedGpioChip", "EmulatedLines"]
