"""The GSW end of the CCSDS ground link over UDP (paper §V.A, Fig. 3 and Fig. 6).

Sends authenticated commands to the CRS (:meth:`GswLink.send_command`), receives telemetry
(:meth:`GswLink.poll`), drops unparsed any datagram whose source is not an accepted one
(``gsw.accept_from``: archived as rejected with reason ``source``, counted per source, logged at a
bounded rate), authenticates the rest with the telemetry keys of the key ring
(:class:`TelemetryVerifier`: MAC, replay window, key retirement), counts it (:class:`LinkStats`:
gaps per APID, CRC errors, rejections per reason) and hands every datagram sent or received to the
archive :class:`Recorder`. A telemetry packet that fails authentication is archived as rejected
with its reason, logged, and never decoded or handed on as telemetry. Acknowledgements are
matched to the command they answer by its security sequence number (a ``replay`` rejection of a
command already acknowledged answers a replayed copy, not the command, and is not matched);
:meth:`GswLink.wait_ack` waits for a stage with a bounded timeout. Nothing here blocks without a timeout.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import socket
import sqlite3
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from tlt_common.ccsds.auth import CommandSequencer, KeyRing
from tlt_common.ccsds.codec import Packet, ParseResult, Rejection, encode_command, parse_datagram
from tlt_common.ccsds.definitions import Definitions
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_common.ccsds.sequence import SequenceCounters
from tlt_common.ccsds.sources import Source, SourceFilter, parse_sources
from tlt_common.ccsds.stats import LinkStats
from tlt_common.ccsds.tm_security import TelemetryVerifier
from tlt_common.rate_limit import TokenBucket
from tlt_gsw.archive.recorder import Recorder

_log = logging.getLogger(__name__)
RECV_BUFFER = 65535
# Rejected telemetry is logged at most this often per second (each one is archived regardless).
REJECTION_LOGS_PER_S = 5
MAX_TRACKED_COMMANDS = 1000


def host_port(text: str) -> tuple[str, int]:
    """``host:port`` from the command line (an argparse ``type``)."""
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected host:port, got {text!r}")
    return host, int(port)


def accepted_sources(
    gsw_config: Mapping[str, Any], crs_override: tuple[str, int] | None = None
) -> list[Source] | None:
    """The sources telemetry is taken from: ``gsw.accept_from`` of a loaded link configuration,
    plus the CRS address given on the command line (``--crs``), which answers from there."""
    accepted = parse_sources(gsw_config["accept_from"])
    if accepted is not None and crs_override is not None:
        host, port = crs_override
        try:
            address = socket.gethostbyname(host)
        except OSError:
            address = host  # sending to it fails with its own message
        accepted.append((address, port))
    return accepted


@dataclass(frozen=True)
class Ack:
    """One acknowledgement packet for a command."""

    stage: AckStage
    reason: Reason
    detail: str
    command: str
    received_at: float
    packet: Packet


@dataclass
class SentCommand:
    """A command as sent, and the acknowledgements received for it so far."""

    name: str
    params: Mapping[str, Any]
    security_seq: int
    seq_count: int
    raw: bytes
    sent_at: float
    acks: list[Ack] = field(default_factory=list)

    @property
    def last_stage(self) -> AckStage | None:
        return self.acks[-1].stage if self.acks else None

    @property
    def final(self) -> Ack | None:
        """The rejected/completed/failed ack, if one arrived."""
        return next((a for a in self.acks if a.stage.final), None)


class GswLink:
    """Command sender and telemetry receiver of the ground station.

    ``accept_from`` lists the (address, port or None for any port) sources telemetry is taken
    from; None takes it from any source.
    """

    def __init__(
        self,
        definitions: Definitions,
        keyring: KeyRing,
        key_id: int,
        crs_address: tuple[str, int],
        *,
        bind: tuple[str, int] = ("127.0.0.1", 0),
        recorder: Recorder | None = None,
        sequencer: CommandSequencer | None = None,
        on_packet: Callable[[ParseResult], None] | None = None,
        close_recorder: bool = False,
        clock: Callable[[], float] = time.time,
        recv_buffer_bytes: int | None = None,
        tm_key_overlap_s: float = 30.0,
        accept_from: list[Source] | None = None,
    ) -> None:
        key = keyring.get(key_id)
        if key is None:
            raise KeyError(f"key id {key_id} is not in the key ring (have {keyring.key_ids})")
        self.defs = definitions
        self.keyring = keyring
        self.key_id = key_id
        self._key = key
        self.crs_address = crs_address
        self.recorder = recorder
        self._close_recorder = close_recorder
        self.sequencer = sequencer or CommandSequencer()
        self.on_packet = on_packet
        self.clock = clock
        self.stats = LinkStats()
        self.sources = SourceFilter(accept_from, _log)
        self.tm_verifier = TelemetryVerifier(keyring.telemetry, overlap_s=tm_key_overlap_s)
        if not self.tm_verifier.key_ids:
            _log.warning("no telemetry keys in the key ring: every telemetry packet will be rejected")
        self._rejection_logs = TokenBucket(REJECTION_LOGS_PER_S, REJECTION_LOGS_PER_S)
        self._seed_replay_window()
        self._counters = SequenceCounters()
        self._sent: dict[int, SentCommand] = {}
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if recv_buffer_bytes:
            # The default (about 200 KiB, a few hundred small datagrams) overflows when the receiving
            # process is not scheduled for a tenth of a second at thousands of packets/s; the kernel
            # caps the request at net.core.rmem_max.
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, recv_buffer_bytes)
        self._sock.bind(bind)

    @property
    def address(self) -> tuple[str, int]:
        return self._sock.getsockname()

    def close(self) -> None:
        """Close the socket; flush the recorder (and close it if this link was given it to own)."""
        self._sock.close()
        if self.recorder is not None:
            if self._close_recorder:
                self.recorder.close()
            else:
                self.recorder.flush()

    def __enter__(self) -> GswLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- commands ---------------------------------------------------------------------------
    def send_command(
        self, name: str, params: Mapping[str, Any] | None = None, *, check: bool = True
    ) -> SentCommand:
        """Build, record and send one command; raise FieldError/KeyError on bad parameters."""
        params = dict(params or {})
        if name == "switch_tm_key":
            # Read the key file again first: the next telemetry key may have been added for this
            # rotation, and the CRS's answer comes under it.
            self.keyring = self.keyring.reload()
            self.tm_verifier.add_keys(self.keyring.telemetry)
        security_seq = self.sequencer.next()
        seq_count = self._counters.next(self.defs.command_apid)
        raw = encode_command(
            self.defs,
            name,
            params,
            key_id=self.key_id,
            key=self._key,
            security_seq=security_seq,
            seq_count=seq_count,
            timestamp=self.clock(),
            check=check,
        )
        sent = SentCommand(name, params, security_seq, seq_count, raw, self.clock())
        self._sent[security_seq] = sent
        while len(self._sent) > MAX_TRACKED_COMMANDS:
            self._sent.pop(next(iter(self._sent)))
        self._sock.sendto(raw, self.crs_address)
        self.stats.record_tx(len(raw))
        if self.recorder is not None:
            self.recorder.record("tx", raw, parse_datagram(raw, self.defs, expect="tc", keyring=self.keyring))
        return sent

    def send_raw(self, datagram: bytes) -> None:
        """Send bytes as they are (link diagnostics, replay tests); recorded as ``tx`` undecoded."""
        self._sock.sendto(datagram, self.crs_address)
        self.stats.record_tx(len(datagram))
        if self.recorder is not None:
            self.recorder.record("tx", datagram)

    def wait_ack(self, sent: SentCommand, *, final: bool = False, timeout: float = 2.0) -> Ack | None:
        """Wait for the first ack of ``sent`` (or, with ``final``, its rejected/completed/failed ack).

        Returns that ack, or None after ``timeout`` seconds. Telemetry arriving meanwhile is
        processed (counted, recorded) as :meth:`poll` does.
        """
        deadline = time.monotonic() + timeout
        while True:
            found = sent.final if final else (sent.acks[0] if sent.acks else None)
            if found is not None:
                return found
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self.poll(left)

    # -- telemetry --------------------------------------------------------------------------
    def poll(self, timeout: float = 0.1, max_packets: int = 1000) -> list[ParseResult]:
        """Receive what arrives within ``timeout`` (returns as soon as one batch was read)."""
        results: list[ParseResult] = []
        self._sock.settimeout(max(timeout, 1e-4))
        try:
            data, source = self._sock.recvfrom(RECV_BUFFER)
        except (TimeoutError, BlockingIOError):
            # A quiet link must still commit what was buffered before it went quiet.
            if self.recorder is not None:
                self.recorder.maybe_flush()
            return results
        results.append(self._handle(data, source))
        self._sock.setblocking(False)
        try:
            while len(results) < max_packets:
                data, source = self._sock.recvfrom(RECV_BUFFER)
                results.append(self._handle(data, source))
        except (BlockingIOError, InterruptedError):
            pass
        if self.recorder is not None:
            self.recorder.maybe_flush()
        return results

    def _handle(self, data: bytes, source: tuple[str, int]) -> ParseResult:
        now = self.clock()
        if not self.sources.allows(source):
            # Not parsed at all: kept as evidence, counted, logged, never handed on as telemetry.
            rejection = Rejection(Reason.SOURCE, self.sources.note_drop(source), bytes(data))
            self.stats.record_foreign(len(data), source)
            if self.recorder is not None:
                self.recorder.record("rx", data, rejection, recorded_at=now)
            if self.on_packet is not None:
                self.on_packet(rejection)
            return rejection
        verifier = self.tm_verifier
        result = parse_datagram(data, self.defs, expect="tm", keyring=verifier, replay=verifier)
        if isinstance(result, Rejection):
            result = self._rejected(result)
        self.stats.record_rx(len(data), result)
        if self.recorder is not None:
            self.recorder.record("rx", data, result, recorded_at=now)
        if isinstance(result, Packet) and result.kind == "ack":
            fields = result.fields
            sent = self._sent.get(fields["security_seq"])
            # A replay rejection of an already answered command answers someone's copy of it.
            if sent is not None and not (sent.acks and fields["reason"] == Reason.REPLAY.label):
                sent.acks.append(
                    Ack(
                        AckStage[fields["stage"].upper()],
                        Reason[fields["reason"].upper()],
                        fields["detail"],
                        fields["command"],
                        now,
                        result,
                    )
                )
        if self.on_packet is not None:
            self.on_packet(result)
        return result

    def _seed_replay_window(self, newest: int = 256) -> None:
        """After a GSW restart, refuse telemetry the archive already holds as accepted: the
        ``newest`` accepted packets are verified again with this link's telemetry keys (rows of
        other keys or runs do not verify and are skipped) and set each key id's floor."""
        if self.recorder is None or not self.recorder.path.exists():
            return
        try:
            conn = sqlite3.connect(f"file:{self.recorder.path}?mode=ro", uri=True)
            try:
                newest_first = (
                    "SELECT raw FROM packets WHERE direction = 'rx' AND status = 'ok' ORDER BY id DESC"
                )
                rows = conn.execute(f"{newest_first} LIMIT ?", (newest,)).fetchall()
            finally:
                conn.close()
        except sqlite3.Error as exc:
            _log.warning("cannot read %s for the telemetry replay window: %s", self.recorder.path, exc)
            return
        floors: dict[int, int] = {}
        for (raw,) in rows:
            result = parse_datagram(raw, self.defs, expect="tm", keyring=self.tm_verifier)
            if isinstance(result, Packet) and result.key_id is not None and result.security_seq is not None:
                floors[result.key_id] = max(floors.get(result.key_id, 0), result.security_seq)
        for key_id, last in floors.items():
            self.tm_verifier.seed(key_id, last)

    def _rejected(self, rejection: Rejection) -> Rejection:
        """Name a retired key as such, and log the rejection (rate limited)."""
        key_id = rejection.key_id
        if rejection.reason is Reason.UNKNOWN_KEY and key_id is not None and self.tm_verifier.retired(key_id):
            rejection = dataclasses.replace(
                rejection, detail=f"telemetry key id {key_id} is retired (superseded by a newer key)"
            )
        if self._rejection_logs.allow():
            _log.warning(
                "telemetry rejected (APID %s, key id %s): %s: %s",
                rejection.apid,
                key_id,
                rejection.reason.label,
                rejection.detail,
            )
        return rejection


__all__ = ["Ack", "GswLink", "SentCommand", "accepted_sources"]
