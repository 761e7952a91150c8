"""The GUI's link in a child process, so painting the GUI never delays receiving (Fig. 6).

Python runs one thread at a time per process: a GUI thread busy drawing plots would delay a link
thread in the same process, and a burst of telemetry could overflow the socket buffer. The GUI
therefore starts :class:`LinkProcess`: a child process (``spawn``) that runs a :class:`LinkWorker`
(GswLink + Recorder) and writes every packet into the archive; the GUI only reads the archive.

Commands cross with two queues: :meth:`submit` returns a :class:`Future` that :meth:`poll` (called
on every GUI refresh) resolves with a :class:`SentInfo`, or fails with :class:`CommandNotSent`
carrying the reason. :meth:`health` says whether the archive is being written. :meth:`start` waits
at most ``start_timeout_s`` for the child to bind its socket and open the archive, and raises
:class:`LinkStartError` with the child's reason if it could not; :meth:`close` stops it within a
bounded time (then terminates it).
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import queue
import time
from collections.abc import Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HEALTH_PERIOD_S = 0.5


class LinkStartError(RuntimeError):
    """The link process could not start (bad key file, port in use, archive not writable...)."""


class CommandNotSent(RuntimeError):
    """The link process could not send a command (bad parameter, link stopped); says why."""


@dataclass(frozen=True)
class LinkSettings:
    """Everything the child needs to build the link; plain data, so it crosses to the child."""

    definitions: str | None
    # None: monitor only, a throwaway command key that never signs anything sent, and no telemetry
    # key, so every telemetry packet is archived as rejected (nothing unverified is shown).
    key_file: str | None
    key_id: int
    crs_address: tuple[str, int]
    bind: tuple[str, int]
    archive: str
    command_state: str | None
    flush_interval_s: float = 0.1
    recv_buffer_bytes: int = 4 << 20  # rides out the GUI host being busy for a while at 2,000 packets/s
    tm_key_overlap_s: float = 30.0
    # The (address, port or None) sources telemetry is taken from; None: any source.
    accept_from: list[tuple[str, int | None]] | None = None


@dataclass(frozen=True)
class SentInfo:
    """A command the link process sent."""

    name: str
    security_seq: int
    seq_count: int


def _build_link(settings: LinkSettings):
    from tlt_common.ccsds.auth import CommandSequencer, KeyRing
    from tlt_common.ccsds.definitions import load_definitions
    from tlt_gsw.archive.recorder import Recorder
    from tlt_gsw.link import GswLink

    defs = load_definitions(settings.definitions)
    if settings.key_file:
        keyring = KeyRing.load(settings.key_file)
    else:
        keyring = KeyRing({settings.key_id: os.urandom(32)})
    recorder = Recorder(settings.archive, flush_interval_s=settings.flush_interval_s)
    try:
        return GswLink(
            defs,
            keyring,
            settings.key_id,
            settings.crs_address,
            bind=settings.bind,
            recorder=recorder,
            close_recorder=True,
            sequencer=CommandSequencer(settings.command_state) if settings.command_state else None,
            recv_buffer_bytes=settings.recv_buffer_bytes,
            tm_key_overlap_s=settings.tm_key_overlap_s,
            accept_from=settings.accept_from,
        )
    except BaseException:
        recorder.close()
        raise


def _serve(settings: LinkSettings, requests: Any, results: Any) -> None:
    """Child process: run the link until a ``None`` request (or the parent's queue closes)."""
    from tlt_gsw.gui.link_worker import LinkWorker

    try:
        link = _build_link(settings)
    except Exception as exc:
        results.put(("failed", f"{type(exc).__name__}: {exc}"))
        return
    worker = LinkWorker(link).start()
    recorder = link.recorder
    results.put(("ready", link.address))

    def report(rid: int, future: Future) -> None:
        error = future.exception()
        if error is not None:
            results.put(("error", rid, str(error)))
        else:
            sent = future.result()
            results.put(("sent", rid, SentInfo(sent.name, sent.security_seq, sent.seq_count)))

    next_health = 0.0
    try:
        while True:
            try:
                item = requests.get(timeout=HEALTH_PERIOD_S / 2)
            except queue.Empty:
                item = ()
            if item is None:
                break
            if item:
                rid, name, params = item

                def report_this(future: Future, rid: int = rid) -> None:
                    report(rid, future)

                worker.submit(name, params).add_done_callback(report_this)
            if time.monotonic() >= next_health and recorder is not None:
                next_health = time.monotonic() + HEALTH_PERIOD_S
                results.put(
                    ("health", recorder.committed, recorder.pending, recorder.last_error, worker.error)
                )
    except (EOFError, OSError, KeyboardInterrupt):
        pass  # the parent went away: stop recording cleanly
    finally:
        worker.close()


class LinkProcess:
    """Parent side of the link process; see the module docstring."""

    def __init__(self, settings: LinkSettings, *, start_timeout_s: float = 30.0) -> None:
        self.settings = settings
        self.start_timeout_s = start_timeout_s
        self.address: tuple[str, int] | None = None
        self.committed = 0
        self.pending = 0
        self.last_error: str | None = None
        self._futures: dict[int, Future] = {}
        self._closed = False
        self._ids = itertools.count(1)
        ctx = multiprocessing.get_context("spawn")
        self._requests = ctx.Queue()
        self._results = ctx.Queue()
        self._process = ctx.Process(
            target=_serve, args=(settings, self._requests, self._results), name="gsw-link", daemon=True
        )

    def start(self) -> LinkProcess:
        self._process.start()
        deadline = time.monotonic() + self.start_timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or (not self._process.is_alive() and self._results.empty()):
                self.close()
                raise LinkStartError(f"the link process did not start within {self.start_timeout_s:g} s")
            try:
                message = self._results.get(timeout=min(left, 0.2))
            except queue.Empty:
                continue
            if message[0] == "ready":
                self.address = message[1]
                return self
            if message[0] == "failed":
                self.close()
                raise LinkStartError(message[1])

    @property
    def alive(self) -> bool:
        return self._process.is_alive()

    def submit(self, name: str, params: Mapping[str, Any] | None = None) -> Future:
        """Queue a command; the future resolves on a later :meth:`poll`."""
        future: Future = Future()
        if self._closed or not self._process.is_alive():
            future.set_exception(CommandNotSent("the link process is not running"))
            return future
        rid = next(self._ids)
        self._futures[rid] = future
        self._requests.put((rid, name, dict(params or {})))
        return future

    def poll(self) -> None:
        """Take the child's reports: sent commands, errors, archive health (never blocks)."""
        while not self._closed:
            try:
                message = self._results.get_nowait()
            except (queue.Empty, EOFError, OSError, ValueError):
                break
            kind = message[0]
            if kind == "sent":
                future = self._futures.pop(message[1], None)
                if future is not None:
                    future.set_result(message[2])
            elif kind == "error":
                future = self._futures.pop(message[1], None)
                if future is not None:
                    future.set_exception(CommandNotSent(message[2]))
            elif kind == "health":
                self.committed, self.pending = message[1], message[2]
                self.last_error = message[3] or message[4]
        if self._closed or not self._process.is_alive():
            for future in self._futures.values():
                future.set_exception(CommandNotSent("the link process stopped"))
            self._futures.clear()

    def health(self) -> tuple[str, bool]:
        """Text and state of the archive writer, for the link status strip."""
        name = Path(self.settings.archive).name
        if self._closed or not self._process.is_alive():
            return f"{name}: LINK PROCESS STOPPED", False
        if self.last_error:
            return f"NOT WRITING ({self.pending} in memory): {self.last_error}", False
        return f"{name}: {self.committed} written", True

    def close(self, timeout: float = 5.0) -> None:
        """Ask the child to stop (it flushes the archive), then make sure it has."""
        if self._closed:
            return
        self._closed = True
        if self._process.is_alive():
            try:
                self._requests.put(None)
            except (OSError, ValueError):
                pass
            self._process.join(timeout)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(timeout)
        for q in (self._requests, self._results):
            q.close()
            q.cancel_join_thread()


__all__ = ["CommandNotSent", "LinkProcess", "LinkSettings", "LinkStartError", "SentInfo"]
