"""Inspection Check (Fig. 22): the ARS holds a part in front of the lifter's ZED camera, the CRS asks
vision for an inspection report and forwards the result to the ARS.

The hand-off
------------
The ARS calls the CRS's ``/crs/inspect_part`` service (``InspectPart``) while it holds the part,
and that call is the "forwarding" channel: its response *is* the result the CRS forwards.

* :class:`~tlt_crs.inspection_desk.InspectionDesk` (the context's ``desk``) sits between the
  service and the tree. When the CRS sends a request
  whose ARS will present a part, it *expects* that member. A call for the expected member waits
  (in the service's own thread, at most ``timeouts.inspect_handoff_s``) until the tree answers it;
  any other call is answered at once with a report saying why (no inspection expected, a
  different member expected). A call the tree did not answer in time, or that the tree withdrew
  (request finished, fault, Stop), is answered with a report that says so. Those reports are not
  passed and have ``not_inspected`` set: nothing judged the part, so the ARS keeps it and may
  present it again (a restarted CRS not yet expecting it, say). The ARS never waits unboundedly
  and never gets a report for another member.
* One ARS presents a member's part, so a second call for the member means its ARS gave the first
  up (it ran out of time while the CRS was held by a fault, say): the second takes over, and the
  verdict goes to the member's call waiting when it is ready, which need not be the one the tree
  took. With none waiting, :class:`ForwardResult` waits for the part to be presented again: a
  verdict answering a call nobody waits for would be lost, and the ARS would present its part
  until it gave up.
* In the tree, Inspection Check is a Sequence with memory: :class:`WaitForPart` (the ARS's call
  arrived), ``Inspect Part`` (a ``ServiceCall`` to ``/vision/inspect_part``), and
  :class:`ForwardResult` (answers the waiting call with vision's report, passed or not).
* :class:`UntilPartPasses` repeats the check while parts fail, up to blackboard
  ``inspection_attempts`` parts; the ARS discards each failed part and fetches another (it reports
  the count as ``parts_discarded``). One failure too many fails the request, which cancels the ARS
  goal and raises a fault.
"""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status

from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import ServiceCall
from tlt_crs.behaviours.ars_requests import ArsRequest
from tlt_crs.context import CrsContext
from tlt_crs.inspection_desk import PendingInspection


class WaitForPart(Action):
    """Wait until the ARS presents the part of ``request`` (its ``/crs/inspect_part`` call arrived).

    Reads: the inspection desk. Writes: nothing.
    RUNNING: no call yet. SUCCESS: the call is waiting for a report.
    FAILURE: the ARS finished the request without presenting a part (its result is recorded in
    the tower model first and its reason reported), the server that took the goal is gone
    (``ArsRequest.server_gone``), or no part came within ``timeouts.part_presented_s``.
    """

    def __init__(self, request: ArsRequest) -> None:
        super().__init__(f"Wait For Part {request.member.id}")
        self.req = request
        self.ctx = request.ctx
        self.pending: PendingInspection | None = None
        self._started = 0.0

    def initialise(self) -> None:
        self.pending = None
        self._started = self.ctx.clock()
        self.feedback_message = "waiting for the ARS to present the part"

    def update(self) -> Status:
        pending = self.ctx.desk.take(self.req.member.id)
        if pending is not None:
            self.pending = pending
            self.feedback_message = f"part presented ({pending.part_kind})"
            return Status.SUCCESS
        why = presentation_lost(self.req, self._started)
        return self.fail(why) if why else Status.RUNNING


def presentation_lost(request: ArsRequest, since: float) -> str:
    """Why waiting since ``since`` for ``request``'s ARS to present its part is over ('' while it
    is not): the ARS finished the request (its result is recorded in the tower model first), the
    server that took the goal is gone (``ArsRequest.server_gone``), or no call came within
    ``timeouts.part_presented_s``."""
    ctx = request.ctx
    if request.finished:
        ok, reason = request.conclude()
        return reason + " without presenting a part for inspection" if ok else reason
    gone = request.server_gone(ctx.clock()) if request.handle is not None else ""
    if gone:
        return gone
    limit = ctx.config.timeouts.part_presented_s
    if ctx.clock() - since > limit:
        return f"no part presented for '{request.member.id}' within {limit:g} s"
    return ""


class ForwardResult(Action):
    """Answer the ARS's waiting call with vision's report (the forwarded result).

    Reads: the report of ``inspect``; the inspection desk. Writes: ``passed``, ``cannot_judge``,
    ``reasons``; an event ``INSPECTION_PASSED`` (info), ``INSPECTION_FAILED`` (warning) or, where
    vision could not judge the part (no verdict: the ARS keeps it and presents it again),
    ``INSPECTION_UNDECIDED`` (warning), whose text starts with the member id, so the ground can
    count inspections per member.
    SUCCESS when forwarded to a call waiting for it, whether the part passed or not.
    RUNNING while no call for the member waits (the ARS gave its call up and has not presented the
    part again yet). FAILURE if there is nothing to forward, or, while waiting for a call, as
    :class:`WaitForPart` fails (the request ended, its server is gone, no call in time).
    """

    def __init__(self, request: ArsRequest, inspect: ServiceCall) -> None:
        super().__init__(f"Forward Result {request.member.id}")
        self.req = request
        self.ctx = request.ctx
        self.inspect = inspect
        self.passed = False
        self.cannot_judge = False
        self.reasons: list[str] = []
        self._started = 0.0

    def initialise(self) -> None:
        self._started = self.ctx.clock()

    def update(self) -> Status:
        response = self.inspect.last_response
        if response is None:
            return self.fail("no inspection report to forward")
        report = response.report
        self.passed = bool(report.passed)
        self.cannot_judge = not self.passed and bool(report.cannot_judge)
        self.reasons = list(report.reasons)
        member = self.req.member.id
        if not self.ctx.desk.answer(member, report):
            why = presentation_lost(self.req, self._started)
            if why:
                return self.fail(why)
            self.feedback_message = "the ARS gave its call up: waiting for it to present the part again"
            return Status.RUNNING
        reasons = "; ".join(self.reasons) or "no reason given"
        if self.passed:
            self.feedback_message = "passed"
            self.ctx.event(1, "INSPECTION_PASSED", f"{member}: part passed inspection")
        elif self.cannot_judge:
            self.feedback_message = "cannot judge: " + reasons
            self.ctx.event(2, "INSPECTION_UNDECIDED", f"{member}: vision cannot judge the part: {reasons}")
        else:
            self.feedback_message = "failed: " + reasons
            reasons = "; ".join(self.reasons) or "no reason given"
            self.ctx.event(2, "INSPECTION_FAILED", f"{member}: part failed inspection: {reasons}")
        return Status.SUCCESS


