"""CRS -> ARS requests as ROS 2 actions, split into "send and wait for acknowledgement" and "wait for
the ARS to finish" as Figs. 21, 23-25 and 27 draw them (paper §V.C.1).

One :class:`ArsRequest` holds the goal of one request for one member while it is in flight. Three
behaviours share it: :class:`SendArsRequest` (the acknowledgement), the Inspection Check in between
(:mod:`tlt_crs.behaviours.inspection`), and :class:`AwaitArsResult` (the result). They sit under a
:class:`RequestScope`, a Sequence with memory that cancels the goal when the scope is pre-empted
(a fault, Stop), so no goal is left running on an ARS that the CRS no longer follows.

Failures name the ARS and the action: server not found within ``timeouts.ars_server_s``, goal
rejected, server gone while the goal runs (not discoverable for ``ars_server_s``, or only a new
server is: the ARS process that took the goal was replaced, say restarted by the launcher, and the
new one will never answer it), no result within blackboard ``ars_result_timeout``, aborted, or a
result of failure with the ARS's reason.

A goal whose server was replaced is not yet a fault: the restarted ARS knows from its state file
what the request had done (the part in its jaws, a member it set or may have set), and the same
request sent again finishes it without placing anything twice (:mod:`tlt_ars.request_data`). So
:class:`RequestScope` sends it again, from the start of the scope, up to blackboard
``ars_resends`` times per run (event ``ARS_REQUEST_RESENT``); a resent request that the ARS
finishes with success without presenting its part again (it had set the member already) succeeds,
as its result is recorded in the tower model.
Every wait is measured on the mission clock, which stands still while the CRS is paused. Whether
a server is there is read through :mod:`tlt_common.bt.server_readiness`: waiting uses an answer up
to a quarter second old, and the "missing" and "gone" failures are decided on a fresh one.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import Any

import py_trees
from action_msgs.msg import GoalStatus
from py_trees.common import Status

from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import default_feedback_text, shared_action_client
from tlt_common.bt.server_readiness import READINESS_PERIOD_S, Readiness, readiness_of
from tlt_common.mission.schema import Member
from tlt_crs.context import CrsContext

GoalBuilder = Callable[[str], Any]  # ARS name -> goal message
ResultRecorder = Callable[[CrsContext, Member, Any, bool], None]


class _Server:
    """One ARS's action server for one request: its name, shared client and readiness."""

    __slots__ = ("action", "client", "readiness", "waiting_text")

    def __init__(self, action: str, client: Any, readiness: Readiness) -> None:
        self.action = action
        self.client = client
        self.readiness = readiness
        self.waiting_text = f"waiting for '{action}'"


