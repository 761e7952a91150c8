"""Action and Condition node types on their own (Table 3)."""

from __future__ import annotations

import logging

import py_trees
import pytest
from py_trees.common import Status

from tlt_common.bt.nodes import (
    Action,
    BlackboardCondition,
    Condition,
    ContractViolation,
    SetBlackboard,
    node_kind,
)


@pytest.fixture(autouse=True)
def clean_blackboard():
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


class Countdown(Action):
    """RUNNING for ``steps`` ticks, then SUCCESS; FAILURE when told it is impossible."""

    def __init__(self, name: str, steps: int, possible: bool = True, **kw) -> None:
        super().__init__(name, **kw)
        self.steps, self.possible = steps, possible
        self.left = steps
        self.terminated: list[Status] = []

    def initialise(self) -> None:
        self.left = self.steps

    def update(self) -> Status:
        if not self.possible:
            return self.fail("cannot be done")
        if self.left > 0:
            self.left -= 1
            return Status.RUNNING
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        self.terminated.append(new_status)


class Flag(Condition):
    def __init__(self, name: str, answer, **kw) -> None:
        super().__init__(name, **kw)
        self.answer = answer

    def evaluate(self):
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer


def test_action_is_running_then_succeeds():
    action = Countdown("count", steps=2)
    seen = []
    for _ in range(3):
        action.tick_once()
        seen.append(action.status)
    assert seen == [Status.RUNNING, Status.RUNNING, Status.SUCCESS]
    assert action.terminated == [Status.SUCCESS]


def test_action_fails_with_reason_when_impossible():
    action = Countdown("count", steps=1, possible=False)
    action.tick_once()
    assert action.status is Status.FAILURE
    assert action.feedback_message == "cannot be done"


class AnswersInvalid(Action):
    def update(self) -> Status:
        return Status.INVALID


def test_action_answering_invalid_becomes_failure(caplog):
    action = AnswersInvalid("bad")
    with caplog.at_level(logging.ERROR, logger="tlt_common.bt"):
        action.tick_once()
    assert action.status is Status.FAILURE
    assert "answered INVALID" in caplog.text


def test_action_answering_invalid_raises_in_strict_mode():
    with pytest.raises(ContractViolation, match="bad"):
        AnswersInvalid("bad", strict=True).tick_once()


@pytest.mark.parametrize(
    ("answer", "expected"),
    [
        (True, Status.SUCCESS),
        (False, Status.FAILURE),
        (Status.SUCCESS, Status.SUCCESS),
        (Status.FAILURE, Status.FAILURE),
    ],
)
def test_condition_answers_success_or_failure(answer, expected):
    condition = Flag("flag", answer)
    condition.tick_once()
    assert condition.status is expected


def test_condition_accepts_numpy_bools():
    import numpy as np

    yes, no = Flag("yes", np.all([True, True])), Flag("no", np.any([False]))
    yes.tick_once()
    no.tick_once()
    assert (yes.status, no.status) == (Status.SUCCESS, Status.FAILURE)


@pytest.mark.parametrize("answer", [Status.RUNNING, Status.INVALID, None, 1])
def test_condition_never_running_turned_into_failure(answer, caplog):
    condition = Flag("flag", answer)
    with caplog.at_level(logging.ERROR, logger="tlt_common.bt"):
        condition.tick_once()
    assert condition.status is Status.FAILURE
    assert "only true/false allowed" in caplog.text


def test_condition_running_raises_in_strict_mode():
    with pytest.raises(ContractViolation, match=r"answered <Status\.RUNNING"):
        Flag("flag", Status.RUNNING, strict=True).tick_once()


def test_strict_default_applies_to_every_condition(monkeypatch):
    monkeypatch.setattr(Condition, "strict_default", True)
    with pytest.raises(ContractViolation):
        Flag("flag", Status.RUNNING).tick_once()


