"""The link in its own process: commands out, acknowledgements into the archive, clear failures."""

from __future__ import annotations

import os
import socket

import pytest

from tlt_common.ccsds.auth import write_key_file
from tlt_common.ccsds.definitions import load_definitions
from tlt_gsw.archive.query import open_archive
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.link_process import CommandNotSent, LinkProcess, LinkSettings, LinkStartError

DEFS = load_definitions()


def settings(tmp_path, crs_address, key_file, bind=("127.0.0.1", 0)) -> LinkSettings:
    return LinkSettings(
        definitions=None, key_file=str(key_file), key_id=1, crs_address=crs_address, bind=bind,
        archive=str(tmp_path / "archive.sqlite"), command_state=str(tmp_path / "seq.json"),
        flush_interval_s=0.05,
    )  # fmt: skip


def test_commands_and_acks_through_the_link_process(tmp_path, wait_for, make_crs):
    key_file = write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    crs = make_crs(key_file)
    link = LinkProcess(settings(tmp_path, crs.link.address, key_file)).start()
    try:
        crs.link.gsw_address = link.address
        start = link.submit("start")
        bad = link.submit("set_actuator_state", {"actuator": "warp_drive", "state": "on"})
        wait_for(lambda: start.done() and bad.done(), pump=link.poll)
        assert start.result().name == "start"
        with pytest.raises(CommandNotSent, match="unknown actuator"):
            bad.result()
        model = ArchiveModel(open_archive(tmp_path / "archive.sqlite"), DEFS)

        def stages():
            model.advance()
            record = model.commands.get(start.result().security_seq)
            return record is not None and [a.stage for a in record.acks] == ["accepted", "completed"]

        wait_for(stages)
        wait_for(lambda: link.health()[1] and link.committed >= 3, pump=link.poll)
        assert [c.name for c in crs.handled] == ["start"]
    finally:
        link.close()
    assert not link.alive and link.health() == ("archive.sqlite: LINK PROCESS STOPPED", False)
    with pytest.raises(CommandNotSent):
        link.submit("stop").result(timeout=1)


def test_a_port_in_use_is_a_start_error_with_the_reason(tmp_path):
    key_file = write_key_file(tmp_path / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    try:
        with pytest.raises(LinkStartError, match="Address already in use"):
            LinkProcess(settings(tmp_path, ("127.0.0.1", 9), key_file, bind=taken.getsockname())).start()
    finally:
        taken.close()
