"""Fault handling of the CRS tree (Fig. 13): raise a fault with its reason, wait for help.

A failure anywhere under Build Tower reaches :class:`RaiseFault`, which finds the reason (the
feedback of the deepest failed behaviour), sets blackboard ``fault`` and publishes an ERROR event.
From the next tick the Fault Check answers RUNNING in :class:`WaitForHelp` until an operator sets
the ground-writable key ``clear_fault``; the tree then re-enters Build Tower, whose guards skip
what the tower model and the sensors say is done.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition
from tlt_crs.context import CrsContext


def failure_reason(root: py_trees.behaviour.Behaviour) -> str:
    """The feedback of the deepest failed behaviour under ``root`` (the last failed child at each level)."""
    node, reason = root, root.feedback_message
    while node.children:
        failed = [c for c in node.children if c.status == Status.FAILURE]
        if not failed:
            break
        node = failed[-1]
        if node.feedback_message:
            reason = node.feedback_message
    return f"{node.name}: {reason}" if reason else f"{node.name} failed"


class NoFault(Condition):
    """Reads: blackboard ``fault``. SUCCESS when it is empty; FAILURE when a fault is set."""

    def __init__(self, ctx: CrsContext) -> None:
        super().__init__("No Fault?")
        self.ctx = ctx

    def evaluate(self) -> bool:
        fault = self.ctx.fault
        self.feedback_message = fault
        return not fault


class WaitForHelp(Action):
    """Wait until the operator clears the fault.

    Reads: blackboard ``fault``, ``clear_fault``. Writes: ``fault`` = "", ``clear_fault`` = false.
    RUNNING while the fault is set and not cleared; SUCCESS once cleared. Never FAILURE.
    """

    def __init__(self, ctx: CrsContext) -> None:
        super().__init__("Wait For Help")
        self.ctx = ctx

    def update(self) -> Status:
        board = self.ctx.board
        if board.get("clear_fault", False):
            cleared = self.ctx.fault
            board.set("fault", "")
            board.set("clear_fault", False)
            self.ctx.event(1, "FAULT_CLEARED", f"operator cleared the fault: {cleared}")
            self.feedback_message = "fault cleared"
            return Status.SUCCESS
        self.feedback_message = f"waiting for help: {self.ctx.fault}"
        return Status.RUNNING


class RaiseFault(Action):
    """Record why ``watched`` failed as the fault.

    Writes: blackboard ``fault``; an ERROR event. Answers FAILURE (the tick in which the work failed
    is a failed tick; the next one waits for help).
    """

    def __init__(self, ctx: CrsContext, watched: py_trees.behaviour.Behaviour) -> None:
        super().__init__("Raise Fault")
        self.ctx = ctx
        self.watched = watched

    def update(self) -> Status:
        reason = failure_reason(self.watched)
        self.ctx.raise_fault(reason)
        return self.fail(reason)


__all__ = ["NoFault", "RaiseFault", "WaitForHelp", "failure_reason"]
