"""Send ARS Request waiting for an ARS action server: the server's readiness is read from a cache
between ticks, but "ARS missing" is decided exactly at ``timeouts.ars_server_s`` of mission time on
a fresh answer, and a server that came up meanwhile gets the goal instead. A goal accepted between
two ticks is still canceled when the request is.

The mission clock is injected (exact timeouts on a loaded machine); the action servers are real."""

from __future__ import annotations

import time

from py_trees.common import Status
from rclpy.action import ActionServer, GoalResponse
from tlt_interfaces.action import AddMember

from tlt_common.bt.server_readiness import FRESH_S
from tlt_crs.behaviours.ars_requests import SendArsRequest
from tlt_crs.context import MissionClock
from tlt_crs.tree import add_member_request

LIMIT = 0.3
MEMBER = "bay1/vertical/x0_y1"  # added by ARS X


class FakeSeconds:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _steadily(client, listed: bool) -> bool:
    """The client's server is listed (or not) on six looks 50 ms apart (the graph can flicker)."""
    for _ in range(6):
        if client.server_is_ready() != listed:
            return False
        time.sleep(0.05)
    return True


def _waiting_send(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, ars_server_s=LIMIT))
    seconds = FakeSeconds()
    ctx.clock = MissionClock(seconds)
    request = add_member_request(ctx, ctx.mission.member(MEMBER))
    # The ARS processes of earlier tests are gone, but the graph may list their servers a while
    # longer (a killed participant, until its DDS lease ends): these tests start with none listed.
    client = request.client("ars_x")
    crs.wait_for(lambda: _steadily(client, listed=False), 30.0, "earlier tests' ARS X servers forgotten")
    send = SendArsRequest(request)
    send.tick_once()
    assert send.status is Status.RUNNING
    assert send.feedback_message == "waiting for '/ars_x/add_member'"
    readiness = request.server("ars_x").readiness
    readiness.period = 3600.0  # the cached "not there" never expires on its own in these tests
    return send, readiness, seconds


def test_missing_ars_fails_exactly_after_the_limit_on_a_fresh_answer(ros, crs, tmp_path):
    rig = crs.Rig(with_drivers=False, with_ars=False)
    try:
        send, readiness, seconds = _waiting_send(rig, crs, tmp_path)
        asked = readiness.asked
        seconds.now += LIMIT  # at the limit, not past it: still waiting, on the cached answer
        for _ in range(20):
            send.tick_once()
            assert send.status is Status.RUNNING
        assert readiness.asked == asked
        time.sleep(2 * FRESH_S)  # an answer younger than FRESH_S would count as fresh
        seconds.now += 0.01
        send.tick_once()
        assert send.status is Status.FAILURE
        assert readiness.asked == asked + 1  # decided on a fresh answer
        assert "ARS 'ars_x' missing" in send.feedback_message
        assert f"'/ars_x/add_member' not available after {LIMIT:g} s" in send.feedback_message
    finally:
        rig.close()


def test_server_that_came_up_behind_the_cache_gets_the_goal_instead_of_a_fault(ros, crs, tmp_path):
    rig = crs.Rig(with_drivers=False, with_ars=False)
    try:
        send, _, seconds = _waiting_send(rig, crs, tmp_path)
        received = []

        def on_goal(goal):
            received.append(goal.member_id)
            return GoalResponse.ACCEPT

        def execute(handle):
            handle.succeed()
            return AddMember.Result(success=True)

        server = ActionServer(
            rig.node,
            AddMember,
            "/ars_x/add_member",
            execute_callback=execute,
            goal_callback=on_goal,
            callback_group=rig.group,
        )
        try:
            # Discovered for good: just after an earlier test's servers went away, the graph can
            # still show theirs for a moment (ready, then not) before this one's are matched.
            client = send.req.client("ars_x")
            crs.wait_for(lambda: _steadily(client, listed=True), 10.0, "the late server discovered")
            send.tick_once()
            assert send.status is Status.RUNNING and send.feedback_message.startswith("waiting for")
            seconds.now += LIMIT + 0.01
            send.tick_once()  # past the limit: the fresh answer says the server is there
            assert (send.status, send.feedback_message) == (Status.RUNNING, "sent to ars_x")
            assert crs.tick_until(send) == Status.SUCCESS
            assert received == [MEMBER]
        finally:
            server.destroy()
    finally:
        rig.close()


def test_a_goal_accepted_since_the_last_tick_is_canceled_too(ros, crs, tmp_path):
    rig = crs.Rig(with_drivers=False)
    try:
        rig.ars["ars_x"].hold_s = 30.0
        rig.ars["ars_x"].present_parts = False
        ctx = crs.make_context(rig, crs.fast_config(tmp_path))
        request = add_member_request(ctx, ctx.mission.member(MEMBER))
        send = SendArsRequest(request)
        crs.wait_for(lambda: request.server("ars_x").readiness.ready_now(), 10.0, "ARS X discovered")
        send.tick_once()
        assert send.feedback_message == "sent to ars_x"
        crs.wait_for(lambda: request.send_future.done(), 10.0, "goal accepted")
        assert request.handle is None  # accepted, but no tick has taken the handle yet
        request.cancel()
        crs.wait_for(
            lambda: [r.outcome for r in rig.recorder.requests] == ["canceled"], 10.0, "ARS goal canceled"
        )
    finally:
        rig.close()
