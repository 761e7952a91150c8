"""DeferredSequence: a phase built when first needed, then the same as one built at once."""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from tlt_common.bt.deferred import DeferredSequence, build_deferred
from tlt_common.bt.nodes import Action

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class Scripted(Action):
    """Answers ``script`` one status per tick (the last repeats)."""

    def __init__(self, name: str, script: list[Status]) -> None:
        super().__init__(name)
        self.script, self.ticks = script, 0

    def update(self) -> Status:
        status = self.script[min(self.ticks, len(self.script) - 1)]
        self.ticks += 1
        return self.fail("scripted failure") if status == F else status


def seq(name: str, children: list) -> py_trees.composites.Sequence:
    s = py_trees.composites.Sequence(name, memory=True)
    s.add_children(children)
    return s


def paths(root: py_trees.behaviour.Behaviour) -> list[str]:
    out = []

    def walk(node, prefix):
        path = f"{prefix}/{node.name}" if prefix else node.name
        out.append(path)
        for child in node.children:
            walk(child, path)

    walk(root, "")
    return out


def place(calls: list[int] | None = None):
    def make():
        if calls is not None:
            calls.append(1)
        return seq("Place", [Scripted("Approach", [S]), seq("Align", [Scripted("Measure", [S])])])

    return make


def test_built_between_ticks_the_phase_is_the_one_built_at_once_and_runs_in_order():
    calls: list[int] = []
    first = Scripted("Load", [R, S])
    branch = seq("Request", [first, DeferredSequence("Place", place(calls))])
    branch.tick_once()
    assert first.status == R and branch.children[1].children == [] and calls == []
    assert build_deferred(branch) and calls == [1]
    assert not build_deferred(branch)  # nothing left to build
    assert paths(branch) == paths(seq("Request", [Scripted("Load", [S]), place()()]))
    branch.tick_once()
    assert branch.status == S and calls == [1]
    assert [n.status for n in branch.children[1].iterate()] == [S, S, S, S]


def test_reached_before_it_was_built_it_builds_itself_on_its_first_tick():
    calls: list[int] = []
    branch = seq("Request", [Scripted("Load", [S]), DeferredSequence("Place", place(calls))])
    branch.tick_once()
    assert branch.status == S and calls == [1]
    assert paths(branch)[-1] == "Request/Place/Align/Measure"


def test_deferred_phases_inside_a_built_one_are_built_too():
    inner = DeferredSequence("Align", lambda: seq("Align", [Scripted("Measure", [S])]))
    outer = DeferredSequence("Place", lambda: seq("Place", [Scripted("Approach", [S]), inner]))
    branch = seq("Request", [Scripted("Load", [R]), outer])
    assert build_deferred(branch)
    assert inner.built and paths(branch)[-1] == "Request/Place/Align/Measure"


def test_a_phase_that_cannot_be_built_fails_when_reached_naming_why():
    def broken():
        raise ValueError("member 'm' has no add rivet in the mission")

    phase = DeferredSequence("Place", broken)
    branch = seq("Request", [Scripted("Load", [R, S]), phase])
    branch.tick_once()
    build_deferred(branch)  # the error is kept for the tick that reaches it
    assert branch.status == R
    branch.tick_once()
    assert branch.status == F and phase.status == F
    assert phase.feedback_message == "cannot build 'Place': member 'm' has no add rivet in the mission"


def test_a_builder_that_makes_another_node_is_refused():
    phase = DeferredSequence("Place", lambda: seq("Retreat", [Scripted("Back", [S])]))
    seq("Request", [phase]).tick_once()
    assert phase.status == F
    assert "expected a Sequence with memory named 'Place', got Sequence 'Retreat'" in phase.feedback_message
