"""GPIO lines in a shared memory file: the EE driver's link to whatever plays the board.

With ``backend: emulator`` (config/hardware/gpio_<arm>.yaml) the driver's lines are bytes of a
small memory-mapped file that the twin maps too (its :class:`tlt_sim.emulators.gpio_chip.EmulatedGpioChip`
plays the board: it drives the inputs and watches the outputs), as a serial driver's link is a
port the twin's emulator answers on. The layout is the link's, so it lives here, with the
driver; the twin builds its chip on it:

* header ``TLTGPIO1``, the number of lines;
* one byte per line: its electrical level (0/1);
* one uint32 per line: how many times its level changed (so a short pulse between two polls,
  a rivet gun firing, is still seen).

Each line has one writer: the driver writes outputs (rivet guns), the board inputs (the limit
switch), so no lock is needed across processes.

:class:`SharedMemoryLines` is the driver-side backend, with the same ``get``/``set``/``close``
calls as the character-device backend: lines by request index, active-low applied as the
kernel does, outputs set to their initial level when requested, undriven inputs at their bias
level. It runs over any :class:`SharedGpioState`, so the twin or a test can hand the driver the
chip it plays the board with (:func:`tlt_drivers.gpio.lines.open_gpio`).
"""

from __future__ import annotations

import mmap
import os
import struct
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

MAGIC = b"TLTGPIO1"
_HEADER = struct.Struct("<8sII")


class SharedGpioState:
    """``num_lines`` lines of shared electrical state, in ``state_file`` (private memory when
    none is given). Thread-safe within one process."""

    def __init__(self, state_file: str | Path | None = None, num_lines: int = 64) -> None:
        self.num_lines = num_lines
        size = _HEADER.size + num_lines + 4 * num_lines
        self._lock = threading.Lock()
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
        self._counters = struct.Struct(f"<{num_lines}I")

    def check(self, line: int) -> None:
        """ValueError unless ``line`` is on this chip."""
        if not 0 <= line < self.num_lines:
            raise ValueError(f"line {line} is not on this chip (0..{self.num_lines - 1})")

    def _count_at(self, line: int) -> int:
        return _HEADER.size + self.num_lines + 4 * line

    def level(self, line: int) -> bool:
        """Electrical level of ``line``."""
        self.check(line)
        return bool(self._map[_HEADER.size + line])

    def edges(self, line: int) -> int:
        """How many times ``line`` changed level since the state was created."""
        self.check(line)
        at = self._count_at(line)
        return struct.unpack("<I", self._map[at : at + 4])[0]

    def counts(self) -> tuple[int, ...]:
        """Every line's change counter, in one read."""
        return self._counters.unpack_from(self._map, self._count_at(0))

    def drive(self, line: int, level: bool) -> None:
        """Set the electrical level of ``line`` (the board drives inputs, the driver outputs)."""
        self.check(line)
        with self._lock:
            self._write(line, level)

    def _write(self, line: int, level: bool) -> int | None:
        """Store a new level and count the edge; the new count, None when the level is unchanged.
        The caller holds the lock."""
        if self.level(line) == bool(level):
            return None
        self._map[_HEADER.size + line] = 1 if level else 0
        at = self._count_at(line)
        count = (self.edges(line) + 1) & 0xFFFFFFFF
        self._map[at : at + 4] = struct.pack("<I", count)
        return count

    def close(self) -> None:
        self._map.close()


class _Spec(Protocol):
    # Read-only members, so that a frozen dataclass (gpio.config.LineSpec) matches.
    @property
    def line(self) -> int: ...
    @property
    def direction(self) -> str: ...
    @property
    def active_low(self) -> bool: ...
    @property
    def bias(self) -> str: ...
    @property
    def initial(self) -> bool: ...


class SharedMemoryLines:
    """Driver-side lines on a :class:`SharedGpioState`, by index into ``specs``; closes the state
    when ``owns_state``."""

    def __init__(self, state: SharedGpioState, specs: Sequence[_Spec], *, owns_state: bool = False) -> None:
        self.state = state
        self._owns_state = owns_state
        self.specs = list(specs)
        for spec in self.specs:
            state.check(spec.line)
        for index, spec in enumerate(self.specs):
            if spec.direction == "output":
                self.set(index, spec.initial)
            elif state.edges(spec.line) == 0 and spec.bias in ("pull_up", "pull_down"):
                # A line nothing has driven yet sits where its bias pulls it, as on the board.
                state.drive(spec.line, spec.bias == "pull_up")

    def get(self, index: int) -> bool:
        spec = self.specs[index]
        return self.state.level(spec.line) != spec.active_low

    def set(self, index: int, level: bool) -> None:
        spec = self.specs[index]
        self.state.drive(spec.line, bool(level) != spec.active_low)

    def close(self) -> None:
        """Release the mapping (if these lines opened it); the shared state file stays."""
        if self._owns_state:
            self.state.close()


__all__ = ["MAGIC", "SharedGpioState", "SharedMemoryLines"]
