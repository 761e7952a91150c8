"""The ARS behaviour tree of paper Fig. 14: wait for a request, install the matching branch, run
it, report the result.

::

    ARS X (Sequence)
    ├── Started?                    condition: the ground's Start (forwarded by the CRS) holds
    ├── Wait For Request            RUNNING until the node hands over a request; installs its branch
    ├── Carry Out Request (?)       Fallback
    │   ├── Request                 Sequence holding the installed branch (Figs. 28, 32, 38, 39)
    │   └── Record Failure          the branch failed: keep the failing step and its reason
    └── Report Result               hand success or failure with the reason to the node

The node (``tlt_ars.node``) owns the ROS goal; the tree sees a :class:`Job` (the request and a
callback for the result). After Report Result the root succeeds and the next tick starts over at
Wait For Request. Each installed branch replaces the previous one; call ``on_change`` observers
(the status publisher) after a change of shape.

Helpers for feedback: :func:`running_step` (path of the running leaf below the branch) and
:func:`progress` (fraction of the branch's leaves done); :func:`failure_reason` walks down the
failed children to the leaf that failed and returns its path and reason.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import py_trees
from py_trees.common import Status

from tlt_ars.context import ArsContext
from tlt_ars.mission_state import Request
from tlt_ars.motion_planner import MotionPlanner
from tlt_ars.subtrees import SubtreeBuilder
from tlt_common.bt.deferred import DeferredSequence, build_deferred
from tlt_common.bt.nodes import Action, Condition
from tlt_common.bt.ros import ServiceCall


@dataclass
class Job:
    """A request handed to the tree, with where its result goes."""

    request: Request
    report: Callable[[bool, str], None]
    outcome: tuple[bool, str] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


class Started(Condition):
    """True once the ground's Start has come (or the ARS is configured to start on launch)."""

    def __init__(self, name: str, is_started: Callable[[], bool]) -> None:
        super().__init__(name)
        self.is_started = is_started

    def evaluate(self) -> bool:
        return bool(self.is_started())


def _leaves(node: py_trees.behaviour.Behaviour) -> list[py_trees.behaviour.Behaviour]:
    if not node.children:
        return [node]
    out = []
    for child in node.children:
        out.extend(_leaves(child))
    return out


def _path(node: py_trees.behaviour.Behaviour, top: py_trees.behaviour.Behaviour) -> str:
    names = []
    while node is not None and node is not top:
        names.append(node.name)
        node = node.parent
    return "/".join(reversed(names))


def running_step(branch: py_trees.behaviour.Behaviour | None) -> str:
    """``Branch/Subtree/.../Leaf`` of the leaf running under ``branch`` ("" when none runs)."""
    if branch is None or branch.status != Status.RUNNING:
        return ""
    # Down the running children, not py_trees' tip(): a Parallel's tip is its last child's, which
    # may have succeeded while another child still runs.
    tip = _last_leaf_with(branch, Status.RUNNING)
    return f"{branch.name}/{_path(tip, branch)}" if tip is not branch else branch.name


def _last_leaf_with(node: py_trees.behaviour.Behaviour, status: Status) -> py_trees.behaviour.Behaviour:
    """Down from ``node`` through the last child with ``status``, as far as one has it."""
    while node.children:
        children = [c for c in node.children if c.status == status]
        if not children:
            break
        node = children[-1]
    return node


def progress(branch: py_trees.behaviour.Behaviour | None) -> float:
    """Fraction of ``branch``'s leaves that have succeeded in this run (0 while a phase is still to
    be built: the whole is not known yet, and the figure must not fall when it is)."""
    if branch is None:
        return 0.0
    leaves = _leaves(branch)
    if any(isinstance(leaf, DeferredSequence) and not leaf.built for leaf in leaves):
        return 0.0
    done = sum(1 for leaf in leaves if leaf.status == Status.SUCCESS)
    return done / len(leaves) if leaves else 0.0


def failure_reason(node: py_trees.behaviour.Behaviour) -> str:
    """``path: reason`` of the leaf whose failure failed ``node``."""
    top = node
    node = _last_leaf_with(top, Status.FAILURE)
    reason = node.feedback_message or "failed"
    path = _path(node, top)
    return f"{top.name}/{path}: {reason}" if path else f"{top.name}: {reason}"


class WaitForRequest(Action):
    """RUNNING until the node hands over a job; then builds and installs its branch.

    Reads: the node's pending job (``take_job``). Writes: the Request placeholder's child, the
    context's request data. SUCCESS once a branch is installed; FAILURE when the branch cannot be
    built (the job is then reported failed with the reason).
    """

    def __init__(self, name: str, tree: ArsTree) -> None:
        super().__init__(name)
        self.tree = tree

    def update(self) -> Status:
        job = self.tree.take_job()
        if job is None:
            self.feedback_message = "idle"
            return Status.RUNNING
        try:
            self.tree.install(job)
        except Exception as exc:  # a branch that cannot be built fails the request, not the ARS
            job.report(False, f"cannot build the branch for {job.request.request}: {exc}")
            self.tree.job = None
            return self.fail(str(exc))
        self.feedback_message = f"{job.request.request} {job.request.member_id}"
        return Status.SUCCESS


