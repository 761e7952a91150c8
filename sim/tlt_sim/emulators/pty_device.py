"""Serve a byte-level device on a pseudo-terminal, so a real driver opens it like a USB serial port.

The emulator keeps the master side; the driver opens :attr:`PtyDevice.path` (the slave) with
pyserial or dynamixel-sdk exactly as it would open ``/dev/ttyUSB0``. A background thread reads what
the driver writes and passes it to ``handler``; whatever the handler returns is written back.
The slave side is put in raw mode (no echo, no newline translation) and kept open by the emulator
too, so the driver can close and reopen the port without the pty hanging up. ``stop`` returns
within one poll period.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import threading
import tty
from collections.abc import Callable
from pathlib import Path

_log = logging.getLogger(__name__)


class PtyDevice:
    """A pseudo-terminal whose far end is ``handler(bytes) -> bytes``."""

    POLL_S = 0.02

    def __init__(self, handler: Callable[[bytes], bytes], name: str = "pty-device") -> None:
        self._handler = handler
        self._name = name
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_in = 0
        self.bytes_out = 0

    def start(self) -> PtyDevice:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master = self._slave = -1

    def __enter__(self) -> PtyDevice:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def send(self, data: bytes) -> None:
        """Write ``data`` towards the driver (unsolicited bytes, e.g. noise)."""
        view = memoryview(data)
        while view:
            written = os.write(self._master, view)
            view = view[written:]
        self.bytes_out += len(data)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], self.POLL_S)
                if not ready:
                    continue
                data = os.read(self._master, 4096)
            except OSError:
                return  # the pty was closed under us: the device is gone
            if not data:
                continue
            self.bytes_in += len(data)
            try:
                reply = self._handler(data)
            except Exception:  # a bug in a device model must not kill the link thread silently
                _log.exception("%s: handler failed", self._name)
                continue
            if reply:
                try:
                    self.send(reply)
                except OSError:
                    return


def publish_link(link: str | Path, target: str) -> None:
    """Point the symlink ``link`` at the pty ``target``, atomically, creating its folder.

    A driver configured with ``link`` as its port finds a restarted emulator at the same name.
    """
    link = Path(link)
    link.parent.mkdir(parents=True, exist_ok=True)
    tmp = link.with_name(link.name + ".new")
    with contextlib.suppress(FileNotFoundError):
        tmp.unlink()
    tmp.symlink_to(target)
    tmp.replace(link)


def withdraw_link(link: str | Path, target: str) -> None:
    """Remove ``link`` if it still points at ``target`` (not at a newer emulator's pty)."""
    link = Path(link)
    if link.is_symlink() and os.readlink(link) == target:
        with contextlib.suppress(FileNotFoundError):
            link.unlink()