class UntilPartPasses(py_trees.decorators.Decorator):
    """Repeat Inspection Check while parts fail, up to blackboard ``inspection_attempts`` parts,
    and while vision cannot judge the part presented, up to ``inspection_looks`` looks at it.

    SUCCESS: a part passed. RUNNING: checking, or waiting for the next part after a failed one, or
    for the same part presented again after a look that could not judge it (a look does not count
    as a failed part: the ARS keeps the part). FAILURE: the check failed, ``inspection_attempts``
    parts failed (reasons of the last one), or ``inspection_looks`` looks in a row could not judge
    the part (the fault then asks the operator).
    """

    def __init__(self, ctx: CrsContext, child: py_trees.behaviour.Behaviour, forward: ForwardResult) -> None:
        super().__init__(
            name=f"Until Part Passes {forward.name.removeprefix('Forward Result ')}", child=child
        )
        self.ctx = ctx
        self.forward = forward
        self.failures = 0
        self.looks = 0

    def initialise(self) -> None:
        self.failures = 0
        self.looks = 0

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.FAILURE:
            self.feedback_message = self.decorated.feedback_message
            return Status.FAILURE
        if status != Status.SUCCESS:
            return status
        if self.forward.passed:
            self.feedback_message = "part passed inspection"
            return Status.SUCCESS
        reasons = "; ".join(self.forward.reasons) or "no reason given"
        if self.forward.cannot_judge:
            self.looks += 1
            looks = int(self.ctx.board.get("inspection_looks", 3))
            if self.looks >= looks:
                self.feedback_message = f"vision could not judge the part in {self.looks} looks: {reasons}"
                return Status.FAILURE
            self.feedback_message = f"look {self.looks} could not judge the part ({reasons}); looking again"
            self.decorated.stop(Status.INVALID)
            return Status.RUNNING
        self.looks = 0
        self.failures += 1
        attempts = int(self.ctx.board.get("inspection_attempts", 2))
        if self.failures >= attempts:
            self.feedback_message = f"{self.failures} part(s) failed inspection, last: {reasons}"
            return Status.FAILURE
        self.feedback_message = f"part {self.failures} failed inspection ({reasons}); waiting for another"
        self.decorated.stop(Status.INVALID)
        return Status.RUNNING


def serve_inspect_part(ctx: CrsContext, callback_group: Any = None) -> Any:
    """Serve ``/crs/inspect_part`` on the context's node from its desk. The callback blocks while
    it waits for the tree, so give it a reentrant group on a multi-threaded executor."""
    from rclpy.callback_groups import ReentrantCallbackGroup
    from tlt_interfaces.srv import InspectPart

    def handle(request: Any, response: Any) -> Any:
        response.report = ctx.desk.serve(
            request.member_id, request.part_kind, request.camera, ctx.config.timeouts.inspect_handoff_s
        )
        return response

    group = callback_group or ReentrantCallbackGroup()
    return ctx.node.create_service(InspectPart, ros_names.CRS_INSPECT_PART, handle, callback_group=group)


def inspection_check(ctx: CrsContext, request: ArsRequest) -> py_trees.behaviour.Behaviour:
    """Fig. 22 for ``request``'s member, wrapped to repeat while parts fail."""
    from tlt_interfaces.srv import InspectPart

    member = request.member
    wait = WaitForPart(request)

    def vision_request() -> Any:
        msg = InspectPart.Request()
        msg.member_id = member.id
        msg.part_kind = wait.pending.part_kind if wait.pending and wait.pending.part_kind else member.kind
        # The ZED the ARS presents the part to (each faces one arm's side of the lifter).
        asked = wait.pending.camera if wait.pending else ""
        msg.camera = asked or ctx.config.camera_mounts.part_camera
        return msg

    inspect = ServiceCall(
        f"Inspect Part {member.id}",
        ctx.node,
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        vision_request,
        response_ok=lambda response: (True, ""),  # pass or fail, the report is forwarded
        **ctx.vision_call_options(),
    )
    forward = ForwardResult(request, inspect)
    check = py_trees.composites.Sequence(
        f"Inspection Check {member.id}", memory=True, children=[wait, inspect, forward]
    )
    return UntilPartPasses(ctx, check, forward)


__all__ = [
    "ForwardResult",
    "UntilPartPasses",
    "WaitForPart",
    "inspection_check",
    "serve_inspect_part",
]