class ArsRequest:
    """The goal of one request (``request``, one of ``ros_names.ARS_ACTIONS``) for one member."""

    def __init__(
        self,
        ctx: CrsContext,
        action_type: Any,
        request: str,
        member: Member,
        ars: str | Callable[[], str],
        make_goal: GoalBuilder,
        record: ResultRecorder,
        *,
        inspected: bool = False,
    ) -> None:
        self.ctx = ctx
        self.action_type = action_type
        self.request = request
        self.member = member
        self._ars = ars
        self.make_goal = make_goal
        self.record = record
        self.inspected = inspected  # the ARS presents the part to /crs/inspect_part meanwhile
        self.title = request.replace("_", " ").title().replace(" ", "")
        self._servers: dict[str, _Server] = {}
        self.reset()
        # Of the last goal sent, kept past the reset that forgets it, for RequestScope to read:
        self.replaced = False  # its server was replaced while it ran (the ARS restarted)
        self.concluded_ok = False  # it ended in success, recorded in the tower model

    def ars(self) -> str:
        return self._ars() if callable(self._ars) else self._ars

    def client(self, ars: str) -> Any:
        return self.server(ars).client

    def server(self, ars: str) -> _Server:
        """The client, readiness and texts for ``ars``'s action server of this request, made once:
        a waiting behaviour looks them up on every tick."""
        server = self._servers.get(ars)
        if server is None:
            action = ros_names.ars_action(ars, self.request)
            client = shared_action_client(self.ctx.node, self.action_type, action)
            server = _Server(action, client, readiness_of(client))
            self._servers[ars] = server
        return server

    def reset(self) -> None:
        self.ars_name = ""
        self.send_future: Any = None
        self.handle: Any = None
        self.result_future: Any = None
        self.feedback: Any = None
        self.accepted_at = 0.0
        self._sent_to: frozenset[bytes] = frozenset()  # status endpoints listed when the goal was sent
        self._serving: frozenset[bytes] = frozenset()  # ... of which one took the goal
        self._known: frozenset[bytes] = frozenset()  # every one listed around the acceptance
        self._serving_seen = (-float("inf"), True)  # (monotonic time, still served)
        self._lost_since: float | None = None

    @property
    def finished(self) -> bool:
        return self.result_future is not None and self.result_future.done()

    def _status_publishers(self) -> frozenset[bytes]:
        topic = f"{ros_names.ars_action(self.ars_name, self.request)}/_action/status"
        return frozenset(bytes(i.endpoint_gid) for i in self.ctx.node.get_publishers_info_by_topic(topic))

    def send(self, ars: str, goal: Any) -> None:
        """Send ``goal`` to ``ars``, noting which servers were there to take it."""
        self.ars_name = ars
        self.replaced = self.concluded_ok = False
        self._sent_to = self._status_publishers()
        self.send_future = self.client(ars).send_goal_async(goal, feedback_callback=self._on_feedback)

    def accepted(self, handle: Any, now: float) -> None:
        """Follow the goal ``handle`` accepted at mission time ``now``, and note which servers may
        hold it: those listed both when it was sent and now (the graph can list a dead process's
        server for its lease, and a restarted one's only after the acceptance came back)."""
        self.handle = handle
        self.accepted_at = now
        self.result_future = handle.get_result_async()
        listed = self._status_publishers()
        self._serving = (self._sent_to & listed) or listed or self._sent_to
        self._known = self._sent_to | listed
        self._serving_seen = (time.monotonic(), True)
        self._lost_since = None

    def _still_served(self, fresh: bool) -> bool:
        """Whether a server that may hold the goal is listed, and none came up since it was taken
        (one ARS runs one server per action: a newcomer replaced it, say a launcher restart)."""
        # Asked of the graph at most every READINESS_PERIOD_S of wall time, as server readiness is.
        if not self._serving:
            return True  # not known (the graph listed none around the acceptance): readiness decides
        at, served = self._serving_seen
        now = time.monotonic()
        if fresh or now - at >= READINESS_PERIOD_S:
            listed = self._status_publishers()
            served = bool(self._serving & listed) and listed <= self._known
            self._serving_seen = (now, served)
        return served

    def server_gone(self, now: float) -> str:
        """Why the goal in flight can no longer finish ('' while it can): the server that took it
        has been undiscoverable, or replaced by another, for ``timeouts.ars_server_s`` of mission
        time up to ``now`` (decided on a fresh look at the graph). The goal is then canceled."""
        readiness = self.server(self.ars_name).readiness
        if readiness.ready() and self._still_served(fresh=False):
            self._lost_since = None
            return ""
        self._lost_since = now if self._lost_since is None else self._lost_since
        if now - self._lost_since <= self.ctx.config.timeouts.ars_server_s:
            return ""
        up, present = readiness.ready_now(), self._still_served(fresh=True)
        if up and present:  # back (or the cached answer was old): not gone
            self._lost_since = None
            return ""
        name = self.describe()
        why = "" if not up else f": a new '{self.server(self.ars_name).action}' server does not know the goal"
        self.cancel()
        self.replaced = up
        return f"ARS '{name.rsplit(' on ', 1)[-1]}' gone while running {name}{why}"

    def describe(self) -> str:
        return f"{self.title} for '{self.member.id}' on {self.ars_name or self.ars()}"

    def cancel(self) -> None:
        """Cancel the goal in flight (also one not yet accepted, or accepted since the last tick);
        forget it."""
        if self.handle is not None:
            if not self.finished:
                self.handle.cancel_goal_async()
        elif self.send_future is not None:

            def cancel_when_accepted(future: Any) -> None:
                handle = future.result()
                if handle is not None and handle.accepted:
                    handle.cancel_goal_async()

            # A goal accepted between two ticks has its handle only in the future: a Stop there
            # left the ARS working on after the CRS had stopped.
            if self.send_future.done():
                cancel_when_accepted(self.send_future)
            else:
                self.send_future.add_done_callback(cancel_when_accepted)
        if self.inspected:
            self.ctx.desk.withdraw(self.member.id, "the CRS stopped following this request")
        self.reset()

    def conclude(self) -> tuple[bool, str]:
        """Record the finished goal's result in the tower model and forget the goal.

        Returns (success, text): the ARS's reason of a failure, or "... done".
        """
        response = self.result_future.result()
        result, status = response.result, response.status
        ok = status == GoalStatus.STATUS_SUCCEEDED and bool(getattr(result, "success", True))
        reason = str(getattr(result, "reason", "") or "")
        if status == GoalStatus.STATUS_UNKNOWN:
            # What a restarted ARS's server answers a result request for its predecessor's goal.
            reason = "the ARS does not know the goal (its server was replaced, say by a restart)"
        elif status != GoalStatus.STATUS_SUCCEEDED:
            reason = f"goal ended with status {status}" + (f": {reason}" if reason else "")
        name = self.describe()
        with self.ctx.lock:
            self.record(self.ctx, self.member, result, ok)
        if self.inspected:
            self.ctx.desk.withdraw(self.member.id, "the ARS finished the request")
        self.reset()
        self.replaced = status == GoalStatus.STATUS_UNKNOWN
        self.concluded_ok = ok
        return ok, (f"{name} done" if ok else f"{name} failed: {reason or 'no reason given'}")

    def _on_feedback(self, message: Any) -> None:
        self.feedback = message.feedback


