"""10,000 hostile datagrams at the GSW's telemetry port over real UDP, among the CRS's telemetry.

The corpus (:mod:`tlt_tools.hostile_corpus`, seeded) is built from telemetry the GSW has already
accepted and sent from an attacker's socket on the CRS's host (a spoofed source passes the source
check: only authentication tells the CRS's word from a forgery), in bursts the GSW reads before
the next; between bursts the CRS stand-in sends genuine signed telemetry. Every hostile datagram
must be refused with a specific reason (never ``internal_error``), counted, archived as rejected
with no decoded field; every genuine packet, before, during and after the flood, is accepted and
archived with its fields, with no gap.
"""

from __future__ import annotations

import os
import socket
import sqlite3
import time
from collections import Counter

from tlt_tools.hostile_corpus import CATEGORIES, REFUSED_AS, hostile_corpus

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import Packet, ParseResult, Rejection
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason
from tlt_common.ccsds.sources import parse_sources
from tlt_common.ccsds.stats import AUTH_REASONS
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.link import GswLink

DEFS = load_definitions()
COUNT = 10_000
BURST = 32  # datagrams sent before the GSW reads them: well inside a default socket buffer
GENUINE_EVERY = 10  # bursts between two genuine telemetry packets
WAIT = 10.0


def read_until(gsw: GswLink, results: list[ParseResult], expected: int) -> None:
    deadline = time.monotonic() + WAIT
    while len(results) < expected:
        assert time.monotonic() < deadline, f"the GSW read {len(results)} of {expected} datagrams"
        gsw.poll(0.05)


def test_a_hostile_corpus_is_archived_as_rejected_and_telemetry_still_flows(tmp_path):
    keyring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
    signer = TelemetrySigner(keyring.telemetry, 1)  # the CRS's signer
    results: list[ParseResult] = []
    archive = tmp_path / "archive.sqlite"
    gsw = GswLink(
        DEFS,
        keyring,
        1,
        ("127.0.0.1", 9),
        recorder=Recorder(archive),
        close_recorder=True,
        on_packet=results.append,
        accept_from=parse_sources(["127.0.0.1"]),
    )
    crs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent_by: list[str | None] = []  # per datagram sent: the hostile category, or None (genuine)

    def telemetry(number: int) -> bytes:
        raw = signer.encode(DEFS, "event", {
            "severity": "info", "source": "crs", "code": "BAY_STEP", "reason": "none",
            "text": f"step {number}",
        }, seq_count=number)  # fmt: skip
        crs.sendto(raw, gsw.address)
        sent_by.append(None)
        read_until(gsw, results, len(sent_by))
        return raw

    try:
        captures = [telemetry(number) for number in range(6)]
        corpus = hostile_corpus(DEFS, "gsw", captures, count=COUNT, seed=66)
        started = time.monotonic()
        for burst, first in enumerate(range(0, COUNT, BURST)):
            for item in corpus[first : first + BURST]:
                attacker.sendto(item.data, gsw.address)
                sent_by.append(item.category)
            read_until(gsw, results, len(sent_by))
            if burst % GENUINE_EVERY == GENUINE_EVERY - 1:
                telemetry(sent_by.count(None))
        flood_s = time.monotonic() - started
        telemetry(sent_by.count(None))  # after the flood: still taken
        genuine = sent_by.count(None)

        assert len(results) == len(sent_by)
        by_category: dict[str, Counter] = {name: Counter() for name in CATEGORIES}
        for number, (category, result) in enumerate(zip(sent_by, results, strict=True)):
            if category is None:
                assert isinstance(result, Packet) and result.kind == "event", (number, result)
                continue
            assert isinstance(result, Rejection), (category, result)
            by_category[category][result.reason.label] += 1
        texts = [r.fields["text"] for r in results if isinstance(r, Packet)]
        assert texts == [f"step {n}" for n in range(genuine)]  # every genuine packet, in order
        for category, reasons in by_category.items():
            assert sum(reasons.values()) >= COUNT // len(CATEGORIES), category
            assert Reason.INTERNAL_ERROR.label not in reasons, (category, reasons)
            if category in REFUSED_AS:
                assert set(reasons) == {REFUSED_AS[category]}, (category, reasons)

        stats = gsw.stats
        assert stats.packets_rx == len(sent_by)
        assert stats.rejections == COUNT and sum(stats.by_reason.values()) == COUNT
        assert stats.auth_rejections == sum(stats.by_reason[r.label] for r in AUTH_REASONS) > 0
        assert stats.crc_errors == stats.by_reason["bad_crc"] > 0
        assert len(stats.by_reason) >= 10  # many different checks caught something
        assert (stats.gaps, stats.missing, gsw.tm_verifier.gaps, gsw.tm_verifier.missing) == (0, 0, 0, 0)
        assert flood_s < 60, f"the flood took {flood_s:.1f} s"
    finally:
        attacker.close()
        crs.close()
        gsw.close()

    conn = sqlite3.connect(archive)
    try:
        statuses = Counter(
            dict(conn.execute("SELECT status, COUNT(*) FROM packets WHERE direction = 'rx' GROUP BY status"))
        )
        assert statuses.pop("ok") == genuine
        assert statuses == stats.by_reason  # each hostile datagram archived with its reason
        rejected_fields = conn.execute(
            "SELECT COUNT(*) FROM fields JOIN packets ON packets.id = fields.packet_id"
            " WHERE packets.status != 'ok'"
        ).fetchone()[0]
        assert rejected_fields == 0  # none of it decoded, none of it shown as telemetry
    finally:
        conn.close()
