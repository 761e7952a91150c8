"""The link thread (Fig. 6): receives telemetry into the archive and sends queued commands.

:class:`LinkWorker` owns a :class:`GswLink` and its :class:`Recorder` in one background thread.
The thread loops: send the queued commands, receive for at most ``poll_s``, commit what the
recorder buffered once it is old enough. The GUI runs it inside its link process
(:mod:`tlt_gsw.gui.link_process`); tests also run it in-process. Displays never touch the socket
or the database writer; they read the archive with their own read-only connection. :meth:`submit` returns a
:class:`concurrent.futures.Future` that holds the sent command, or the error that kept it from
being sent (bad parameter, closed link). :meth:`close` stops the thread within a bounded time and
closes the link and the archive.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Mapping
from concurrent.futures import Future
from typing import Any

from tlt_gsw.link import GswLink, SentCommand

_log = logging.getLogger(__name__)


class LinkClosedError(RuntimeError):
    """A command was submitted after the link thread stopped."""


class LinkWorker:
    """Background thread around one GswLink; see the module docstring."""

    def __init__(self, link: GswLink, *, poll_s: float = 0.02) -> None:
        self.link = link
        self.poll_s = poll_s
        self.error: str | None = None
        self._queue: queue.Queue[tuple[str, dict[str, Any], Future]] = queue.Queue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gsw-link", daemon=True)

    def start(self) -> LinkWorker:
        self._thread.start()
        return self

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def submit(self, name: str, params: Mapping[str, Any] | None = None) -> Future:
        """Queue a command for the link thread; the future resolves once it is sent (or refused)."""
        future: Future = Future()
        if self._stop.is_set() or not self._thread.is_alive():
            future.set_exception(LinkClosedError("the link thread is not running"))
            return future
        self._queue.put((name, dict(params or {}), future))
        return future

    def _send_queued(self) -> None:
        while True:
            try:
                name, params, future = self._queue.get_nowait()
            except queue.Empty:
                return
            if not future.set_running_or_notify_cancel():
                continue
            try:
                sent: SentCommand = self.link.send_command(name, params)
            except Exception as exc:  # a bad parameter is the operator's error: report it, go on
                future.set_exception(exc)
            else:
                future.set_result(sent)

    def _run(self) -> None:
        recorder = self.link.recorder
        while not self._stop.is_set():
            try:
                self._send_queued()
                self.link.poll(self.poll_s)
                if recorder is not None:
                    recorder.maybe_flush()
            except OSError as exc:
                if self._stop.is_set():
                    break
                self.error = f"link error: {exc}"
                _log.exception("GSW link thread")
                self._stop.wait(0.2)
        # Fail what is still queued so no caller waits on a command that will never go out.
        while True:
            try:
                _, _, future = self._queue.get_nowait()
            except queue.Empty:
                break
            if future.set_running_or_notify_cancel():
                future.set_exception(LinkClosedError("the link thread stopped before sending"))

    def close(self, timeout: float = 2.0) -> None:
        """Stop the thread, then close the link (which flushes and closes the archive it owns)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)
        self.link.close()


__all__ = ["LinkClosedError", "LinkWorker"]