class SendArsRequest(Action):
    """Send the request's goal and wait for the ARS to acknowledge (accept) it.

    Reads: blackboard ``cross_frame_ars`` for a cross frame (through the request's ARS callable).
    RUNNING: waiting for the server or the acceptance, each up to ``timeouts.ars_server_s``.
    SUCCESS: the goal was accepted. FAILURE: no server, no answer, rejected, goal not buildable.
    """

    def __init__(self, request: ArsRequest) -> None:
        super().__init__(f"Send {request.title} {request.member.id}")
        self.req = request
        self.ctx = request.ctx
        self._started = 0.0

    def initialise(self) -> None:
        if self.req.send_future is not None or self.req.handle is not None:
            self.req.cancel()
        self.req.reset()
        self._started = self.ctx.clock()
        self.feedback_message = "looking for the ARS"

    def update(self) -> Status:
        req, now = self.req, self.ctx.clock()
        limit = self.ctx.config.timeouts.ars_server_s
        if req.send_future is None:
            try:
                ars = req.ars()
                server = req.server(ars)
            except ValueError as exc:
                return self.fail(f"cannot address the ARS: {exc}")
            up = server.readiness.wait(now - self._started, limit)
            if up is None:
                self.feedback_message = server.waiting_text
                return Status.RUNNING
            if not up:
                return self.fail(
                    f"ARS '{ars}' missing: action server '{server.action}' not available after {limit:g} s"
                )
            try:
                goal = req.make_goal(ars)
            except Exception as exc:
                return self.fail(f"cannot build the {req.title} goal for '{req.member.id}': {exc}")
            if req.inspected:
                self.ctx.desk.expect(req.member.id)
            req.send(ars, goal)
            self._started = now
            self.feedback_message = f"sent to {ars}"
            return Status.RUNNING
        if not req.send_future.done():
            if now - self._started > limit:
                req.cancel()
                return self.fail(f"ARS did not acknowledge {req.describe()} within {limit:g} s")
            return Status.RUNNING
        handle = req.send_future.result()
        if handle is None or not handle.accepted:
            name = req.describe()
            req.cancel()
            return self.fail(f"{name} rejected by the ARS")
        req.accepted(handle, now)
        self.feedback_message = f"acknowledged by {req.ars_name}"
        return Status.SUCCESS


