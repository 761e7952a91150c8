"""The emulated lifter firmware on a pseudo-terminal: the serial port the real driver (pyserial)
opens, served in real time around a :class:`~tlt_sim.emulators.lifter_firmware.LifterFirmware`."""

from __future__ import annotations

import contextlib
import errno
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

from tlt_sim.emulators.lifter_firmware import LifterFirmware
from tlt_sim.emulators.pty_device import publish_link, withdraw_link


class PtyFirmwareServer:
    """Serves a :class:`LifterFirmware` on a pseudo-terminal in real time.

    ``start`` opens the pty (raw mode) and a thread that steps the model every ``tick_s`` of
    ``clock`` and answers bytes from the master side; with ``self_stepping=False`` it only serves
    bytes and whoever owns time (the twin, on ROS time) calls ``firmware.step``. ``path`` is the
    slave device for pyserial;
    with ``link_path`` a symlink there points at it, so a restarted emulator is found at the same
    name. ``stop`` closes the pty (to the driver, the port is gone) and removes the symlink.
    """

    def __init__(
        self,
        firmware: LifterFirmware,
        *,
        link_path: str | Path | None = None,
        clock: Callable[[], float] = time.monotonic,
        self_stepping: bool = True,
    ) -> None:
        self.firmware = firmware
        self.self_stepping = self_stepping
        self.link_path = Path(link_path) if link_path else None
        self.clock = clock
        self.path = ""
        self.write_drops = 0
        self._master = -1
        self._slave = -1
        self._thread: threading.Thread | None = None
        self._running = threading.Event()

    def start(self) -> str:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        if self.link_path:
            publish_link(self.link_path, self.path)
        self._running.set()
        self._thread = threading.Thread(target=self._serve, name="lifter-firmware", daemon=True)
        self._thread.start()
        return str(self.link_path or self.path)

    def stop(self) -> None:
        self._running.clear()
        if self._thread:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        if self.link_path:
            withdraw_link(self.link_path, self.path)

    def __enter__(self) -> PtyFirmwareServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _serve(self) -> None:
        tick = self.firmware.config.tick_s
        last = self.clock()
        while self._running.is_set():
            readable, _, _ = select.select([self._master], [], [], tick)
            now = self.clock()
            if self.self_stepping:
                self.firmware.step(max(0.0, now - last))
            last = now
            if not readable:
                continue
            try:
                data = os.read(self._master, 4096)
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EIO):
                    continue
                raise
            reply = self.firmware.receive(data)
            if reply:
                try:
                    os.write(self._master, reply)
                except BlockingIOError:
                    # nobody is reading the port: like a UART, the bytes are simply lost
                    self.write_drops += 1


__all__ = ["PtyFirmwareServer"]