class RecordFailure(Action):
    """The branch failed: remember the failing leaf's path and reason. SUCCESS at once."""

    def __init__(self, name: str, tree: ArsTree) -> None:
        super().__init__(name)
        self.tree = tree

    def update(self) -> Status:
        branch = self.tree.branch
        reason = failure_reason(branch) if branch is not None else "no branch installed"
        if self.tree.job is not None:
            self.tree.job.outcome = (False, reason)
        self.feedback_message = reason
        return Status.SUCCESS


class ReportResult(Action):
    """Hand the outcome to the node (success, or the recorded failure). SUCCESS at once."""

    def __init__(self, name: str, tree: ArsTree) -> None:
        super().__init__(name)
        self.tree = tree

    def update(self) -> Status:
        job, self.tree.job = self.tree.job, None
        if job is None:
            return self.fail("no request to report")
        ok, reason = job.outcome if job.outcome is not None else (True, "")
        job.report(ok, reason)
        self.feedback_message = "succeeded" if ok else f"failed: {reason}"
        return Status.SUCCESS


class ArsTree:
    """The Fig. 14 tree of one ARS and the branch currently installed in it."""

    def __init__(self, ctx: ArsContext, planner: MotionPlanner, is_started: Callable[[], bool]) -> None:
        self.ctx = ctx
        self.builder = SubtreeBuilder(ctx, planner)
        self.job: Job | None = None
        self._pending: Job | None = None
        self.branch: py_trees.behaviour.Behaviour | None = None
        self._deferred = False  # the installed branch has phases still to build
        self.on_change: list[Callable[[], None]] = []
        self.slot = py_trees.composites.Sequence("Request", memory=True)
        carry = py_trees.composites.Selector("Carry Out Request", memory=True)
        carry.add_children([self.slot, RecordFailure("Record Failure", self)])
        self.root = py_trees.composites.Sequence(ctx.ars.upper().replace("_", " "), memory=True)
        self.root.add_children(
            [
                Started("Started?", is_started),
                WaitForRequest("Wait For Request", self),
                carry,
                ReportResult("Report Result", self),
            ]
        )
        self.tree = py_trees.trees.BehaviourTree(self.root)

    # ----- the node's side -----
    def submit(self, job: Job) -> None:
        """Hand over a job; Wait For Request picks it up at the next tick."""
        self._pending = job

    def take_job(self) -> Job | None:
        job, self._pending = self._pending, None
        if job is not None:
            self.job = job
        return job

    def install(self, job: Job) -> None:
        finishing = self.ctx.begin(job.request)
        member = self.ctx.data.member
        if member is None:
            raise ValueError(f"unknown member '{job.request.member_id}'")
        if finishing and self.ctx.data.setting:
            branch = self.builder.finish_in_doubt(job.request.request, member)
        elif finishing:
            branch = self.builder.finish(job.request.request, member)
        else:
            branch = self.builder.branch(job.request.request, member, defer=True)
        for child in list(self.slot.children):
            self.slot.remove_child(child)
        self.slot.add_child(branch)
        self.branch = branch
        self._deferred = not finishing
        for callback in self.on_change:
            callback()

    def tick(self) -> None:
        # The phases a request reaches later are built on the tick after the one that installed
        # its branch (its first feedback is out by then), before anything can reach them.
        if self._deferred and self.branch is not None:
            self._deferred = False
            if build_deferred(self.branch):
                for callback in self.on_change:
                    callback()
        self.tree.tick()

    def interrupt(self) -> Job | None:
        """Pre-empt everything (cancel, Stop): running goals are canceled; returns the job that was
        running, which the caller finishes."""
        self.root.stop(Status.INVALID)
        job, self.job = self.job, None
        self._pending = None
        self._deferred = False  # the branch will not run again: nothing of it is worth building
        return job

    def hold(self) -> None:
        """Pause: stop the running motion (its goal is canceled and the arm holds). A motion is
        stopped as a whole, so Resume plans it again from where the arm stands. A service call in
        flight (a part presented to the CRS, a question to vision) moves nothing and is left to
        finish: its answer is read on Resume. Given up, the answer could be lost (the CRS held by
        a fault pauses the ARS while it inspects the part)."""
        tip = self.root.tip()
        if tip is None or tip.status != Status.RUNNING or tip is self.root:
            return
        node = tip
        while node is not None and not getattr(node, "replan_on_resume", False):
            node = node.parent
        if node is None and isinstance(tip, ServiceCall):
            return
        (node or tip).stop(Status.INVALID)

    def resume(self, paused_s: float) -> None:
        """Resume after ``paused_s`` s of Pause: a behaviour left running through it (a service
        call) does not count that time toward its limits (``postpone``)."""
        for behaviour in self.root.iterate():
            if behaviour.status == Status.RUNNING and hasattr(behaviour, "postpone"):
                behaviour.postpone(paused_s)

    def step(self) -> str:
        return running_step(self.branch) if self.job is not None else ""

    def progress(self) -> float:
        return progress(self.branch) if self.job is not None else 0.0


__all__ = ["ArsTree", "Job", "failure_reason", "progress", "running_step"]
