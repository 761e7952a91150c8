"""The GUI's link thread: sends queued commands, records what it sends and receives."""

from __future__ import annotations

import pytest

from tlt_common.ccsds.definitions import load_definitions
from tlt_gsw.archive.query import open_archive
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.link_worker import LinkClosedError

DEFS = load_definitions()


def test_commands_go_out_and_their_acks_reach_the_archive(link_pair, wait_for):
    crs, worker, archive = link_pair
    sent = worker.submit("start").result(timeout=5)
    refused = worker.submit("set_blackboard_value", {"key": "x", "value": 3}).result(timeout=5)
    wait_for(lambda: len(crs.handled) == 1)
    model = ArchiveModel(open_archive(archive), DEFS)

    def stages():
        model.advance()
        return {r.security_seq: [a.stage for a in r.acks] for r in model.commands.values()}

    wait_for(
        lambda: (
            stages().get(sent.security_seq) == ["accepted", "completed"]
            and stages().get(refused.security_seq) == ["rejected"]
        )
    )
    assert model.commands[refused.security_seq].acks[0].reason == "refused"
    assert [c.name for c in crs.handled] == ["start"]


def test_a_bad_parameter_fails_the_future_and_the_link_goes_on(link_pair, wait_for):
    crs, worker, _ = link_pair
    bad = worker.submit("set_actuator_state", {"actuator": "warp_drive", "state": "on"})
    with pytest.raises(ValueError, match="unknown actuator"):
        bad.result(timeout=5)
    assert worker.submit("pause").result(timeout=5).name == "pause"
    wait_for(lambda: [c.name for c in crs.handled] == ["pause"])


def test_submit_after_close_is_refused(link_pair):
    _, worker, _ = link_pair
    worker.close()
    assert not worker.alive
    with pytest.raises(LinkClosedError):
        worker.submit("start").result(timeout=1)
