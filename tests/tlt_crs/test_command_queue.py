"""The CRS's command queue: the arrival check and the acceptance, once each, and in order."""

from __future__ import annotations

from tlt_common.ccsds.reasons import AckStage
from tlt_crs.commands import CommandQueue


def _queue(refusal: str | None = None) -> tuple[CommandQueue, list[str]]:
    checked: list[str] = []

    def check(name: str, params) -> str | None:
        checked.append(name)
        return refusal

    return CommandQueue(check), checked


def test_submit_checks_once_and_acknowledges_acceptance_before_the_command_can_run():
    queue, checked = _queue()
    acks: list[tuple[AckStage, int]] = []
    queue.submit("pause", {}, lambda stage, why: acks.append((stage, len(queue))))
    assert checked == ["pause"]
    assert acks == [(AckStage.ACCEPTED, 0)]  # acknowledged while nothing was queued yet
    command = queue.pop()
    assert command is not None and command.name == "pause" and queue.pop() is None


def test_submit_of_a_refused_command_rejects_it_once_and_queues_nothing():
    queue, checked = _queue("not paused")
    acks: list[tuple[AckStage, str]] = []
    queue.submit("resume", {}, lambda stage, why: acks.append((stage, why)))
    assert checked == ["resume"] and acks == [(AckStage.REJECTED, "not paused")]
    assert queue.pop() is None


def test_a_command_its_front_end_accepted_is_queued_unchecked_and_unacknowledged():
    queue, checked = _queue("would be refused")
    acks: list[AckStage] = []
    queue.put_accepted("stop", {}, lambda stage, why: acks.append(stage))
    assert checked == [] and acks == []
    command = queue.pop()
    assert command is not None and command.name == "stop"
    command.ack(AckStage.COMPLETED)
    assert acks == [AckStage.COMPLETED]


def test_a_checker_that_raises_is_a_refusal():
    def broken(name: str, params) -> str | None:
        raise KeyError("registry")

    queue = CommandQueue(broken)
    acks: list[tuple[AckStage, str]] = []
    queue.submit("start", {}, lambda stage, why: acks.append((stage, why)))
    assert acks == [(AckStage.REJECTED, "command could not be checked: 'registry'")]
