"""The GSW end takes telemetry only from the sources ``gsw.accept_from`` names, over real UDP.

A real CRS :class:`GroundLink` on 127.0.0.1 is the configured peer; a foreign sender on
127.0.0.2 (Linux routes all of 127/8 to loopback) holds the telemetry key, so what it sends
would verify: only the source check stops it. The GSW is built from a link configuration file
as ``tlt gsw`` builds it.
"""

from __future__ import annotations

import io
import logging
import os
import socket
import threading
import time

import pytest
import yaml

from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.codec import Packet, Rejection
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.link_config import load_link_config
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_crs.ground_link import GroundLink
from tlt_gsw import cli
from tlt_gsw.archive import Recorder
from tlt_gsw.archive import query as q
from tlt_gsw.link import GswLink, accepted_sources

DEFS = load_definitions()
WAIT = 5.0
FOREIGN = "127.0.0.2"


def _write_config(tmp_path, key_file, crs_port: int, **gsw: object):
    path = tmp_path / "link.yaml"
    section = {
        "crs_host": "127.0.0.1",
        "crs_port": crs_port,
        "bind_host": "127.0.0.1",
        "bind_port": 0,
        "archive": str(tmp_path / "archive.sqlite"),
        "command_state": str(tmp_path / "seq.json"),
        **gsw,
    }
    crs = {"bind_host": "127.0.0.1", "bind_port": crs_port, "replay_state": str(tmp_path / "replay.json")}
    path.write_text(yaml.safe_dump({"key_file": str(key_file), "key_id": 1, "crs": crs, "gsw": section}))
    return path


@pytest.fixture
def ends(tmp_path):
    key_file = write_key_file(tmp_path / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    ring = KeyRing.load(key_file)
    crs = GroundLink(DEFS, ring, tmp_path / "replay.json", stats_period_s=0).start()
    conf = load_link_config(_write_config(tmp_path, key_file, crs.address[1]))
    gsw_conf = conf["gsw"]
    gsw = GswLink(
        DEFS,
        ring,
        1,
        (gsw_conf["crs_host"], gsw_conf["crs_port"]),
        recorder=Recorder(tmp_path / "archive.sqlite"),
        close_recorder=True,
        accept_from=accepted_sources(gsw_conf),
    )
    crs.gsw_address = gsw.address
    foreign = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    foreign.bind((FOREIGN, 0))
    yield crs, gsw, foreign, ring, tmp_path / "archive.sqlite"
    foreign.close()
    gsw.close()
    crs.close()


def _genuine_telemetry(ring: KeyRing) -> bytes:
    """What the CRS would send: signed with the telemetry key, so it verifies wherever it comes from."""
    signer = TelemetrySigner(ring.telemetry, 1)
    return signer.encode(DEFS, "hk_tower", {"member_count": 3, "member_states": b"\x15"}, seq_count=1)


def _poll_until(gsw: GswLink, count: int) -> list:
    got: list = []
    for _ in range(int(WAIT / 0.05)):
        got += gsw.poll(0.05)
        if len(got) >= count:
            break
    return got


def test_telemetry_from_a_foreign_source_is_dropped_counted_and_archived_as_rejected(ends, caplog):
    _crs, gsw, foreign, ring, archive = ends
    caplog.set_level(logging.WARNING, logger="tlt_gsw.link")
    raw = _genuine_telemetry(ring)
    foreign.sendto(raw, gsw.address)
    (result,) = _poll_until(gsw, 1)
    name = f"{FOREIGN}:{foreign.getsockname()[1]}"
    text = f"datagram from {name} dropped: not a configured source"
    assert isinstance(result, Rejection) and (result.reason, result.detail) == (Reason.SOURCE, text)
    assert gsw.stats.by_source == {name: 1} and gsw.stats.source_rejections == 1
    assert gsw.stats.by_reason == {"source": 1} and gsw.stats.auth_rejections == 0
    assert gsw.tm_verifier.gaps == 0  # never parsed: its security sequence was not taken
    assert text in caplog.messages
    # The configured CRS still gets through: its acknowledgement arrives and is matched.
    sent = gsw.send_command("start")
    ack = gsw.wait_ack(sent, timeout=WAIT)
    assert ack is not None and ack.stage is AckStage.ACCEPTED
    gsw.close()
    conn = q.open_archive(archive)
    rows = [r for r in q.packets(conn, limit=10, newest_first=False) if r.direction == "rx"]
    assert [(r.kind, r.status, r.detail, r.raw) for r in rows[:1]] == [(None, "source", text, raw)]
    assert q.packet_fields(conn, rows[0].id) == {}
    assert [(r.kind, r.status) for r in rows[1:]] == [("ack", "ok")]


def test_the_crs_host_on_another_port_is_not_the_crs(ends):
    crs, gsw, _foreign, ring, _ = ends
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        other.bind(("127.0.0.1", 0))
        other.sendto(_genuine_telemetry(ring), gsw.address)
        (result,) = _poll_until(gsw, 1)
    assert isinstance(result, Rejection) and result.reason is Reason.SOURCE
    crs.send_telemetry("hk_tower", {"member_count": 3, "member_states": b"\x15"})
    (result,) = _poll_until(gsw, 1)
    assert isinstance(result, Packet) and result.kind == "hk_tower"
    assert gsw.stats.source_rejections == 1


def test_watch_says_what_it_dropped(ends, tmp_path):
    crs, gsw, foreign, ring, _ = ends
    port = gsw.address[1]
    gsw.close()  # `tlt gsw watch` takes its port
    config = _write_config(tmp_path, tmp_path / "ground.key", crs.address[1], bind_port=port)
    out = io.StringIO()
    argv = ["--config", str(config), "watch", "--count", "1", "--duration", str(WAIT)]
    watch = threading.Thread(target=lambda: codes.append(cli.main(argv, out=out)))
    codes: list[int] = []
    watch.start()
    deadline = time.monotonic() + WAIT
    while "listening" not in out.getvalue() and time.monotonic() < deadline:
        time.sleep(0.01)
    foreign.sendto(_genuine_telemetry(ring), ("127.0.0.1", port))
    watch.join(WAIT + 5)
    assert codes == [0], out.getvalue()
    name = f"{FOREIGN}:{foreign.getsockname()[1]}"
    assert f"REJECTED source: datagram from {name} dropped: not a configured source" in out.getvalue()
    assert "(failed authentication 0, not a configured source 1)" in out.getvalue().splitlines()[-1]


def test_a_bad_accepted_address_is_refused_naming_file_and_key(tmp_path, capsys):
    config = _write_config(
        tmp_path, tmp_path / "ground.key", 52001, accept_from=["127.0.0.1:52001", "10.0.0.999"]
    )
    assert cli.main(["--config", str(config), "watch", "--count", "1"], out=io.StringIO()) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert f"{config}: gsw.accept_from: item 1: '10.0.0.999' is not an IPv4 address" in err