def test_condition_that_raises_fails_with_reason(caplog):
    condition = Flag("flag", RuntimeError("sensor gone"))
    with caplog.at_level(logging.ERROR, logger="tlt_common.bt"):
        condition.tick_once()
    assert condition.status is Status.FAILURE
    assert "sensor gone" in condition.feedback_message


def test_condition_cannot_override_update():
    with pytest.raises(TypeError, match="implements evaluate"):

        class Sneaky(Condition):
            def update(self) -> Status:
                return Status.RUNNING


def test_condition_in_sequence_never_leaves_it_running():
    root = py_trees.composites.Sequence("root", memory=False, children=[Flag("f", Status.RUNNING)])
    root.tick_once()
    assert root.status is Status.FAILURE


def test_blackboard_condition_reads_key():
    condition = BlackboardCondition("engaged?", "top_gripper_engaged")
    condition.tick_once()
    assert condition.status is Status.FAILURE
    assert "not set" in condition.feedback_message
    py_trees.blackboard.Blackboard.set("/top_gripper_engaged", True)
    condition.tick_once()
    assert condition.status is Status.SUCCESS
    limit = BlackboardCondition("bay < 3?", "top_gripper_engaged", predicate=lambda v: v is False)
    limit.tick_once()
    assert limit.status is Status.FAILURE


def test_set_blackboard_writes_and_reports_errors():
    SetBlackboard("set", "current_bay", 2).tick_once()
    assert py_trees.blackboard.Blackboard.get("/current_bay") == 2
    broken = SetBlackboard("broken", "x", value_fn=lambda: 1 / 0)
    broken.tick_once()
    assert broken.status is Status.FAILURE
    assert "division by zero" in broken.feedback_message


def test_preempted_action_terminates_invalid():
    slow = Countdown("slow", steps=10)
    fallback = py_trees.composites.Selector("?", memory=False, children=[Flag("gate", False), slow])
    fallback.tick_once()
    assert slow.status is Status.RUNNING
    fallback.children[0].answer = True
    fallback.tick_once()
    assert slow.status is Status.INVALID
    assert slow.terminated == [Status.INVALID]


def test_node_kind_names_table3_types():
    seq = py_trees.composites.Sequence("s", memory=False)
    sel = py_trees.composites.Selector("f", memory=False)
    par = py_trees.composites.Parallel("p", policy=py_trees.common.ParallelPolicy.SuccessOnAll())
    dec = py_trees.decorators.Inverter("i", child=Flag("c", True))
    assert [node_kind(n) for n in (seq, sel, par, dec, Flag("c", True), Countdown("a", 1))] == [
        "sequence",
        "fallback",
        "parallel",
        "decorator",
        "condition",
        "action",
    ]


def _scripted(base: type):
    """A leaf of ``base`` answering a script of statuses and logging its life cycle calls."""

    class Scripted(base):
        def __init__(self, script: list[Status]) -> None:
            super().__init__("scripted")
            self.script, self.calls = list(script), []

        def initialise(self) -> None:
            self.calls.append("initialise")

        def update(self) -> Status:
            self.calls.append("update")
            return self.script.pop(0)

        def terminate(self, new_status: Status) -> None:
            self.calls.append(f"terminate {new_status.name}")

    return Scripted


def test_action_tick_keeps_the_py_trees_life_cycle():
    """Action.tick is py_trees' Behaviour.tick written out: the same calls, statuses and yields,
    also when a parent pre-empts it (a Selector whose first child turns true)."""
    script = [Status.RUNNING, Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.RUNNING, Status.RUNNING]
    traces = []
    for base in (py_trees.behaviour.Behaviour, Action):
        leaf = _scripted(base)(script)
        guard = Flag("guard", False)
        root = py_trees.composites.Selector("root", memory=False, children=[guard, leaf])
        trace = []
        for tick in range(len(script) + 1):
            guard.answer = tick == 5  # pre-empts the leaf while it runs
            yielded = [node.name for node in root.tick()]
            trace.append((yielded, leaf.status, root.status))
        traces.append((trace, leaf.calls))
    assert traces[0] == traces[1]
    assert "terminate INVALID" in traces[1][1]
