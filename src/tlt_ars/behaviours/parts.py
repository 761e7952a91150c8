"""Part bookkeeping behaviours: dispenser counts, inspection by the CRS, discarding a part that
failed it, and fetching a replacement (paper §IV.B "tracking the available components", §V.C.3).

* :class:`DispenserHasParts` (condition) and :class:`TakePart` read and decrease the count of a
  dispenser in the ARS's :class:`~tlt_ars.mission_state.MissionState`.
* :class:`PresentPart` calls the CRS's ``InspectPart`` (``ros_names.CRS_INSPECT_PART``), which has
  vision look at the held part with the lifter camera, until a report judges the part (a
  presentation the CRS did not inspect is made again); :class:`PartPassed` reads the verdict.
* :class:`CountDiscard` records a discarded part (dispenser's ``discarded``, the request's
  ``parts_discarded``), then fails with the inspection's reason so the attempt ends (or, for a
  part an earlier request left in the gripper, succeeds).
* :class:`ReplaceDiscarded` (decorator) runs its child again after an attempt that ended with a
  discarded part: a replacement comes from the dispenser until one passes or the dispenser is
  empty (then the request fails with that reason).
"""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status
from tlt_interfaces.srv import InspectPart

from tlt_ars.context import ArsContext
from tlt_ars.mission_state import DispenserEmpty
from tlt_common import ros_names
from tlt_common.bt.nodes import Action, Condition
from tlt_common.bt.ros import ServiceCall


class DispenserHasParts(Condition):
    """True while ``dispenser`` has parts left (the ARS's count). Feedback names the count."""

    def __init__(self, name: str, ctx: ArsContext, dispenser: str) -> None:
        super().__init__(name)
        self.ctx, self.dispenser = ctx, dispenser

    def evaluate(self) -> bool:
        left = self.ctx.state.remaining[self.dispenser]
        self.feedback_message = f"dispenser '{self.dispenser}' is empty" if left <= 0 else f"{left} left"
        return left > 0


class TakePart(Action):
    """Count a part (or rivet) taken from ``dispenser``: decreases its count. Writes
    ``RequestData.holding`` (``kind``, when given) and ``.dispenser``, and the state file
    (:meth:`ArsContext.keep`). SUCCESS at once; FAILURE when the dispenser is already empty or the
    state file cannot be written."""

    def __init__(self, name: str, ctx: ArsContext, dispenser: str, kind: str | None) -> None:
        super().__init__(name)
        self.ctx, self.dispenser, self.kind = ctx, dispenser, kind

    def update(self) -> Status:
        try:
            left = self.ctx.state.take_part(self.dispenser)
        except DispenserEmpty as exc:
            return self.fail(str(exc))
        if self.kind is not None:
            self.ctx.data.holding = self.kind
            self.ctx.data.dispenser = self.dispenser
            if (why := self.ctx.keep()) is not None:
                return self.fail(why)
        self.feedback_message = f"{left} left in '{self.dispenser}'"
        return Status.SUCCESS


# How long after a presentation nobody inspected the part is presented again, s of mission time.
PRESENT_AGAIN_S = 2.0


