"""Executors that call quick callbacks straight from the wait, without rclpy's per-callback tasks.

rclpy's executors wrap every callback in a ``Task`` that runs a coroutine, keep it in a list that
each later wait walks, and trigger the executor's guard condition when the callback is taken and
again when it is done, so every callback costs one more wait that finds nothing to do. A driver
node on the twin wakes twice per ``/clock`` message (the clock, then its timer), 50 times per
simulated second; for a node with a timer, a publisher and a subscription that bookkeeping is
about a third of its CPU.

:class:`DirectExecutor` takes a ready timer or subscription whose callback is a plain function and
calls it on the spinning thread, with no task, coroutine or guard trigger: the spinning thread
builds the next wait set itself, after the callback. Everything else (async callbacks, services,
clients, guard conditions, waitables such as action servers) goes rclpy's way. As with rclpy's
``SingleThreadedExecutor``, callback groups are honoured and an exception from a callback comes
out of ``spin_once``.

:class:`DirectMultiThreadedExecutor` is rclpy's ``MultiThreadedExecutor`` for nodes whose
callbacks may block (a tree tick, an inspection): it calls on its spinning thread only what cannot
block, the node's ``/clock`` subscription (rclpy's time source) and subscriptions in a
:class:`QuickCallbackGroup` (a topic cache storing the newest message); everything else goes to its
worker threads as before. An exception from such a call is logged, as rclpy's multi-threaded
executor keeps a callback's exception to itself.

They replace rclpy's ``_make_handler`` (and the multi-threaded one its ``_spin_once_impl``) and
read entity attributes rclpy itself uses, as rclpy 7.1 (Jazzy, pinned in
requirements/ros.txt) has them; tests/tlt_common/ros/test_direct_executor.py holds them to that.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from rclpy._rclpy_pybind11 import InvalidHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
)
from rclpy.subscription import Subscription
from rclpy.time_source import TimeSource
from rclpy.timer import Timer


class QuickCallbackGroup(MutuallyExclusiveCallbackGroup):
    """Subscriptions whose callbacks only take a message in and never block (storing the newest
    message). :class:`DirectMultiThreadedExecutor` calls them on its spinning thread; any other
    executor runs them one at a time, as the group they replace (a node's default) did."""


def _call_timer(timer: Timer) -> None:
    try:
        with timer.handle:
            timer.handle.call_timer()
    except InvalidHandle:  # destroyed since it was found ready
        return
    timer.callback()


def _call_subscription(sub: Subscription) -> None:
    try:
        with sub.handle:
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
    except InvalidHandle:
        return
    if taken is None:  # nothing there after all (another reader took it)
        return
    if sub._callback_type is Subscription.CallbackType.MessageOnly:
        sub.callback(taken[0])
    else:
        sub.callback(*taken)


class _DirectCall:
    """What the executor's ``spin_once`` runs for a directly called entity: ``handler()``, then
    ``handler.exception()`` and ``handler.result()``, as it does with a finished ``Task``."""

    __slots__ = ("_call", "_entity", "_error", "_executor", "node")

    def __init__(self, executor: Any, entity: Any, node: Any, call: Callable[[Any], None]) -> None:
        self._executor, self._entity, self.node, self._call = executor, entity, node, call
        self._error: BaseException | None = None

    def __call__(self) -> None:
        entity, executor = self._entity, self._executor
        group = entity.callback_group
        if executor._is_shutdown or not group.beginning_execution(entity):
            entity._executor_event = False
            return
        try:
            with executor._work_tracker:  # counted as running work, as rclpy's handlers are
                # No longer in the executor's hands: the next wait set may hold it again.
                entity._executor_event = False
                self._call(entity)
        except Exception as exc:
            self._error = exc
        finally:
            group.ending_execution(entity)

    def exception(self) -> BaseException | None:
        return self._error

    def result(self) -> None:
        if self._error is not None:
            raise self._error


class DirectExecutor(SingleThreadedExecutor):
    """``SingleThreadedExecutor`` that calls plain timer and subscription callbacks directly."""

    def _make_handler(self, entity: Any, node: Any, take_from_wait_list: Callable) -> Any:
        call: Callable[[Any], None] | None = None
        if take_from_wait_list == self._take_timer:
            call = _call_timer
        elif take_from_wait_list == self._take_subscription:
            call = _call_subscription
        if call is None or inspect.iscoroutinefunction(entity.callback):
            return super()._make_handler(entity, node, take_from_wait_list)
        entity._executor_event = True  # out of the wait sets until the call has taken it
        return _DirectCall(self, entity, node, call)


def _quick(entity: Any) -> bool:
    return isinstance(entity.callback_group, QuickCallbackGroup) or (
        getattr(entity.callback, "__func__", None) is TimeSource.clock_callback
    )


class DirectMultiThreadedExecutor(MultiThreadedExecutor):
    """``MultiThreadedExecutor`` that calls quick subscriptions (``/clock``, a
    :class:`QuickCallbackGroup`) on its spinning thread instead of handing them to a worker."""

    def _make_handler(self, entity: Any, node: Any, take_from_wait_list: Callable) -> Any:
        if (
            take_from_wait_list == self._take_subscription
            and _quick(entity)
            and not inspect.iscoroutinefunction(entity.callback)
        ):
            entity._executor_event = True
            return _DirectCall(self, entity, node, _call_subscription)
        return super()._make_handler(entity, node, take_from_wait_list)

    def _spin_once_impl(
        self, timeout_sec: Any = None, wait_condition: Callable[[], bool] = lambda: False
    ) -> None:
        entity: Any  # any waitable; rclpy annotates it with a TypeVar bound to nothing
        try:
            handler, entity, _node = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException, ConditionReachedException):
            return
        if isinstance(handler, _DirectCall):
            handler()
            if handler.exception() is not None:
                handler.node.get_logger().error(
                    f"callback on '{entity.topic_name}' failed: {handler.exception()!r}"
                )
            return
        self._futures.append(self._executor.submit(handler))
        for future in [f for f in self._futures if f.done()]:
            self._futures.remove(future)
            future.result()  # an error of the worker itself, not of the callback (kept in its task)


__all__ = ["DirectExecutor", "DirectMultiThreadedExecutor", "QuickCallbackGroup"]
