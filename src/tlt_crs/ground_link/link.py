"""The CRS end of the CCSDS ground link over UDP (paper §V.A), owned by the CRS node.

Reads command datagrams on a UDP socket, and for each one:

* drops it unparsed if its source is not one the configuration accepts (``crs.accept_from``,
  :class:`SourceFilter`): counted per source, logged and reported as an ``event`` (both rate
  limited), never acknowledged;
* parses, authenticates and checks it against replay (:func:`parse_datagram`), counting it in
  :class:`LinkStats`;
* a refused datagram is reported as an ``event`` packet and, when it carries a command header, an
  ``ack`` packet at stage *rejected* with the reason code; it is never acted on;
* ``switch_tm_key`` (link management) is carried out by the link itself: acknowledged *accepted*
  under the current telemetry key, then *completed* under the next one (or *failed* if the key
  file has no next one);
* any other accepted command is acknowledged at stage *accepted* first and then handed to the
  ``on_command`` callback (called on the receive thread), or, without one, put on the
  :attr:`GroundLink.commands` queue. The CRS reports the outcome later with
  :meth:`GroundLink.complete` (stage *completed* or *failed*).

Writes telemetry packets the caller gives (:meth:`send_telemetry`) and periodic ``link_stats``,
each signed with the current telemetry key (:class:`TelemetrySigner`, never a command key).
Telemetry goes to the configured GSW address, else to the source of the last *authenticated*
command; acks of an authenticated command also go back to its sender. An unauthenticated sender
never receives anything. Nothing a datagram contains can stop the receive thread: every failure
is caught, counted and reported.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tlt_common.ccsds.auth import KeyFileError, KeyRing, ReplayGuard
from tlt_common.ccsds.codec import Packet, ParseResult, Rejection, parse_datagram
from tlt_common.ccsds.definitions import Definitions, load_definitions
from tlt_common.ccsds.link_config import expand_path, load_link_config
from tlt_common.ccsds.reasons import AckStage, Reason, Severity
from tlt_common.ccsds.sequence import SequenceCounters
from tlt_common.ccsds.sources import Source, SourceFilter, parse_sources
from tlt_common.ccsds.stats import LinkStats
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_common.rate_limit import TokenBucket

_log = logging.getLogger(__name__)
RECV_BUFFER = 65535
SWITCH_TM_KEY = "switch_tm_key"


@dataclass(frozen=True)
class GroundCommand:
    """An authenticated, checked command handed to the CRS."""

    name: str
    params: Mapping[str, Any]
    command_id: int
    security_seq: int
    seq_count: int
    key_id: int
    sent_at: float
    received_at: float
    source: tuple[str, int] | None = None


Validator = Callable[[GroundCommand], "tuple[Reason, str] | None"]


class GroundLink:
    """CRS side of the link: receive thread, command verification, acknowledgements, telemetry.

    ``replay_state`` is the file holding the last accepted security sequence per key; a new
    instance on the same file refuses everything the old one accepted. ``validator`` lets the CRS
    refuse a well-formed command (e.g. a blackboard key that is not ground-writable) with a reason
    before it is acknowledged as accepted. ``tm_key_id`` is the telemetry key to sign with first
    (default: the lowest telemetry key id of ``keyring``); a ring without telemetry keys raises
    :class:`KeyFileError`. ``accept_from`` lists the (address, port or None for any port) sources
    commands are taken from; None takes them from any source.
    """

    def __init__(
        self,
        definitions: Definitions,
        keyring: KeyRing,
        replay_state: str | Path,
        *,
        bind: tuple[str, int] = ("127.0.0.1", 0),
        gsw_address: tuple[str, int] | None = None,
        on_command: Callable[[GroundCommand], None] | None = None,
        validator: Validator | None = None,
        source_name: str = "crs.ground_link",
        max_rejection_events_per_s: float = 20.0,
        stats_period_s: float | None = None,
        clock: Callable[[], float] = time.time,
        tm_key_id: int | None = None,
        accept_from: list[Source] | None = None,
    ) -> None:
        self.defs = definitions
        self.sources = SourceFilter(accept_from, _log)
        self.keyring = keyring
        tm_keys = keyring.telemetry
        self.tm_signer = TelemetrySigner(
            tm_keys, tm_key_id if tm_key_id is not None else min(tm_keys.key_ids, default=0)
        )
        self.replay = ReplayGuard(replay_state)
        self.on_command = on_command
        self.validator = validator
        self.source_name = source_name
        self.clock = clock
        self.stats = LinkStats()
        self.commands: queue.Queue[GroundCommand] = queue.Queue()
        self.telemetry_dropped = 0
        self._configured_gsw = gsw_address
        self._learned_gsw: tuple[str, int] | None = None
        self._counters = SequenceCounters()
        self._send_lock = threading.Lock()
        self._limiter = TokenBucket(max_rejection_events_per_s, max(1.0, max_rejection_events_per_s))
        rate = definitions.packet("link_stats").rate_hz
        self._stats_period = stats_period_s if stats_period_s is not None else (1.0 / rate if rate else None)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind(bind)
        except OSError as exc:
            self._sock.close()
            raise OSError(
                exc.errno, f"cannot bind the ground link to {bind[0]}:{bind[1]}: {exc.strerror}"
            ) from exc
        self._sock.settimeout(0.1)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @classmethod
    def from_config(
        cls,
        config: Mapping[str, Any] | None = None,
        definitions: Definitions | None = None,
        **options: Any,
    ) -> GroundLink:
        """Build from the link settings (``load_link_config()``: bind address, GSW address, key file,
        replay state, rejection report rate); ``options`` pass through (``on_command``, ...).

        Raises ConfigError, KeyFileError or ReplayStateError with a message naming the file.
        """
        conf = config if config is not None else load_link_config()
        crs = conf["crs"]
        key_file = conf["key_file"]
        gsw = (crs["gsw_host"], crs["gsw_port"]) if crs["gsw_host"] else None
        options.setdefault("max_rejection_events_per_s", crs["max_rejection_events_per_s"])
        options.setdefault("accept_from", parse_sources(crs["accept_from"]))
        return cls(
            definitions or load_definitions(),
            KeyRing.load(expand_path(key_file) if key_file else None),
            expand_path(crs["replay_state"]),
            bind=(crs["bind_host"], crs["bind_port"]),
            gsw_address=gsw,
            tm_key_id=conf["tm_key_id"],
            **options,
        )

    # -- life cycle -------------------------------------------------------------------------
    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port) commands are received on."""
        return self._sock.getsockname()

    @property
    def gsw_address(self) -> tuple[str, int] | None:
        """Where telemetry goes: the configured address, else the last authenticated sender."""
        return self._configured_gsw or self._learned_gsw

    @gsw_address.setter
    def gsw_address(self, address: tuple[str, int] | None) -> None:
        self._configured_gsw = address

    def start(self) -> GroundLink:
        """Start the receive thread (idempotent)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="ground-link-rx", daemon=True)
            self._thread.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        """Stop the receive thread and close the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        self._sock.close()

    def __enter__(self) -> GroundLink:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        next_stats = time.monotonic() + (self._stats_period or 0.0)
        while not self._stop.is_set():
            try:
                data, addr = self._sock.recvfrom(RECV_BUFFER)
            except TimeoutError:
                data = None
            except OSError:
                if self._stop.is_set():
                    return
                _log.exception("ground link receive failed")
                time.sleep(0.05)
                continue
            if data is not None:
                try:
                    self.handle_datagram(data, addr)
                except Exception:  # a bug here must not end the link; it is logged and reported
                    _log.exception("ground link failed on a datagram from %s", addr)
                    self._safe_event(
                        Severity.ERROR,
                        "LINK_INTERNAL_ERROR",
                        Reason.INTERNAL_ERROR,
                        "internal error while handling a datagram",
                    )
            if self._stats_period and time.monotonic() >= next_stats:
                next_stats = time.monotonic() + self._stats_period
                self.send_link_stats()

    # -- receive ----------------------------------------------------------------------------
    def handle_datagram(self, data: bytes, source: tuple[str, int] | None = None) -> ParseResult:
        """Process one datagram as the receive thread does; return what the parser made of it (a
        datagram from a source not accepted is a ``source`` rejection, never parsed)."""
        if source is not None and not self.sources.allows(source):
            return self._drop_foreign(data, source)
        result = parse_datagram(data, self.defs, expect="tc", keyring=self.keyring, replay=self.replay)
        self.stats.record_rx(len(data), result)
        if isinstance(result, Rejection):
            self._reject(result, source)
            return result
        assert isinstance(result, Packet)
        command = GroundCommand(
            name=result.kind,
            params=dict(result.fields),
            command_id=result.command_id or 0,
            security_seq=result.security_seq or 0,
            seq_count=result.seq_count,
            key_id=result.key_id or 0,
            sent_at=result.time,
            received_at=self.clock(),
            source=source,
        )
        if source is not None:
            self._learned_gsw = source
        if command.name == SWITCH_TM_KEY:
            self._switch_tm_key(command)
            return result
        if self.validator is not None:
            try:
                refusal = self.validator(command)
            except Exception as exc:
                _log.exception("command validator failed")
                refusal = (Reason.INTERNAL_ERROR, f"validator failed: {exc}")
            if refusal is not None:
                reason, detail = refusal
                rejection = Rejection(
                    reason,
                    detail,
                    bytes(data),
                    apid=result.apid,
                    packet_type="tc",
                    seq_count=result.seq_count,
                    key_id=command.key_id,
                    security_seq=command.security_seq,
                    command_id=command.command_id,
                    authenticated=True,
                )
                self.stats.record_refusal(reason)
                self._reject(rejection, source)
                return rejection
        self._accept(command)
        if self.on_command is None:
            self.commands.put(command)
        else:
            try:
                self.on_command(command)
            except Exception as exc:
                _log.exception("command handler failed on %s", command.name)
                self.complete(command, False, Reason.INTERNAL_ERROR, f"handler failed: {exc}")
        return result

    def _accept(self, command: GroundCommand) -> None:
        """Count ``command`` accepted and acknowledge it so."""
        self.stats.record_accepted()
        self._ack(
            command.seq_count,
            command.security_seq,
            command.command_id,
            AckStage.ACCEPTED,
            Reason.NONE,
            "",
            command.source,
        )

    def _drop_foreign(self, data: bytes, source: tuple[str, int]) -> Rejection:
        text = self.sources.note_drop(source)
        self.stats.record_foreign(len(data), source)
        rejection = Rejection(Reason.SOURCE, text, bytes(data))
        # Reported like other unauthenticated junk: an event, rate limited, nothing sent to the source.
        if self._limiter.allow():
            suppressed = self._limiter.take_suppressed()
            if suppressed:
                text += f" ({suppressed} earlier rejection report(s) suppressed)"
            self._safe_event(Severity.WARNING, "DATAGRAM_REJECTED", Reason.SOURCE, text)
        return rejection

    def _switch_tm_key(self, command: GroundCommand) -> None:
        """Move telemetry to the next key id: the accepted ack still under the old key, the
        completed ack (and everything after it) under the new one."""
        self._accept(command)
        old = self.tm_signer.key_id
        try:
            # The key file is read again, so a key added to it for this rotation is found.
            self.keyring = self.keyring.reload()
            new = self.tm_signer.switch_to_next(self.keyring.telemetry)
        except KeyFileError as exc:
            self.complete(command, False, Reason.EXECUTION_FAILED, str(exc))
            return
        _log.info("telemetry key id %d -> %d on ground command", old, new)
        self.complete(command, True, detail=f"telemetry key id {old} -> {new}")
        text = f"telemetry now signed with key id {new} (was {old})"
        self._safe_event(Severity.INFO, "TM_KEY_SWITCHED", Reason.NONE, text)

    def _reject(self, rejection: Rejection, source: tuple[str, int] | None) -> None:
        # Unauthenticated junk is rate limited; an authenticated command is always answered.
        if not rejection.authenticated and not self._limiter.allow():
            return
        suppressed = self._limiter.take_suppressed()
        is_command = rejection.packet_type == "tc" and rejection.apid == self.defs.command_apid
        label = self._command_label(rejection.command_id) if rejection.authenticated else "unverified"
        where = f"{source[0]}:{source[1]}" if source else "unknown source"
        text = f"{label} from {where} rejected: {rejection.reason.label}: {rejection.detail}"
        if suppressed:
            text += f" ({suppressed} earlier rejection report(s) suppressed)"
        self._safe_event(
            Severity.WARNING,
            "COMMAND_REJECTED" if is_command else "DATAGRAM_REJECTED",
            rejection.reason,
            text,
        )
        if is_command:
            self._ack(
                rejection.seq_count or 0,
                rejection.security_seq or 0,
                (rejection.command_id or 0) if rejection.authenticated else 0,
                AckStage.REJECTED,
                rejection.reason,
                rejection.detail,
                # Answer the sender only if it holds the key and is not replaying someone's packet.
                source if rejection.authenticated and rejection.reason is not Reason.REPLAY else None,
            )

    def _command_label(self, command_id: int | None) -> str:
        cmd = self.defs.commands_by_id.get(command_id or -1)
        return cmd.name if cmd else f"command id {command_id}"

    # -- send -------------------------------------------------------------------------------
    def complete(
        self, command: GroundCommand, success: bool = True, reason: Reason = Reason.NONE, detail: str = ""
    ) -> None:
        """Acknowledge the outcome of an accepted command: stage completed, or failed with a reason."""
        if success:
            stage, reason = AckStage.COMPLETED, Reason.NONE
        else:
            stage = AckStage.FAILED
            reason = reason if reason is not Reason.NONE else Reason.EXECUTION_FAILED
        self._ack(
            command.seq_count, command.security_seq, command.command_id, stage, reason, detail, command.source
        )

    def _ack(
        self,
        seq_count: int,
        security_seq: int,
        command_id: int,
        stage: AckStage,
        reason: Reason,
        detail: str,
        reply_to: tuple[str, int] | None = None,
    ) -> None:
        command = command_id if command_id < len(self.defs.enums["command"]) else 0
        self.send_telemetry(
            "ack",
            {
                "command_apid": self.defs.command_apid,
                "command_seq_count": seq_count,
                "security_seq": security_seq,
                "command": command,
                "stage": int(stage),
                "reason": int(reason),
                "detail": _clip(detail, 200),
            },
            also_to=reply_to,
        )

    def send_event(
        self, severity: Severity, code: str, text: str, reason: Reason = Reason.NONE
    ) -> bytes | None:
        """Send an ``event`` packet from this link's source name."""
        return self.send_telemetry(
            "event",
            {
                "severity": int(severity),
                "source": _clip(self.source_name, 32),
                "code": _clip(code, 48),
                "reason": int(reason),
                "text": _clip(text, 200),
            },
        )

    def _safe_event(self, severity: Severity, code: str, reason: Reason, text: str) -> None:
        try:
            self.send_event(severity, code, text, reason)
        except Exception:
            _log.exception("could not send event %s", code)

    def send_link_stats(self) -> bytes | None:
        return self.send_telemetry("link_stats", self.stats.as_fields())

    def send_telemetry(
        self,
        kind: str,
        values: Mapping[str, Any],
        timestamp: float | None = None,
        also_to: tuple[str, int] | None = None,
    ) -> bytes | None:
        """Encode and send one telemetry packet; return its bytes, or None if it went nowhere.

        It goes to the GSW address and, if given and different, to ``also_to`` (the authenticated
        sender of the command an ack answers). Raises KeyError/ValueError (FieldError) if
        ``values`` do not match the definition of ``kind``.
        """
        pdef = self.defs.packet(kind)
        with self._send_lock:
            targets = [t for t in (self.gsw_address, also_to) if t is not None]
            if len(targets) == 2 and targets[0] == targets[1]:
                targets.pop()
            if not targets:
                self.telemetry_dropped += 1
                return None
            raw = self.tm_signer.encode(
                self.defs,
                kind,
                values,
                seq_count=self._counters.next(pdef.apid),
                timestamp=self.clock() if timestamp is None else timestamp,
            )
            sent = False
            for target in targets:
                try:
                    self._sock.sendto(raw, target)
                except OSError as exc:
                    # A GSW that is not listening must not stop the CRS; the loss shows as a gap.
                    _log.warning("telemetry to %s failed: %s", target, exc)
                    continue
                sent = True
                self.stats.record_tx(len(raw))
            if not sent:
                self.telemetry_dropped += 1
                return None
            return raw


def _clip(text: str, size: int) -> str:
    encoded = text.encode("utf-8")
    if len(encoded) <= size:
        return text
    return encoded[: size - 3].decode("utf-8", errors="ignore") + "..."


__all__ = ["GroundCommand", "GroundLink"]
