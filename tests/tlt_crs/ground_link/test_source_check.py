"""The CRS end takes commands only from the sources ``crs.accept_from`` names, over real UDP.

The CRS is built from a link configuration file (as the CRS node builds it); the GSW is on
127.0.0.1 and a foreign sender on 127.0.0.2 (Linux routes all of 127/8 to loopback). The foreign
sender holds the command key, so what it sends would be accepted from the GSW's address: only the
source check stops it.
"""

from __future__ import annotations

import logging
import os
import socket
import time

import pytest
import yaml

from tlt_common.ccsds.auth import CommandSequencer, KeyRing, write_key_file
from tlt_common.ccsds.codec import Packet, encode_command
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.link_config import load_link_config
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_common.ccsds.sources import DROP_LOGS_PER_S
from tlt_common.config_schema import ConfigError
from tlt_crs.ground_link import GroundLink
from tlt_gsw.link import GswLink

DEFS = load_definitions()
WAIT = 5.0
FOREIGN = "127.0.0.2"


def _config(tmp_path, key_file, gsw_port: int, **crs: object) -> dict:
    path = tmp_path / "link.yaml"
    section = {
        "bind_host": "127.0.0.1",
        "bind_port": 0,
        "gsw_host": "127.0.0.1",
        "gsw_port": gsw_port,
        "replay_state": str(tmp_path / "replay.json"),
        **crs,
    }
    gsw = {
        "crs_host": "127.0.0.1",
        "crs_port": 1,
        "bind_host": "127.0.0.1",
        "bind_port": gsw_port,
        "archive": str(tmp_path / "archive.sqlite"),
        "command_state": str(tmp_path / "seq.json"),
    }
    path.write_text(yaml.safe_dump({"key_file": str(key_file), "key_id": 1, "crs": section, "gsw": gsw}))
    return load_link_config(path)


@pytest.fixture
def ends(tmp_path):
    key_file = write_key_file(tmp_path / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    ring = KeyRing.load(key_file)
    gsw = GswLink(DEFS, ring, 1, ("127.0.0.1", 1))
    crs = GroundLink.from_config(_config(tmp_path, key_file, gsw.address[1]), DEFS, stats_period_s=0)
    gsw.crs_address = crs.address
    crs.start()
    foreign = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    foreign.bind((FOREIGN, 0))
    yield crs, gsw, foreign, ring
    foreign.close()
    crs.close()
    gsw.close()


def _command(ring: KeyRing, name: str) -> bytes:
    return encode_command(
        DEFS, name, {}, key_id=1, key=ring.get(1), security_seq=CommandSequencer().next(), seq_count=0
    )


def _wait(condition, timeout: float = WAIT) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.01)


def test_a_command_from_a_foreign_source_is_dropped_counted_and_reported(ends, caplog):
    crs, gsw, foreign, ring = ends
    caplog.set_level(logging.WARNING, logger="tlt_crs.ground_link.link")
    foreign.sendto(_command(ring, "start"), crs.address)
    _wait(lambda: crs.stats.source_rejections == 1)
    name = f"{FOREIGN}:{foreign.getsockname()[1]}"
    text = f"datagram from {name} dropped: not a configured source"
    assert crs.stats.by_source == {name: 1} and crs.stats.by_reason == {"source": 1}
    assert crs.stats.rejections == 1 and crs.stats.commands_accepted == 0
    assert crs.commands.empty()  # never handed to the CRS
    assert text in caplog.messages
    # The GSW hears of it as an event; the foreign source hears nothing.
    seen: list = []
    deadline = time.monotonic() + WAIT
    while not any(isinstance(r, Packet) and r.kind == "event" for r in seen):
        assert time.monotonic() < deadline, seen
        seen += gsw.poll(0.05)
    event = next(r for r in seen if isinstance(r, Packet) and r.kind == "event")
    assert (event.fields["code"], event.fields["reason"], event.fields["text"]) == (
        "DATAGRAM_REJECTED",
        Reason.SOURCE.label,
        text,
    )
    assert not any(isinstance(r, Packet) and r.kind == "ack" for r in seen)
    foreign.settimeout(0.2)
    with pytest.raises(TimeoutError):
        foreign.recvfrom(4096)
    # The configured peer still gets its command through, and the link statistics report the drop.
    sent = gsw.send_command("start")
    ack = gsw.wait_ack(sent, timeout=WAIT)
    assert ack is not None and ack.stage is AckStage.ACCEPTED
    assert crs.commands.get(timeout=WAIT).name == "start"
    assert crs.stats.as_fields()["source_rejections"] == 1


def test_a_flood_from_a_foreign_source_is_all_counted_and_logged_at_a_bounded_rate(ends, caplog):
    crs, gsw, foreign, _ring = ends
    caplog.set_level(logging.WARNING, logger="tlt_crs.ground_link.link")
    for _ in range(50):
        foreign.sendto(b"junk", crs.address)
    _wait(lambda: crs.stats.source_rejections == 50)
    drops = [m for m in caplog.messages if m.endswith("dropped: not a configured source")]
    # At most DROP_LOGS_PER_S lines per second (the flood may straddle a second's boundary).
    assert 1 <= len(drops) <= 2 * DROP_LOGS_PER_S
    ack = gsw.wait_ack(gsw.send_command("pause"), timeout=WAIT)
    assert ack is not None and ack.stage is AckStage.ACCEPTED


def test_a_named_port_accepts_that_port_only(tmp_path):
    key_file = write_key_file(tmp_path / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    ring = KeyRing.load(key_file)
    with (
        GswLink(DEFS, ring, 1, ("127.0.0.1", 1)) as gsw,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other,
    ):
        other.bind(("127.0.0.1", 0))
        conf = _config(tmp_path, key_file, gsw.address[1], accept_from=[f"127.0.0.1:{gsw.address[1]}"])
        crs = GroundLink.from_config(conf, DEFS, stats_period_s=0).start()
        try:
            gsw.crs_address = crs.address
            other.sendto(_command(ring, "start"), crs.address)  # same host, another port
            _wait(lambda: crs.stats.source_rejections == 1)
            ack = gsw.wait_ack(gsw.send_command("start"), timeout=WAIT)
            assert ack is not None and ack.stage is AckStage.ACCEPTED
            assert crs.stats.by_source == {f"127.0.0.1:{other.getsockname()[1]}": 1}
        finally:
            crs.close()


@pytest.mark.parametrize(
    ("entry", "reason"),
    [
        ("10.0.0.300", "item 0: '10.0.0.300' is not an IPv4 address"),
        ("gsw-host", "item 0: 'gsw-host' is not an IPv4 address"),
        ("127.0.0.1:70000", "item 0: '70000' is not a UDP port (1 ... 65535)"),
    ],
)
def test_a_bad_accepted_address_is_refused_naming_file_and_key(tmp_path, entry, reason):
    with pytest.raises(ConfigError) as info:
        _config(tmp_path, tmp_path / "ground.key", 1, accept_from=[entry])
    assert (info.value.source, info.value.key, info.value.reason) == (
        str(tmp_path / "link.yaml"),
        "crs.accept_from",
        reason,
    )
