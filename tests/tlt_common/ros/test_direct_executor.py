"""DirectExecutor against rclpy in one process: timers (on sim time too) and subscriptions called
directly, async callbacks, services and actions still served, errors out of spin_once, an entity
destroyed by its own callback; the multi-threaded one calling /clock and quick subscriptions on its
spinning thread while a worker is busy, and logging a quick callback's error."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator

import pytest
import rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.parameter import Parameter
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from std_srvs.srv import Trigger
from tlt_interfaces.action import FollowJointTrajectory

from tlt_common.ros.direct_executor import DirectExecutor, DirectMultiThreadedExecutor, QuickCallbackGroup
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.node_teardown import destroy_node

TIMEOUT_S = 10.0


class Rig:
    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = LeanNode("direct_executor_test", context=self.context)
        self.executor = DirectExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, predicate, what: str) -> None:
        deadline = time.monotonic() + TIMEOUT_S
        while not predicate():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.executor.shutdown()
        destroy_node(self.node)
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    try:
        yield r
    finally:
        r.close()


def test_timers_and_subscriptions_are_called_with_their_messages(rig):
    got: list[str] = []
    with_info: list[tuple[str, int]] = []
    pub = rig.node.create_publisher(String, "chatter", 10)
    rig.node.create_subscription(String, "chatter", lambda m: got.append(m.data), 10)
    rig.node.create_subscription(
        String, "chatter", lambda m, info: with_info.append((m.data, info["source_timestamp"])), 10
    )
    sent = iter(range(1000))
    rig.node.create_timer(0.01, lambda: pub.publish(String(data=f"m{next(sent)}")))
    rig.spin_until(lambda: len(got) >= 5 and len(with_info) >= 5, "five messages")
    assert got[:5] == ["m0", "m1", "m2", "m3", "m4"]
    assert [d for d, _ in with_info[:5]] == got[:5] and all(stamp > 0 for _, stamp in with_info)


def test_a_sim_time_timer_follows_the_clock_messages(rig):
    node = LeanNode(
        "on_sim_time", context=rig.context, parameter_overrides=[Parameter("use_sim_time", value=True)]
    )
    rig.executor.add_node(node)
    clock = rig.node.create_publisher(Clock, "/clock", 10)
    fired: list[float] = []
    node.create_timer(0.02, lambda: fired.append(node.get_clock().now().nanoseconds * 1e-9))
    step = [0]

    def publish_clock() -> None:
        step[0] += 1
        clock.publish(Clock(clock=rclpy.time.Time(nanoseconds=1_000_000_000 + step[0] * 20_000_000).to_msg()))

    rig.node.create_timer(0.005, publish_clock)
    rig.spin_until(lambda: len(fired) >= 10, "ten sim-time timer calls")
    assert all(t >= 1.0 for t in fired)  # on sim time, not the system clock
    gaps = [b - a for a, b in itertools.pairwise(fired)]
    assert min(gaps) >= 0.02 - 1e-9


def test_async_callbacks_services_and_actions_still_run(rig):
    released = Future()
    awaited: list[str] = []

    async def on_message(msg: String) -> None:
        await released
        awaited.append(msg.data)

    rig.node.create_subscription(String, "async", on_message, 10)
    pub = rig.node.create_publisher(String, "async", 10)
    rig.node.create_service(Trigger, "ping", lambda _req, res: setattr(res, "success", True) or res)
    client = rig.node.create_client(Trigger, "ping")
    goals: list[int] = []

    def execute(handle):
        goals.append(len(handle.request.trajectory.points))
        handle.succeed()
        return FollowJointTrajectory.Result(error_string="done")

    ActionServer(rig.node, FollowJointTrajectory, "follow", execute_callback=execute)
    actions = ActionClient(rig.node, FollowJointTrajectory, "follow")
    rig.spin_until(lambda: client.service_is_ready() and actions.server_is_ready(), "servers")
    reply = client.call_async(Trigger.Request())
    rig.spin_until(reply.done, "the service reply")
    assert reply.result().success
    accepted = actions.send_goal_async(FollowJointTrajectory.Goal())
    rig.spin_until(accepted.done, "the goal accepted")
    result = accepted.result().get_result_async()
    rig.spin_until(result.done, "the action result")
    assert result.result().result.error_string == "done" and goals == [0]
    # (an async callback waiting holds its callback group, here the node's default one: last)
    pub.publish(String(data="later"))
    for _ in range(20):
        rig.executor.spin_once(timeout_sec=0.02)
    assert awaited == []  # the async callback is waiting on its future
    released.set_result(None)
    rig.executor.wake()
    rig.spin_until(lambda: awaited, "the async callback resumed")
    assert awaited == ["later"]


def test_an_error_in_a_callback_comes_out_of_spin_once(rig):
    def broken() -> None:
        raise RuntimeError("servo table corrupt")

    rig.node.create_timer(0.01, broken)
    with pytest.raises(RuntimeError, match="servo table corrupt"):
        rig.spin_until(lambda: False, "the error")


def test_a_subscription_destroyed_by_its_own_callback_is_not_called_again(rig):
    got: list[str] = []
    pub = rig.node.create_publisher(String, "once", 10)

    def once(msg: String) -> None:
        got.append(msg.data)
        rig.node.destroy_subscription(sub)

    sub = rig.node.create_subscription(String, "once", once, 10)
    ticks = [0]

    def publish() -> None:
        ticks[0] += 1
        pub.publish(String(data=f"m{ticks[0]}"))

    rig.node.create_timer(0.01, publish)
    rig.spin_until(lambda: ticks[0] >= 20, "twenty publications")
    assert got == ["m1"]


def test_the_multi_threaded_one_calls_clock_and_quick_subscriptions_on_its_spinning_thread(rig):
    executor = DirectMultiThreadedExecutor(num_threads=2, context=rig.context)
    sim = LeanNode(
        "on_sim_time_mt", context=rig.context, parameter_overrides=[Parameter("use_sim_time", value=True)]
    )
    feeder = LeanNode("feeder", context=rig.context)
    executor.add_node(sim)
    executor.add_node(feeder)
    threads: dict[str, set[str]] = {"quick": set(), "plain": set()}
    busy = threading.Event()

    def plain(_msg: String) -> None:
        threads["plain"].add(threading.current_thread().name)
        busy.set()
        time.sleep(0.5)  # a worker held: quick callbacks and the clock go on meanwhile

    def quick(msg: String) -> None:
        threads["quick"].add(threading.current_thread().name)
        if msg.data == "bad":
            raise ValueError("a broken store")

    sim.create_subscription(String, "quick", quick, 10, callback_group=QuickCallbackGroup())
    sim.create_subscription(String, "plain", plain, 10)
    clock = feeder.create_publisher(Clock, "/clock", 10)
    quick_pub = feeder.create_publisher(String, "quick", 10)
    plain_pub = feeder.create_publisher(String, "plain", 10)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, name="spinner", daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while not (
            sim.count_publishers("plain")
            and feeder.count_subscribers("quick")
            and feeder.count_subscribers("/clock")
        ):
            assert time.monotonic() < deadline, "no match"
            time.sleep(0.05)
        plain_pub.publish(String(data="x"))
        assert busy.wait(TIMEOUT_S)
        for k in range(5):
            quick_pub.publish(String(data="bad" if k == 2 else "ok"))
        while sim.get_clock().now().nanoseconds < 100 * 10**9 or len(threads["quick"]) == 0:
            assert time.monotonic() < deadline, "the clock and quick callbacks did not run"
            clock.publish(Clock(clock=rclpy.time.Time(seconds=100).to_msg()))
            time.sleep(0.02)
        assert threads["quick"] == {"spinner"}  # and spinning went on after the broken store
        assert threads["plain"] and "spinner" not in threads["plain"]
    finally:
        stop.set()
        spinner.join(TIMEOUT_S)
        executor.shutdown()
        destroy_node(sim)
        destroy_node(feeder)
