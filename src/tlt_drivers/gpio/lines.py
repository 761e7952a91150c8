"""Named GPIO lines for the end effector: ``read_input(name)`` and ``write_output(name, level)``.

:class:`GpioLines` maps the names of ``config/hardware/gpio_<arm>.yaml`` (``rivet_gun_left``,
``limit_switch``, ...) to line indices of a backend: the Linux character device on the Jetsons
(:class:`~tlt_drivers.gpio.chardev.CharDevLines`), or the shared memory file the twin plays the
board through (:class:`~tlt_drivers.gpio.shared_memory.SharedMemoryLines`). The backend is handed
in: :class:`GpioLines` takes one, and :func:`open_gpio` opens the one the configuration names
unless the caller (the twin, a test) hands it its own. Levels are logical: ``True`` is "active"
(a firing rivet gun, a pressed switch) whatever the wiring's polarity. An unknown name, or a
write to an input / read of an output's name as input, raises ``KeyError``/``ValueError`` naming
the line and what it is.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from .config import GpioConfig, load_gpio_config
from .shared_memory import SharedGpioState, SharedMemoryLines


class LineBackend(Protocol):
    def get(self, index: int) -> bool: ...

    def set(self, index: int, level: bool) -> None: ...

    def close(self) -> None: ...


class GpioLines:
    """The configured lines of one GPIO set over ``backend``."""

    def __init__(self, config: GpioConfig, backend: LineBackend) -> None:
        self.config = config
        self.backend = backend
        self._index = {spec.name: i for i, spec in enumerate(config.lines)}

    def _lookup(self, name: str, direction: str) -> int:
        if name not in self._index:
            raise KeyError(
                f"{self.config.component}: no GPIO line named {name!r} (known: {sorted(self._index)})"
            )
        index = self._index[name]
        spec = self.config.lines[index]
        if spec.direction != direction:
            raise ValueError(
                f"{self.config.component}: line {name!r} is an {spec.direction}, not an {direction}"
            )
        return index

    def read_input(self, name: str) -> bool:
        """Logical level of input ``name`` (True = active, e.g. switch pressed)."""
        return self.backend.get(self._lookup(name, "input"))

    def write_output(self, name: str, level: bool) -> None:
        """Drive output ``name`` to the logical ``level`` (True = active, e.g. rivet gun firing)."""
        self.backend.set(self._lookup(name, "output"), bool(level))

    def read_output(self, name: str) -> bool:
        """The level output ``name`` is driven to."""
        return self.backend.get(self._lookup(name, "output"))

    @property
    def inputs(self) -> list[str]:
        return [s.name for s in self.config.lines if s.direction == "input"]

    @property
    def outputs(self) -> list[str]:
        return [s.name for s in self.config.lines if s.direction == "output"]

    def close(self) -> None:
        self.backend.close()


def open_gpio(config: GpioConfig | str | Path, backend: LineBackend | None = None) -> GpioLines:
    """The configured lines over ``backend``, or, when none is handed in, over the backend the
    configuration names (``chardev``: the character device; ``emulator``: the shared memory file)."""
    if not isinstance(config, GpioConfig):
        config = load_gpio_config(config)
    if backend is None:
        if config.backend == "chardev":
            from .chardev import CharDevLines

            backend = CharDevLines(config.chip, config.consumer, config.lines)
        else:
            state = SharedGpioState(config.emulator_state)
            backend = SharedMemoryLines(state, config.lines, owns_state=True)
    return GpioLines(config, backend)


__all__ = ["GpioLines", "LineBackend", "open_gpio"]
