"""10,000 hostile datagrams at the CRS's command port over real UDP, while an operator commands it.

The corpus (:mod:`tlt_tools.hostile_corpus`, seeded) is built from commands the CRS has already
accepted and sent from an attacker's socket in bursts; between bursts the test waits until the
receive thread has handled each datagram (so none is lost to a full socket buffer and every one
can be matched to what the CRS made of it), and now and then the operator sends a genuine
command. Every hostile datagram must be refused with a specific reason (never ``internal_error``),
counted in the link statistics the CRS reports to the ground, never acted on; every genuine
command before, during and after the flood is accepted and handed over exactly once.
"""

from __future__ import annotations

import os
import socket
import time
from collections import Counter

from tlt_tools.hostile_corpus import CATEGORIES, REFUSED_AS, hostile_corpus

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import Packet, ParseResult, Rejection
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_crs.ground_link import GroundCommand, GroundLink
from tlt_gsw.link import GswLink

DEFS = load_definitions()
COUNT = 10_000
BURST = 32  # datagrams sent before waiting for the CRS: well inside a default socket buffer
OPERATOR_EVERY = 31  # bursts between two genuine commands
WAIT = 10.0


def wait_handled(results: list[ParseResult], expected: int) -> None:
    deadline = time.monotonic() + WAIT
    while len(results) < expected:
        assert time.monotonic() < deadline, f"the CRS handled {len(results)} of {expected} datagrams"
        time.sleep(0.0005)


def test_a_hostile_corpus_is_refused_counted_and_never_acted_on(tmp_path):
    keyring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
    acted: list[GroundCommand] = []
    results: list[ParseResult] = []
    operator = GswLink(DEFS, keyring, 1, ("127.0.0.1", 9))
    crs = GroundLink(
        DEFS,
        keyring,
        tmp_path / "replay.json",
        gsw_address=operator.address,
        on_command=acted.append,
        stats_period_s=0,
    )
    handle = crs.handle_datagram

    def handle_and_keep(data: bytes, source: tuple[str, int] | None = None) -> ParseResult:
        result = handle(data, source)  # the receive thread's own handling, its result kept in order
        results.append(result)
        return result

    crs.handle_datagram = handle_and_keep
    operator.crs_address = crs.address
    attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    genuine: list[str] = []  # the names of the operator's commands, in order
    sent_by: list[str | None] = []  # per datagram the CRS handled: the hostile category, or None

    def command(name: str, params: dict | None = None) -> bytes:
        sent = operator.send_command(name, params)
        sent_by.append(None)
        genuine.append(name)
        ack = operator.wait_ack(sent, timeout=WAIT)
        assert ack is not None and ack.stage is AckStage.ACCEPTED, ack
        wait_handled(results, len(sent_by))
        return sent.raw

    crs.start()
    try:
        captures = [
            command("start"),
            command("pause"),
            command("resume"),
            command("set_blackboard_value", {"key": "lifter_speed", "value": 0.02}),
            command("set_actuator_state", {"actuator": "camera_mounts", "state": "move", "value": 0.5}),
        ]
        corpus = hostile_corpus(DEFS, "crs", captures, count=COUNT, seed=66)
        started = time.monotonic()
        for burst, first in enumerate(range(0, COUNT, BURST)):
            for item in corpus[first : first + BURST]:
                attacker.sendto(item.data, crs.address)
                sent_by.append(item.category)
            wait_handled(results, len(sent_by))
            operator.poll(0.0)  # the ground reads what the CRS reports (events, rejected replays' acks)
            if burst % OPERATOR_EVERY == OPERATOR_EVERY - 1:
                command("pause" if burst % 2 else "resume")  # the operator goes on working
        flood_s = time.monotonic() - started
        command("stop")  # after the flood: still served
        assert crs._thread is not None and crs._thread.is_alive()

        # Every datagram was handled, in the order sent: match each to what the CRS made of it.
        assert len(results) == len(sent_by)
        by_category: dict[str, Counter] = {name: Counter() for name in CATEGORIES}
        for category, result in zip(sent_by, results, strict=True):
            if category is None:
                assert isinstance(result, Packet), result
                continue
            assert isinstance(result, Rejection), (category, result)
            by_category[category][result.reason.label] += 1
        for category, reasons in by_category.items():
            assert sum(reasons.values()) >= COUNT // len(CATEGORIES), category
            assert Reason.INTERNAL_ERROR.label not in reasons, (category, reasons)
            if category in REFUSED_AS:
                assert set(reasons) == {REFUSED_AS[category]}, (category, reasons)
        assert [c.name for c in acted] == genuine  # the operator's commands, once each, in order

        stats = crs.stats
        assert stats.packets_rx == len(sent_by)
        assert stats.rejections == COUNT and sum(stats.by_reason.values()) == COUNT
        assert stats.commands_accepted == len(genuine)
        assert Reason.INTERNAL_ERROR.label not in stats.by_reason
        assert len(stats.by_reason) >= 10  # many different checks caught something
        assert stats.crc_errors == stats.by_reason["bad_crc"] > 0

        # The counts reach the ground in the CRS's link_stats packet.
        crs.send_link_stats()
        deadline = time.monotonic() + WAIT
        reported = None
        while reported is None and time.monotonic() < deadline:
            for result in operator.poll(0.05):
                if isinstance(result, Packet) and result.kind == "link_stats":
                    reported = result.fields
        assert reported is not None
        assert (reported["packets_rx"], reported["rejections"], reported["commands_accepted"]) == (
            len(sent_by),
            COUNT,
            len(genuine),
        )
        assert flood_s < 60, f"the flood took {flood_s:.1f} s"
    finally:
        attacker.close()
        crs.close()
        operator.close()
