"""The CRS ground link over real UDP on 127.0.0.1, against the GSW link.

Each test runs a :class:`GroundLink` with its receive thread and a :class:`GswLink` in the test
thread; waits are bounded by generous timeouts and end as soon as the expected packet arrives.
"""

from __future__ import annotations

import os
import queue
import socket
import time

import pytest

from tlt_common.ccsds.auth import CommandSequencer, KeyRing
from tlt_common.ccsds.codec import Packet, encode_command
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_crs.ground_link import GroundCommand, GroundLink
from tlt_gsw.link import GswLink

DEFS = load_definitions()
WAIT = 5.0


@pytest.fixture
def keyring():
    return KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})


@pytest.fixture
def crs(tmp_path, keyring):
    handled: queue.Queue[GroundCommand] = queue.Queue()
    link = GroundLink(DEFS, keyring, tmp_path / "replay.json", on_command=handled.put, stats_period_s=0)
    link.handled = handled
    link.start()
    yield link
    link.close()


@pytest.fixture
def gsw(crs, keyring):
    link = GswLink(DEFS, keyring, 1, crs.address)
    yield link
    link.close()


def _collect(gsw: GswLink, *predicates, timeout: float = WAIT) -> list:
    """Poll until every predicate matched some received packet; return everything received."""
    seen: list = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        seen.extend(gsw.poll(0.05))
        if all(any(p(r) for r in seen) for p in predicates):
            return seen
    raise AssertionError(f"not everything matched within {timeout} s; got {seen}")


def _is(kind: str, **fields):
    def match(result) -> bool:
        return (
            isinstance(result, Packet)
            and result.kind == kind
            and all(result.fields.get(k) == v for k, v in fields.items())
        )

    return match


def test_start_is_accepted_handed_over_and_completed(crs, gsw):
    sent = gsw.send_command("start")
    ack = gsw.wait_ack(sent, timeout=WAIT)
    assert ack is not None and ack.stage is AckStage.ACCEPTED and ack.command == "start"
    command = crs.handled.get(timeout=WAIT)
    assert (command.name, command.security_seq, command.seq_count) == (
        "start",
        sent.security_seq,
        sent.seq_count,
    )
    assert crs.commands.empty()  # with a callback, the queue is not used
    crs.complete(command)
    final = gsw.wait_ack(sent, final=True, timeout=WAIT)
    assert final.stage is AckStage.COMPLETED and final.reason is Reason.NONE
    crs.complete(command, success=False, detail="lifter fault")
    _collect(gsw, _is("ack", stage="failed", reason="execution_failed", detail="lifter fault"))


def test_parameters_reach_the_handler(crs, gsw):
    sent = gsw.send_command("set_blackboard_value", {"key": "mission.skip_bay", "value": 3})
    assert gsw.wait_ack(sent, timeout=WAIT).stage is AckStage.ACCEPTED
    command = crs.handled.get(timeout=WAIT)
    assert command.params == {"key": "mission.skip_bay", "value": 3}


def test_unauthenticated_datagram_is_rejected_and_reported(crs, gsw, keyring):
    gsw.send_command("pause")  # the CRS learns where the GSW is from an authenticated command
    _collect(gsw, _is("ack", stage="accepted"))
    crs.handled.get(timeout=WAIT)
    intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        forged = encode_command(DEFS, "stop", key_id=1, key=os.urandom(32), security_seq=2**60, seq_count=0)
        intruder.sendto(forged, crs.address)
        _collect(
            gsw,
            _is("ack", stage="rejected", reason="bad_auth", command="none"),
            _is("event", code="COMMAND_REJECTED", reason="bad_auth"),
        )
        intruder.settimeout(0.2)
        with pytest.raises(TimeoutError):  # the forger hears nothing back
            intruder.recvfrom(2048)
    finally:
        intruder.close()
    assert crs.handled.empty()
    assert crs.stats.by_reason["bad_auth"] == 1


def test_replayed_command_is_rejected_and_reported(crs, gsw):
    sent = gsw.send_command("resume")
    assert gsw.wait_ack(sent, timeout=WAIT).stage is AckStage.ACCEPTED
    crs.handled.get(timeout=WAIT)
    gsw.send_raw(sent.raw)
    _collect(gsw, _is("event", code="COMMAND_REJECTED", reason="replay"), _is("ack", stage="rejected"))
    # The rejection answers the copy: it is reported, but it is not an ack of the command itself.
    assert [a.stage for a in sent.acks] == [AckStage.ACCEPTED]
    assert crs.handled.empty()


def test_replay_is_rejected_across_a_crs_restart(tmp_path, keyring):
    state = tmp_path / "replay.json"
    first = GroundLink(DEFS, keyring, state, stats_period_s=0).start()
    try:
        with GswLink(DEFS, keyring, 1, first.address) as gsw:
            sent = gsw.send_command("start")
            assert gsw.wait_ack(sent, timeout=WAIT).stage is AckStage.ACCEPTED
    finally:
        first.close()
    handled: list = []
    second = GroundLink(DEFS, keyring, state, on_command=handled.append, stats_period_s=0).start()
    try:
        with GswLink(DEFS, keyring, 1, second.address, sequencer=CommandSequencer()) as gsw:
            # A replayed packet is never answered to its sender, only reported to the GSW address.
            second.gsw_address = gsw.address
            gsw.send_raw(sent.raw)
            _collect(gsw, _is("ack", stage="rejected", reason="replay"), _is("event", reason="replay"))
            fresh = gsw.send_command("start")
            assert gsw.wait_ack(fresh, timeout=WAIT).stage is AckStage.ACCEPTED
    finally:
        second.close()
    assert [c.security_seq for c in handled] == [fresh.security_seq]


