"""Readiness: a server's "is it up?" answer kept for a period of monotonic time (injected here),
fresh on demand; and one Readiness per rclpy client."""

from __future__ import annotations

import pytest
import rclpy
from tlt_interfaces.action import AddMember
from tlt_interfaces.srv import SetBlackboardValue

from tlt_common.bt.ros import shared_action_client, shared_service_client
from tlt_common.bt.server_readiness import FRESH_S, Readiness, readiness_of


class Server:
    """What rclpy would answer, and how often it was asked."""

    def __init__(self) -> None:
        self.up = False
        self.asked = 0

    def is_ready(self) -> bool:
        self.asked += 1
        return self.up


class Monotonic:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def server_and_clock():
    server, clock = Server(), Monotonic()
    return server, clock, Readiness(server.is_ready, period=0.25, monotonic=clock)


def test_answer_is_kept_for_the_period(server_and_clock):
    server, clock, readiness = server_and_clock
    assert readiness.ready() is False
    server.up = True
    for _ in range(10):
        clock.now += 0.02
        assert readiness.ready() is False  # 0.2 s old at most: the cached answer
    assert server.asked == 1 and readiness.asked == 1
    clock.now += 0.05  # 0.25 s: asked again
    assert readiness.ready() is True
    assert server.asked == 2


def test_ready_now_asks_unless_just_asked(server_and_clock):
    server, clock, readiness = server_and_clock
    assert readiness.ready() is False
    assert readiness.ready_now() is False  # the same instant: the answer just given
    assert server.asked == 1
    server.up = True
    clock.now += 2 * FRESH_S
    assert readiness.ready_now() is True
    assert server.asked == 2
    server.up = False
    clock.now += 0.1
    assert readiness.ready() is True  # within the period of the fresh answer
    assert readiness.ready_now() is False
    assert server.asked == 3


def test_wait_runs_on_cached_answers_and_decides_on_fresh_ones(server_and_clock):
    server, clock, readiness = server_and_clock
    assert readiness.wait(0.0, timeout=1.0) is None  # not up: keep waiting
    server.up = True
    clock.now += 0.1
    assert readiness.wait(0.1, timeout=1.0) is None  # up, but the cached answer says not yet
    assert server.asked == 1
    clock.now += 0.2
    assert readiness.wait(0.3, timeout=1.0) is True  # the period is over: asked, up
    assert server.asked == 2


def test_wait_fails_only_on_a_fresh_answer_after_the_timeout(server_and_clock):
    server, clock, readiness = server_and_clock
    assert readiness.wait(0.0, timeout=1.0) is None
    clock.now += 0.01
    server.up = True  # came up just now; the cache still says not
    assert readiness.wait(1.5, timeout=1.0) is True  # past the timeout: asked afresh, not failed
    server.up = False
    clock.now += 0.01
    assert readiness.wait(1.6, timeout=1.0) is False
    assert server.asked == 3


def test_period_zero_asks_every_time():
    server, clock = Server(), Monotonic()
    readiness = Readiness(server.is_ready, period=0.0, monotonic=clock)
    for _ in range(5):
        readiness.ready()
    assert server.asked == 5


def test_negative_period_is_refused():
    with pytest.raises(ValueError, match="period"):
        Readiness(lambda: True, period=-1.0)


def test_one_readiness_per_client_for_actions_and_services():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("readiness_test", context=context)
    try:
        action = shared_action_client(node, AddMember, "nobody/add_member")
        service = shared_service_client(node, SetBlackboardValue, "nobody/set")
        again = shared_action_client(node, AddMember, "nobody/add_member")
        assert readiness_of(action) is readiness_of(again)
        assert readiness_of(service) is readiness_of(service)
        assert readiness_of(action) is not readiness_of(service)
        assert readiness_of(action).ready() is False and readiness_of(service).ready() is False
        assert readiness_of(action).asked == 1 and readiness_of(service).asked == 1
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
