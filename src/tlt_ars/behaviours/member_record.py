"""The steps around the one that sets a request's member, kept in the ARS's state file (paper
§V.C.3's Figs. 31, 37, 40): Mark Setting before it begins, Record Member when it has set the member,
and Arm Still There?, which allows a step left in doubt between the two to be done again
(:class:`tlt_ars.context.ArsContext`, :mod:`tlt_ars.request_data`).
"""

from __future__ import annotations

import numpy as np
from py_trees.common import Status

from tlt_ars.context import ArsContext
from tlt_common.bt.nodes import Action, Condition


class RecordMember(Action):
    """Record in the ARS's mission state that the request's member is ``what`` (placed, affixed,
    riveted). Writes the mission state, ``RequestData.recorded`` and the state file
    (:meth:`ArsContext.record`). SUCCESS at once; FAILURE without a member, or when the state file
    cannot be written (the member is still known set in memory, and finished when sent again)."""

    def __init__(self, name: str, ctx: ArsContext, what: str) -> None:
        super().__init__(name)
        self.ctx, self.what = ctx, what

    def update(self) -> Status:
        member = self.ctx.data.member
        if member is None:
            return self.fail("no member in this request")
        if (why := self.ctx.record(self.what)) is not None:
            return self.fail(f"{member.id} {self.what}, but {why}")
        self.feedback_message = f"{member.id} {self.what}"
        return Status.SUCCESS


class MarkSetting(Action):
    """Keep in the state file that the step that sets the request's member begins: ``what`` it
    sets (placed, affixed, riveted) and the arm's joints now. Writes ``RequestData.setting`` and
    ``setting_q`` (:meth:`ArsContext.record` clears them). SUCCESS at once; FAILURE without a fresh
    joint state, or when the state file cannot be written (the step does not begin)."""

    def __init__(self, name: str, ctx: ArsContext, what: str) -> None:
        super().__init__(name)
        self.ctx, self.what = ctx, what

    def update(self) -> Status:
        q = self.ctx.arm_q()
        if q is None:
            return self.fail(f"no fresh joint state on '{self.ctx.joint_topic}'")
        data = self.ctx.data
        data.setting, data.setting_q = self.what, tuple(float(v) for v in q)
        if (why := self.ctx.keep()) is not None:
            return self.fail(why)
        return Status.SUCCESS


class ArmStillThere(Condition):
    """True when the arm stands where the step that sets the member began (every joint within
    ``tolerance`` rad of ``RequestData.setting_q``): only there may a step left in doubt be done
    again."""

    def __init__(self, name: str, ctx: ArsContext, tolerance: float = 0.005) -> None:
        super().__init__(name)
        self.ctx, self.tolerance = ctx, tolerance

    def evaluate(self) -> bool:
        began_at, q = self.ctx.data.setting_q, self.ctx.arm_q()
        if began_at is None or q is None:
            self.feedback_message = "no fresh joint state" if q is None else "no joints kept for the step"
            return False
        off = float(np.max(np.abs(q - np.asarray(began_at))))
        self.feedback_message = f"the arm is {off:.4f} rad from where the step began"
        return off <= self.tolerance


__all__ = ["ArmStillThere", "MarkSetting", "RecordMember"]
