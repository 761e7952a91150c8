"""Lifter Link Watch: the build waits while the CRS cannot reach the lifter (issue "whole
system", scenario 7).

The lifter firmware's watchdog zeroes the motors when its link stays silent (docs/lifter-protocol.md),
so while the link is down the CRS can neither move the lifter nor trust what it last reported. It
faults, but not as a failed step does: a failure reaching Raise Fault pre-empts Build Tower, which
cancels every ARS goal in flight (an arm may be holding a part). Instead the build is *held* as a
Pause holds it (mission clock, the CRS's own running motions, PAUSE to each ARS), with the fault
shown in the run state and telemetry, and it goes on by itself when the link is back: the cause is
gone and nothing was lost or redone.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from py_trees.common import Status

from tlt_common.bt.nodes import Action
from tlt_crs.context import CrsContext

if TYPE_CHECKING:
    from tlt_crs.commands import CommandProcessor

HOLD = "lifter link"  # the mission clock's hold reason


class LifterLinkWatch(Action):
    """Hold the build while the lifter is unreachable; let it go on when it is back.

    Reads: the lifter's state (``CrsContext.lifter_link_down``: no state, a stale one, or the
    driver's ``link_ok`` false), for ``timeouts.lifter_link_s`` of ROS time before holding.
    Writes: ``ctx.link_fault``; a ``CRS_FAULT`` event when the hold starts, ``FAULT_CLEARED`` when
    the link is back; the hold itself through the command processor (Hold While Paused above Build
    Tower answers RUNNING meanwhile).
    Always SUCCESS: a guard that failed or ran here would pre-empt the build it protects.
    """

    def __init__(self, ctx: CrsContext, processor: CommandProcessor) -> None:
        super().__init__("Lifter Link Watch")
        self.ctx = ctx
        self.processor = processor
        self._down_since: float | None = None

    def update(self) -> Status:
        ctx = self.ctx
        down = ctx.lifter_link_down()
        now = ctx.ros_seconds()
        if not down:
            self._down_since = None
            if ctx.link_fault:
                cleared, ctx.link_fault = ctx.link_fault, ""
                self.processor.release_build(HOLD)
                ctx.event(1, "FAULT_CLEARED", f"lifter link back, the build goes on (was: {cleared})")
        elif not ctx.link_fault:
            self._down_since = now if self._down_since is None else self._down_since
            if now - self._down_since >= ctx.config.timeouts.lifter_link_s:
                ctx.link_fault = (
                    f"{down}: its watchdog stops the motors; the build is held until the link is back"
                )
                self.processor.hold_build(HOLD)
                ctx.event(3, "CRS_FAULT", ctx.link_fault)
        self.feedback_message = ctx.link_fault or ("lifter link up" if not down else f"{down} (watching)")
        return Status.SUCCESS


__all__ = ["HOLD", "LifterLinkWatch"]