class AwaitArsResult(Action):
    """Wait for the ARS to finish the request, then record the result in the tower model.

    Reads: blackboard ``ars_result_timeout``. Writes: the tower model (through the request's recorder).
    RUNNING: the goal runs (feedback shows the ARS's step). SUCCESS: result success.
    FAILURE: result failure (the ARS's reason), aborted/canceled, no result in time (the goal is
    canceled), the server that took the goal gone (:meth:`ArsRequest.server_gone`), or no goal
    was sent.
    """

    def __init__(self, request: ArsRequest) -> None:
        super().__init__(f"Wait For {request.title} {request.member.id}")
        self.req = request
        self.ctx = request.ctx
        self._shown: Any = None

    def initialise(self) -> None:
        self._shown = None

    def update(self) -> Status:
        req, now = self.req, self.ctx.clock()
        if req.result_future is None:
            return self.fail(f"no {req.title} goal in flight for '{req.member.id}'")
        if not req.result_future.done():
            feedback = req.feedback
            if feedback is not None and feedback is not self._shown:  # formatted once per message
                self._shown = feedback
                self.feedback_message = f"{req.ars_name}: {default_feedback_text(feedback)}"
            timeout = float(self.ctx.board.get("ars_result_timeout", 600.0))
            if now - req.accepted_at > timeout:
                name = req.describe()
                req.cancel()
                return self.fail(f"no result for {name} within {timeout:g} s")
            gone = req.server_gone(now)
            return self.fail(gone) if gone else Status.RUNNING
        ok, reason = req.conclude()
        if not ok:
            return self.fail(reason)
        self.feedback_message = reason
        return Status.SUCCESS


class RequestScope(py_trees.composites.Sequence):
    """A Sequence with memory owning one :class:`ArsRequest`: when it ends other than in SUCCESS
    (pre-empted or failed), the goal still in flight is canceled.

    Reads: blackboard ``ars_resends``. Writes: event ``ARS_REQUEST_RESENT``.
    When it fails because the server running its goal was replaced (the ARS restarted, see
    :meth:`ArsRequest.server_gone` and :meth:`ArsRequest.conclude`), it starts again from its first
    child, which sends the same request to the new server, and answers RUNNING instead, up to
    ``ars_resends`` times per run. After such a resend, a failure of a request the ARS finished
    with success (a Wait For Part that saw the result before any part) is SUCCESS: the result is
    recorded in the tower model.
    """

    def __init__(self, name: str, request: ArsRequest, children: list[py_trees.behaviour.Behaviour]) -> None:
        super().__init__(name, memory=True, children=children)
        self.request = request
        self.resends = 0

    def initialise(self) -> None:
        self.resends = 0

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        for node in super().tick():
            if node is self and self.status == Status.FAILURE:
                self._after_failure()
            yield node

    def _after_failure(self) -> None:
        """Turn a failure into a resend (RUNNING) or, after one, into the ARS's success."""
        req, ctx = self.request, self.request.ctx
        if self.resends and req.concluded_ok:
            self.status = Status.SUCCESS
            self.feedback_message = f"{req.describe()} finished by the restarted ARS"
            return
        if not req.replaced:
            return
        limit = int(ctx.board.get("ars_resends", 2))
        if self.resends >= limit:
            self.feedback_message = f"sent {self.resends + 1} times, the ARS replaced each time"
            return
        self.resends += 1
        ctx.event(
            2,
            "ARS_REQUEST_RESENT",
            f"{req.describe()}: the ARS was replaced (restarted) while it ran the request; sent"
            f" again ({self.resends} of {limit})",
        )
        req.replaced = False
        for child in self.children:
            if child.status != Status.INVALID:
                child.stop(Status.INVALID)
        self.current_child = self.children[0]
        self.status = Status.RUNNING
        self.feedback_message = f"sending again to the restarted ARS ({self.resends} of {limit})"

    def terminate(self, new_status: Status) -> None:
        # Pre-empted, or failed part-way (e.g. a part failed inspection too often): the ARS stops too.
        if new_status != Status.SUCCESS:
            self.request.cancel()


__all__ = ["ArsRequest", "AwaitArsResult", "RequestScope", "SendArsRequest"]