class PresentPart(ServiceCall):
    """Hold the part up to the CRS's camera: call ``/crs/inspect_part`` until a report judges it.

    Reads: ``RequestData.member``. Writes: :attr:`report` (the judging report);
    ``RequestData.alignment`` = None (the part was moved since any earlier alignment).
    RUNNING: waiting for the CRS's service or its answer; after no answer, or an answer that judged
    nothing (``not_inspected``: the CRS was not expecting the part, say restarted and not started
    again, or it withdrew it; ``cannot_judge``: vision saw nothing wrong but could not settle it),
    presenting again after ``PRESENT_AGAIN_S``.
    SUCCESS: a report judged the part, passed or not (:class:`PartPassed` tells which).
    FAILURE: no judgement within ``timeouts.present_part_s`` (time paused not counted); the part
    is kept (never discarded for a failure of the hand-off, only for a judgement).
    """

    def __init__(self, name: str, ctx: ArsContext) -> None:
        timeouts = ctx.config.timeouts
        super().__init__(
            name,
            ctx.node,
            InspectPart,
            ros_names.CRS_INSPECT_PART,
            self._make,
            service_timeout=timeouts["server_s"],
            timeout=timeouts["service_s"],
            response_ok=self._judged,
            clock=ctx.clock,
        )
        self.ctx = ctx
        self.report: Any = None
        self._deadline = 0.0
        self._again_at: float | None = None

    def initialise(self) -> None:
        super().initialise()
        self.report = None
        self._deadline = self.clock() + self.ctx.config.timeouts["present_part_s"]
        self._again_at = None

    def postpone(self, seconds: float) -> None:
        """A Pause does not count toward ``present_part_s`` (nor the call's own limit)."""
        super().postpone(seconds)
        self._deadline += seconds
        if self._again_at is not None:
            self._again_at += seconds

    def _make(self) -> Any:
        ctx = self.ctx
        member = ctx.data.member
        if member is None:
            raise RuntimeError("no member to inspect")
        return InspectPart.Request(
            member_id=member.id, part_kind=member.kind, camera=ctx.config.cameras["inspection"]
        )

    def _judged(self, response: Any) -> tuple[bool, str]:
        report = response.report
        if report.not_inspected:
            return False, "; ".join(report.reasons) or "not inspected"
        if report.cannot_judge and not report.passed:
            # No verdict: the part is kept and presented again, never discarded on it.
            return False, "vision cannot judge the part: " + ("; ".join(report.reasons) or "no reason given")
        self.report = report
        self.ctx.data.alignment = None
        return True, ""

    def update(self) -> Status:
        now = self.clock()
        if self._again_at is not None:
            if now < self._again_at:
                return Status.RUNNING
            self._again_at = None
            super().initialise()
        status = super().update()
        if status == Status.SUCCESS:
            self.feedback_message = "judged: " + ("passed" if self.report.passed else "failed")
        if status != Status.FAILURE:
            return status
        why = self.feedback_message
        if now >= self._deadline:
            limit = self.ctx.config.timeouts["present_part_s"]
            return self.fail(f"the part was not inspected within {limit:g} s (kept): {why}")
        self._again_at = now + PRESENT_AGAIN_S
        self.feedback_message = f"presenting again in {PRESENT_AGAIN_S:g} s: {why}"
        return Status.RUNNING


class PartPassed(Condition):
    """Reads: ``present``'s report. SUCCESS when it passed; FAILURE with its reasons otherwise."""

    def __init__(self, name: str, present: PresentPart) -> None:
        super().__init__(name)
        self.present = present

    def evaluate(self) -> bool:
        report = self.present.report
        if report is None:
            self.feedback_message = "no inspection report"
            return False
        if not report.passed:
            self.feedback_message = "inspection failed: " + ("; ".join(report.reasons) or "no reason given")
        return bool(report.passed)


class CountDiscard(Action):
    """Record the part just dropped at the discard pose (the Release before it wrote the state
    file). Writes the dispenser's ``discarded`` count, ``RequestData.discarded_from`` (the part's
    dispenser, which the request's result names to the CRS) and ``.holding`` (none). After a
    failed inspection (``reason_of``, the verdict), FAILS the attempt with that reason; for a part
    an earlier request left in the gripper (``reason_of`` None), SUCCEEDS."""

    def __init__(self, name: str, ctx: ArsContext, reason_of: py_trees.behaviour.Behaviour | None) -> None:
        super().__init__(name)
        self.ctx, self.reason_of = ctx, reason_of

    def update(self) -> Status:
        data = self.ctx.data
        if data.dispenser is not None:
            self.ctx.state.count_discard(data.dispenser)
        data.discarded_from.append(data.dispenser or "")
        data.holding = None
        if self.reason_of is not None:
            reason = self.reason_of.feedback_message or "inspection failed"
            return self.fail(f"part discarded ({reason})")
        self.feedback_message = f"a {data.dispenser or 'held'} part discarded"
        return Status.SUCCESS


class ReplaceDiscarded(py_trees.decorators.Decorator):
    """Re-run the child after an attempt that failed having discarded a part; otherwise pass the
    child's status through. Bounded by the dispenser: an empty one fails the child for good."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, ctx: ArsContext) -> None:
        super().__init__(name=name, child=child)
        self.ctx = ctx
        self._discarded_at_start = 0

    def initialise(self) -> None:
        self._discarded_at_start = self.ctx.data.parts_discarded

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.FAILURE and self.ctx.data.parts_discarded > self._discarded_at_start:
            self._discarded_at_start = self.ctx.data.parts_discarded
            self.feedback_message = (
                f"{self.ctx.data.parts_discarded} part(s) discarded: fetching a replacement"
            )
            self.decorated.stop(Status.INVALID)  # the next tick starts the child afresh
            return Status.RUNNING
        self.feedback_message = self.decorated.feedback_message
        return status


__all__ = ["CountDiscard", "DispenserHasParts", "PartPassed", "PresentPart", "ReplaceDiscarded", "TakePart"]
