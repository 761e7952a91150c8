"""stop_executor: the callbacks an executor is running end before it returns, and what they raised
is handed back, not reported at exit."""

from __future__ import annotations

import gc
import threading
import time

import pytest
import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node

from tlt_common.ros.executor_stop import stop_executor


@pytest.fixture
def running():
    """A node on a MultiThreadedExecutor spun by a thread, as the nodes' mains spin it."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("executor_stop_test", context=context)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    done = threading.Event()

    def spin() -> None:
        while not done.is_set():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception:  # a failed callback's exception, raised at the next dispatch
                pass

    def stop_spinning() -> None:
        # As in the mains, stop_executor comes after the spin loop has returned: rclpy records a
        # dispatched callback only after handing it to a worker, which may already be running it.
        done.set()
        thread.join(timeout=5)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    yield node, executor, stop_spinning
    stop_spinning()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def _once(node: Node, callback, group=None) -> threading.Event:
    started = threading.Event()

    def fire() -> None:
        timer.cancel()
        started.set()
        callback()

    timer = node.create_timer(0.01, fire, callback_group=group)
    return started


def test_it_returns_only_once_the_running_callback_has_ended(running):
    node, executor, stop_spinning = running
    ended = []
    started = _once(node, lambda: (time.sleep(0.5), ended.append(time.monotonic())))
    assert started.wait(5)
    stop_spinning()  # as on a signal
    raised = stop_executor(executor, 5.0)
    returned = time.monotonic()
    assert ended and ended[0] <= returned and raised == []


def test_it_hands_back_what_a_callback_raised_and_nothing_is_reported_at_exit(running, capsys):
    node, executor, stop_spinning = running
    # Earlier tests in this process may leave rclpy tasks in reference cycles; collected below,
    # they would report their own exceptions into this test's stderr.
    gc.collect()
    capsys.readouterr()

    def fail() -> None:
        time.sleep(0.2)
        raise RuntimeError("publisher gone")

    assert _once(node, fail).wait(5)
    stop_spinning()
    raised = stop_executor(executor, 5.0)
    assert [str(e) for e in raised] == ["publisher gone"]
    executor._futures.clear()  # the executor's last references to the tasks
    gc.collect()
    assert "never retrieved" not in capsys.readouterr().err


def test_a_callback_longer_than_the_bound_is_left_running(running):
    node, executor, stop_spinning = running
    release = threading.Event()
    assert _once(node, lambda: release.wait(10)).wait(5)
    stop_spinning()
    t0 = time.monotonic()
    assert stop_executor(executor, 0.3) == []
    assert 0.25 <= time.monotonic() - t0 < 2.0
    release.set()


def test_a_callback_queued_behind_busy_workers_still_runs_cleanly(running):
    """Both worker threads busy, a third callback waits in the pool: shut down before it starts,
    the executor's guard condition, which it triggers as it starts, would be gone."""
    node, executor, stop_spinning = running
    group = ReentrantCallbackGroup()
    ran = []
    busy = [_once(node, lambda: time.sleep(0.4), group) for _ in range(2)]
    assert all(b.wait(5) for b in busy)
    queued = _once(node, lambda: ran.append(True), group)
    deadline = time.monotonic() + 5
    while len(executor._futures) < 3 and time.monotonic() < deadline:  # dispatched, not started
        time.sleep(0.005)
    assert not queued.is_set()
    stop_spinning()
    assert stop_executor(executor, 5.0) == []
    assert ran == [True]