def test_bad_parameter_is_rejected_with_reason(crs, gsw):
    sent = gsw.send_command("set_actuator_state", {"actuator": "lifter", "state": "warp"}, check=False)
    ack = gsw.wait_ack(sent, timeout=WAIT)
    assert ack.stage is AckStage.REJECTED and ack.reason is Reason.BAD_PARAMETER_RANGE
    assert "warp" in ack.detail
    assert crs.handled.empty()


def test_validator_refuses_and_handler_failure_is_reported(tmp_path, keyring):
    def only_writable(command: GroundCommand):
        if command.name == "set_blackboard_value" and command.params["key"] != "speed":
            return Reason.REFUSED, f"{command.params['key']} is not ground-writable"
        return None

    def handler(command: GroundCommand) -> None:
        if command.name == "stop":
            raise RuntimeError("tree missing")

    crs = GroundLink(
        DEFS, keyring, tmp_path / "r.json", validator=only_writable, on_command=handler, stats_period_s=0
    ).start()
    try:
        with GswLink(DEFS, keyring, 1, crs.address) as gsw:
            refused = gsw.send_command("set_blackboard_value", {"key": "bays_total", "value": 1})
            ack = gsw.wait_ack(refused, timeout=WAIT)
            assert (ack.stage, ack.reason) == (AckStage.REJECTED, Reason.REFUSED)
            assert "not ground-writable" in ack.detail
            stop = gsw.send_command("stop")
            final = gsw.wait_ack(stop, final=True, timeout=WAIT)
            assert [a.stage for a in stop.acks] == [AckStage.ACCEPTED, AckStage.FAILED]
            assert final.reason is Reason.INTERNAL_ERROR and "tree missing" in final.detail
    finally:
        crs.close()
    assert crs.stats.commands_accepted == 1 and crs.stats.rejections == 1


def test_junk_is_reported_as_events_and_the_link_keeps_working(crs, gsw):
    gsw.send_command("start")
    _collect(gsw, _is("ack", stage="accepted"))
    for junk in (b"", b"\x00", os.urandom(40), os.urandom(5000)):
        gsw.send_raw(junk)
    _collect(
        gsw,
        _is("event", code="DATAGRAM_REJECTED", reason="truncated"),
        _is("event", code="DATAGRAM_REJECTED", reason="oversized"),
    )
    assert crs.stats.rejections == 4 and crs.handled.get_nowait().name == "start"
    sent = gsw.send_command("pause")
    assert gsw.wait_ack(sent, timeout=WAIT).stage is AckStage.ACCEPTED


def test_telemetry_and_link_stats_reach_the_gsw(crs, gsw):
    gsw.send_command("start")
    _collect(gsw, _is("ack"))
    crs.send_telemetry(
        "hk_mission",
        {
            "run_state": "running",
            "started": True,
            "bays_total": 4,
            "bays_built": 1,
            "current_bay": 2,
            "members_total": 40,
            "members_placed": 12,
            "members_riveted": 10,
            "current_step": "Build Bay 2",
            "fault": "",
        },
    )
    _collect(gsw, _is("hk_mission", current_bay=2, current_step="Build Bay 2"))
    crs.send_link_stats()
    seen = _collect(gsw, _is("link_stats"))
    stats = next(r for r in seen if _is("link_stats")(r)).fields
    assert stats["packets_rx"] >= 1 and stats["commands_accepted"] >= 1
    assert gsw.stats.gaps == 0 and gsw.stats.crc_errors == 0


def test_without_a_callback_commands_wait_in_the_queue(tmp_path, keyring):
    crs = GroundLink(DEFS, keyring, tmp_path / "r.json", stats_period_s=0).start()
    try:
        with GswLink(DEFS, keyring, 1, crs.address) as gsw:
            sent = gsw.send_command("set_actuator_state", {"actuator": "lifter", "state": "safe"})
            assert gsw.wait_ack(sent, timeout=WAIT).stage is AckStage.ACCEPTED
            command = crs.commands.get(timeout=WAIT)
            assert command.params == {"actuator": "lifter", "state": "safe", "value": None}
            crs.complete(command)
            assert gsw.wait_ack(sent, final=True, timeout=WAIT).stage is AckStage.COMPLETED
    finally:
        crs.close()


def test_bind_failure_is_clear(tmp_path, keyring, crs):
    with pytest.raises(OSError, match=r"cannot bind the ground link to 127\.0\.0\.1"):
        GroundLink(DEFS, keyring, tmp_path / "other.json", bind=crs.address)


def test_periodic_link_stats(tmp_path, keyring):
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(WAIT)
    crs = GroundLink(DEFS, keyring, tmp_path / "r.json", gsw_address=sink.getsockname(), stats_period_s=0.05)
    try:
        crs.start()
        apids = {sink.recvfrom(4096)[0][1] for _ in range(2)}
        assert apids == {DEFS.packet("link_stats").apid}
    finally:
        crs.close()
        sink.close()
