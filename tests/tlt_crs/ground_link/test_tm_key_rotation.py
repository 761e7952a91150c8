"""Telemetry key rotation over UDP: a key is added to the key file of running ends and the ground
commands the switch in the middle of a packet stream; no packet is lost, and after the overlap the
old key is refused even with a fresh sequence number."""

from __future__ import annotations

import io
import os
import socket
import threading
import time

from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.codec import Packet, Rejection
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_crs.ground_link import GroundLink
from tlt_gsw import cli
from tlt_gsw.archive import Recorder
from tlt_gsw.archive import query as q
from tlt_gsw.link import GswLink

DEFS = load_definitions()
STREAM = 600


def test_switch_in_the_middle_of_a_stream_loses_nothing_and_retires_the_old_key(tmp_path):
    key_file = write_key_file(tmp_path / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    ring = KeyRing.load(key_file)  # both ends read the one file here, as on one machine
    crs = GroundLink(DEFS, ring, tmp_path / "replay.json", stats_period_s=0, tm_key_id=1).start()
    received: list = []
    halfway = threading.Event()

    def stream() -> None:
        for i in range(STREAM):
            crs.send_telemetry("hk_tower", {"member_count": i, "member_states": b""})
            if i == STREAM // 2:
                halfway.set()
            time.sleep(0.0005)

    archive = tmp_path / "a.sqlite"
    with GswLink(
        DEFS,
        ring,
        1,
        crs.address,
        recorder=Recorder(archive),
        close_recorder=True,
        on_packet=received.append,
        recv_buffer_bytes=4 << 20,
        tm_key_overlap_s=0.5,
    ) as gsw:
        crs.gsw_address = gsw.address
        sender = threading.Thread(target=stream)
        sender.start()
        while not halfway.is_set():
            gsw.poll(0.01)
        assert cli.main(["keygen", str(key_file), "--add-tm-key"], out=io.StringIO()) == 0  # no restart
        switch = gsw.send_command("switch_tm_key")
        done = gsw.wait_ack(switch, final=True, timeout=5.0)
        deadline = time.monotonic() + 10.0
        while sender.is_alive() or (
            sum(getattr(r, "kind", None) == "hk_tower" for r in received) < STREAM
            and time.monotonic() < deadline
        ):
            gsw.poll(0.05)
        sender.join()
        assert (
            done is not None and done.stage is AckStage.COMPLETED and done.detail == "telemetry key id 1 -> 2"
        )
        towers = [r for r in received if isinstance(r, Packet) and r.kind == "hk_tower"]
        assert sorted(r.fields["member_count"] for r in towers) == list(range(STREAM))  # none lost
        keys = [r.key_id for r in towers]
        assert keys[0] == 1 and keys[-1] == 2 and keys == sorted(keys)  # one switch, mid-stream
        assert not [r for r in received if isinstance(r, Rejection)]
        assert gsw.tm_verifier.gaps == 0 and gsw.stats.auth_rejections == 0

        time.sleep(0.6)  # past the overlap: key 1 is retired, even for a number never seen
        stolen = TelemetrySigner(KeyRing.load(key_file).telemetry, 1, base=2**62).encode(
            DEFS, "hk_tower", {"member_count": 1, "member_states": b""}, seq_count=0
        )
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
            attacker.sendto(stolen, gsw.address)
        crs.send_telemetry("hk_tower", {"member_count": STREAM, "member_states": b""})
        late: list = []
        deadline = time.monotonic() + 5.0
        while len(late) < 2 and time.monotonic() < deadline:
            late += gsw.poll(0.05)
        by_kind = {type(r).__name__: r for r in late}
        assert by_kind["Rejection"].reason is Reason.UNKNOWN_KEY and "retired" in by_kind["Rejection"].detail
        assert by_kind["Packet"].key_id == 2  # the CRS's telemetry under the new key still arrives

        again = gsw.send_command("switch_tm_key")  # no key id above 2 in the file
        failed = gsw.wait_ack(again, final=True, timeout=5.0)
        assert (
            failed is not None
            and failed.stage is AckStage.FAILED
            and "no telemetry key id above 2" in failed.detail
        )
    crs.close()
    conn = q.open_archive(archive)
    statuses = [r.status for r in q.packets(conn, limit=10_000, newest_first=False) if r.direction == "rx"]
    assert statuses.count("unknown_key") == 1 and set(statuses) == {"ok", "unknown_key"}
