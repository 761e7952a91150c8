"""What every emulated bus of daisy-chained devices shares: serving on a pty, keeping time, faults.

A subclass (a Dynamixel or a MightyZAP chain) answers bytes in ``handle`` and moves its devices
in ``advance(dt)``. With a ``clock`` the chain advances itself to that clock on every packet (and on
``catch_up``); with ``clock=None`` whoever owns time (the twin) calls ``advance``. Link faults are
kept here for the subclass's ``handle`` to honour: silenced ids, a dropped link, and a count of
replies to corrupt.
"""

from __future__ import annotations

import abc
import threading
import time
from collections.abc import Callable

from tlt_sim.emulators.pty_device import PtyDevice


class SerialChain(abc.ABC):
    """Base of the emulated device chains; subclasses implement ``handle`` and ``advance``."""

    MAX_STEP_S = 0.005
    PTY_NAME = "serial-chain"

    def __init__(self, clock: Callable[[], float] | None = time.monotonic) -> None:
        self._clock = clock
        self._last = clock() if clock else 0.0
        self._lock = threading.RLock()
        self._silenced: set[int] = set()
        self._link_dropped = False
        self._corrupt_remaining = 0
        self._device: PtyDevice | None = None

    @abc.abstractmethod
    def handle(self, data: bytes) -> bytes:
        """Bytes from the driver in, the devices' replies out."""

    @abc.abstractmethod
    def advance(self, dt: float) -> None:
        """Move every device by ``dt`` seconds."""

    # --- serving ----------------------------------------------------------------------------------
    def start(self) -> str:
        """Serve on a new pty; returns the slave path for the driver to open."""
        self._device = PtyDevice(self.handle, name=self.PTY_NAME).start()
        return self._device.path

    @property
    def port(self) -> str:
        if self._device is None:
            raise RuntimeError("the chain is not being served; call start()")
        return self._device.path

    def stop(self) -> None:
        if self._device is not None:
            self._device.stop()
            self._device = None

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def catch_up(self) -> None:
        """Advance the devices to the clock (done on every packet; call it to read them between packets)."""
        if self._clock is None:
            return
        with self._lock:
            now = self._clock()
            dt, self._last = now - self._last, now
            if dt > 0:
                self.advance(dt)

    # --- faults ---------------------------------------------------------------------------------------
    def silence(self, device_id: int, silent: bool = True) -> None:
        """Make one device stop (or resume) answering."""
        with self._lock:
            (self._silenced.add if silent else self._silenced.discard)(device_id)

    def drop_link(self, dropped: bool = True) -> None:
        """Drop (or restore) the whole link: no device answers."""
        with self._lock:
            self._link_dropped = dropped

    def corrupt_next(self, count: int) -> None:
        """Send the next ``count`` replies with a wrong CRC or checksum."""
        with self._lock:
            self._corrupt_remaining = count
