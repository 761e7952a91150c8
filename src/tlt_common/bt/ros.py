"""Behaviours that talk to ROS without ever blocking a tick (paper §V.C.1).

Each behaviour sends its request asynchronously, polls the returned futures in ``update()`` and
cancels what it started in ``terminate()`` when a parent pre-empts it (new status INVALID). The
node they use must be spun by someone else (an executor in a thread, or ``spin_once`` between
ticks): a behaviour never spins, sleeps or waits.

Timeouts are measured on ``clock`` (seconds, a callable); by default the node's clock, which is
ROS time, so a twin publishing ``/clock`` faster than real time shortens them accordingly.

Whether a server is there is read through :mod:`tlt_common.bt.server_readiness`: a behaviour waits
on an answer up to a quarter second old and sends a goal, or fails for want of a server, only on a
fresh one.
"""

from __future__ import annotations

import time
import weakref
from collections.abc import Callable
from typing import Any

import py_trees
from action_msgs.msg import GoalStatus
from py_trees.common import Status
from rclpy.action import ActionClient
from rclpy.clock import ClockChange, JumpThreshold, ROSClock, TimeJump
from rclpy.node import Node
from rclpy.qos import QoSProfile

from tlt_common.action_client import SerialisedActionClient
from tlt_common.bt.nodes import Action, Condition
from tlt_common.bt.server_readiness import readiness_of
from tlt_common.bt.status_codec import DEFAULT_MAX_STATUS_BYTES, TreeShape, encode
from tlt_common.direct_executor import QuickCallbackGroup

Clock = Callable[[], float]


class RosSeconds:
    """Seconds on an rclpy ROS clock, read cheaply while no simulated time is active.

    rclpy's ``Clock.now()`` builds a ``Time`` on every call (several microseconds, as much as a
    whole bare behaviour tick). While ROS time is not overridden by ``/clock``, rcl answers it from
    the system clock (CLOCK_REALTIME), which ``time.time_ns()`` reads directly. A jump callback on
    clock change (the public rclpy way to hear of it) says when simulated time is switched on or
    off; from then on ``Clock.now()`` is used again.
    """

    def __init__(self, clock: ROSClock) -> None:
        self._clock_now = clock.now
        # The callback holds only this cell, not self: the clock keeps its jump callbacks alive.
        self._simulated = simulated = [False]

        def on_jump(jump: TimeJump) -> None:
            if jump.clock_change == ClockChange.ROS_TIME_ACTIVATED:
                simulated[0] = True
            elif jump.clock_change == ClockChange.ROS_TIME_DEACTIVATED:
                simulated[0] = False

        handle = clock.create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=None, on_clock_change=True), post_callback=on_jump
        )
        # The clock holds the handle and the handle the clock: unregister once nobody reads these
        # seconds any more, so neither is kept for the life of the process.
        finalizer = weakref.finalize(self, _unregister, handle)
        finalizer.atexit = False
        # Read after registering, so a switch in between is not missed.
        simulated[0] = clock.ros_time_is_active

    @property
    def simulated(self) -> bool:
        """Whether ROS time is currently overridden (``use_sim_time`` and ``/clock``)."""
        return self._simulated[0]

    def __call__(self) -> float:
        if self._simulated[0]:
            return self._clock_now().nanoseconds * 1e-9
        return time.time_ns() * 1e-9


def _unregister(handle: Any) -> None:
    try:
        handle.unregister()
    except Exception:  # the clock's handle is already gone: nothing left to unregister
        pass


def node_clock(node: Node) -> Clock:
    """Seconds on ``node``'s clock (ROS time; simulated time when use_sim_time is set)."""
    clock = node.get_clock()
    if isinstance(clock, ROSClock):
        return RosSeconds(clock)
    return lambda: clock.now().nanoseconds * 1e-9


def _clients_of(node: Node) -> dict[tuple[str, str], Any]:
    # Kept on the node itself: as values of a module-level WeakKeyDictionary the clients (which
    # hold their node) kept every node, and with it its context, alive for the life of the process.
    clients = getattr(node, "_tlt_shared_clients", None)
    if clients is None:
        clients = {}
        # An attribute of the project's own on rclpy's Node, which does not declare it.
        node._tlt_shared_clients = clients  # type: ignore[attr-defined]
    return clients


def shared_action_client(node: Node, action_type: Any, action_name: str) -> ActionClient:
    """One ActionClient per (node, action name): a CRS tree has a goal behaviour per member, and
    a client each would multiply DDS entities and discovery traffic for nothing."""
    clients = _clients_of(node)
    key = ("action", action_name)
    if key not in clients:
        clients[key] = SerialisedActionClient(node, action_type, action_name)
    return clients[key]


def shared_service_client(node: Node, srv_type: Any, srv_name: str) -> Any:
    """One service client per (node, service name), for the same reason."""
    clients = _clients_of(node)
    key = ("service", srv_name)
    if key not in clients:
        clients[key] = node.create_client(srv_type, srv_name)
    return clients[key]


def default_feedback_text(feedback: Any) -> str:
    """``step`` (and ``progress`` as a percentage) when the feedback has them, else its repr."""
    step = getattr(feedback, "step", None)
    if step is None:
        return repr(feedback)
    progress = getattr(feedback, "progress", None)
    return f"{step} ({progress * 100:.0f}%)" if progress is not None else str(step)


def default_result_ok(result: Any) -> tuple[bool, str]:
    """A result with ``success`` or ``accepted`` and ``reason`` fields (the TLT interfaces) decides by
    them; any other result counts as success."""
    for field in ("success", "accepted"):
        if hasattr(result, field):
            return bool(getattr(result, field)), str(getattr(result, "reason", "") or "")
    return True, ""


_GOAL_STATUS_TEXT = {
    GoalStatus.STATUS_ABORTED: "aborted by the server",
    GoalStatus.STATUS_CANCELED: "canceled by the server",
    GoalStatus.STATUS_UNKNOWN: "ended in an unknown state",
}


class ActionGoal(Action):
    """Send one goal to a ROS 2 action server and follow it to its result.

    Reads: whatever ``goal`` (a callable) reads when it builds the goal at the start of a run.
    Writes: ``result_key`` (the result message) when given, on SUCCESS and on FAILURE from a result.
    ``feedback_message`` shows the server's latest feedback, or the reason of a failure.

    RUNNING: waiting for the server (up to ``server_timeout``), for acceptance, or for the result
    (up to ``result_timeout`` after acceptance).
    SUCCESS: the goal SUCCEEDED and ``result_ok(result)`` says it succeeded.
    FAILURE: server not available in time, goal rejected, result timeout (the goal is canceled),
    aborted or canceled by the server, or ``result_ok`` says it failed (its reason is reported).
    Pre-empted (terminate with INVALID): a goal in flight is canceled server-side.
    """

    def __init__(
        self,
        name: str,
        node: Node,
        action_type: Any,
        action_name: str,
        goal: Callable[[], Any] | Any,
        *,
        server_timeout: float = 5.0,
        result_timeout: float = 600.0,
        feedback_text: Callable[[Any], str] = default_feedback_text,
        result_ok: Callable[[Any], tuple[bool, str]] = default_result_ok,
        on_result: Callable[[Any, bool, str], None] | None = None,
        result_key: str | None = None,
        clock: Clock | None = None,
        client: ActionClient | None = None,
    ) -> None:
        super().__init__(name)
        self.node = node
        self.action_name = action_name
        self.client = client or shared_action_client(node, action_type, action_name)
        self._readiness = readiness_of(self.client)
        self._goal = goal
        self.server_timeout = server_timeout
        self.result_timeout = result_timeout
        self.feedback_text = feedback_text
        self.result_ok = result_ok
        self.on_result = on_result
        self.result_key = result_key
        self.clock = clock or node_clock(node)
        self.last_result: Any = None
        self._bb = None
        if result_key:
            self._bb = self.attach_blackboard_client(name=name)
            self._bb.register_key(key=result_key, access=py_trees.common.Access.WRITE)
        self._reset()

    def _reset(self) -> None:
        self._started = 0.0
        self._accepted_at = 0.0
        self._send_future = None
        self._goal_handle = None
        self._result_future = None
        self._feedback: Any = None

    def initialise(self) -> None:
        self._reset()
        self._started = self.clock()
        self.last_result = None
        self.feedback_message = f"waiting for server '{self.action_name}'"

    def _on_feedback(self, message: Any) -> None:
        # Called on the executor's thread; a single assignment is atomic for the tick thread.
        self._feedback = message.feedback

    def update(self) -> Status:
        now = self.clock()
        if self._send_future is None:
            up = self._readiness.wait(now - self._started, self.server_timeout)
            if up is None:
                return Status.RUNNING
            if not up:
                return self.fail(
                    f"action server '{self.action_name}' not available after {self.server_timeout:g} s"
                )
            try:
                goal = self._goal() if callable(self._goal) else self._goal
            except Exception as exc:
                return self.fail(f"cannot build goal for '{self.action_name}': {exc}")
            self._send_future = self.client.send_goal_async(goal, feedback_callback=self._on_feedback)
            self._started = now
            self.feedback_message = f"goal sent to '{self.action_name}'"
            return Status.RUNNING
        if self._goal_handle is None:
            if not self._send_future.done():
                if now - self._started > self.server_timeout:
                    return self.fail(
                        f"'{self.action_name}' did not answer the goal in {self.server_timeout:g} s"
                    )
                return Status.RUNNING
            handle = self._send_future.result()
            if handle is None or not handle.accepted:
                return self.fail(f"goal rejected by '{self.action_name}'")
            self._goal_handle = handle
            self._accepted_at = now
            self._result_future = handle.get_result_async()
            self.feedback_message = f"goal accepted by '{self.action_name}'"
        if not self._result_future.done():
            if self._feedback is not None:
                self.feedback_message = self.feedback_text(self._feedback)
            if now - self._accepted_at > self.result_timeout:
                self._cancel()
                return self.fail(f"no result from '{self.action_name}' within {self.result_timeout:g} s")
            return Status.RUNNING
        response = self._result_future.result()
        self._goal_handle = None
        status = response.status
        result = response.result
        self.last_result = result
        if self._bb is not None:
            self._bb.set(self.result_key, result)
        if status != GoalStatus.STATUS_SUCCEEDED:
            reason = _GOAL_STATUS_TEXT.get(status, f"ended with goal status {status}")
            _, detail = self.result_ok(result)
            ok, reason = False, f"'{self.action_name}' {reason}" + (f": {detail}" if detail else "")
        else:
            ok, detail = self.result_ok(result)
            reason = "" if ok else f"'{self.action_name}' failed: {detail or 'no reason given'}"
        if self.on_result is not None:
            try:
                self.on_result(result, ok, reason)
            except Exception as exc:
                return self.fail(f"'{self.action_name}' result could not be recorded: {exc}")
        if not ok:
            return self.fail(reason)
        self.feedback_message = f"'{self.action_name}' succeeded"
        return Status.SUCCESS

    def _cancel(self) -> None:
        handle = self._goal_handle
        if handle is None and self._send_future is not None and self._send_future.done():
            # Accepted between two ticks: the handle exists but update() has not picked it up yet.
            accepted = self._send_future.result()
            handle = accepted if accepted is not None and accepted.accepted else None
            if handle is None:
                self._send_future = None
        if handle is not None:
            handle.cancel_goal_async()
        elif self._send_future is not None and not self._send_future.done():
            # Accepted later: cancel as soon as the handle exists, so no goal is left behind.
            def cancel_when_accepted(future: Any) -> None:
                accepted = future.result()
                if accepted is not None and accepted.accepted:
                    accepted.cancel_goal_async()

            self._send_future.add_done_callback(cancel_when_accepted)
        self._goal_handle = None
        self._send_future = None

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and (self._goal_handle is not None or self._send_future is not None):
            self._cancel()
            self.feedback_message = f"pre-empted: goal on '{self.action_name}' canceled"
        self._reset()


class ServiceCall(Action):
    """Call a ROS 2 service once per run and wait (by polling) for its response.

    Reads: whatever ``request`` (a callable) reads when it builds the request.
    Writes: ``response_key`` (the response message) when given.
    RUNNING: waiting for the service (up to ``service_timeout``) or the response (up to ``timeout``).
    SUCCESS: a response came and ``response_ok(response)`` says it is good.
    FAILURE: service not available, no response in time (the request is dropped), the request
    could not be built, or ``response_ok`` says it failed (its reason is reported).
    """

    def __init__(
        self,
        name: str,
        node: Node,
        srv_type: Any,
        srv_name: str,
        request: Callable[[], Any] | Any,
        *,
        service_timeout: float = 5.0,
        timeout: float = 30.0,
        response_ok: Callable[[Any], tuple[bool, str]] = default_result_ok,
        response_key: str | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(name)
        self.srv_name = srv_name
        self.client = shared_service_client(node, srv_type, srv_name)
        self._readiness = readiness_of(self.client)
        self._request = request
        self.service_timeout = service_timeout
        self.timeout = timeout
        self.response_ok = response_ok
        self.response_key = response_key
        self.clock = clock or node_clock(node)
        self.last_response: Any = None
        self._bb = None
        if response_key:
            self._bb = self.attach_blackboard_client(name=name)
            self._bb.register_key(key=response_key, access=py_trees.common.Access.WRITE)
        self._future = None
        self._started = 0.0

    def initialise(self) -> None:
        self._future = None
        self._started = self.clock()
        self.last_response = None
        self.feedback_message = f"waiting for service '{self.srv_name}'"

    def update(self) -> Status:
        now = self.clock()
        if self._future is None:
            up = self._readiness.wait(now - self._started, self.service_timeout)
            if up is None:
                return Status.RUNNING
            if not up:
                return self.fail(f"service '{self.srv_name}' not available after {self.service_timeout:g} s")
            try:
                request = self._request() if callable(self._request) else self._request
            except Exception as exc:
                return self.fail(f"cannot build request for '{self.srv_name}': {exc}")
            self._future = self.client.call_async(request)
            self._started = now
            self.feedback_message = f"request sent to '{self.srv_name}'"
            return Status.RUNNING
        if not self._future.done():
            if now - self._started > self.timeout:
                self._drop()
                return self.fail(f"no response from '{self.srv_name}' within {self.timeout:g} s")
            return Status.RUNNING
        response = self._future.result()
        self._future = None
        self.last_response = response
        if self._bb is not None:
            self._bb.set(self.response_key, response)
        ok, reason = self.response_ok(response)
        if not ok:
            return self.fail(f"'{self.srv_name}' refused: {reason or 'no reason given'}")
        self.feedback_message = f"'{self.srv_name}' answered"
        return Status.SUCCESS

    def postpone(self, seconds: float) -> None:
        """Leave ``seconds`` (a pause it was left running through) out of its time limits."""
        self._started += seconds

    def _drop(self) -> None:
        if self._future is not None:
            self.client.remove_pending_request(self._future)
            self._future.cancel()
            self._future = None

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self._drop()
        self._future = None


class TopicCache:
    """Latest message and its arrival time (on ``clock``, and on the wall clock for
    :mod:`tlt_common.topic_silence_watch`) per topic, one subscription per topic.

    Several behaviours reading one topic share its subscription. Callbacks run on the executor's
    thread; readers get a (message, stamp) pair replaced atomically.
    """

    def __init__(self, node: Node, clock: Clock | None = None) -> None:
        self.node = node
        self.clock = clock or node_clock(node)
        self._latest: dict[str, tuple[Any, float] | None] = {}
        self._heard: dict[str, float] = {}  # time.monotonic() of the newest message, per topic
        self._subscriptions: dict[str, Any] = {}
        self._group = QuickCallbackGroup()  # a store never blocks: spun on the executor's own thread

    def watch(self, topic: str, msg_type: Any, qos: QoSProfile | int = 10) -> None:
        """Subscribe to ``topic`` once; later calls for the same topic are no-ops."""
        if topic in self._subscriptions:
            return
        self._latest[topic] = None

        def store(msg: Any, topic: str = topic) -> None:
            self._latest[topic] = (msg, self.clock())
            self._heard[topic] = time.monotonic()

        self._subscriptions[topic] = self.node.create_subscription(
            msg_type, topic, store, qos, callback_group=self._group
        )

    def latest(self, topic: str) -> tuple[Any, float] | None:
        """(message, arrival time) of the newest message on ``topic``, or None before the first."""
        return self._latest.get(topic)

    def topics(self) -> list[str]:
        """The topics watched, in the order they were first watched."""
        return list(self._subscriptions)

    def heard(self, topic: str) -> float | None:
        """``time.monotonic()`` when the newest message on ``topic`` arrived; None before the first."""
        return self._heard.get(topic)

    def publishers(self, topic: str) -> tuple[int, int]:
        """(publishers of ``topic`` this process's graph knows, those matched to its subscription)."""
        return self.node.count_publishers(topic), self._subscriptions[topic].get_publisher_count()

    def age(self, topic: str) -> float | None:
        """Seconds since the newest message on ``topic`` arrived; None before the first."""
        entry = self._latest.get(topic)
        return None if entry is None else self.clock() - entry[1]


class TopicCondition(Condition):
    """``predicate(latest message)`` on ``topic``.

    Reads: the topic (through ``cache``). Writes: nothing.
    SUCCESS when a message no older than ``max_age`` seconds exists and the predicate holds.
    FAILURE when the predicate is false, or the latest message is absent or stale (feedback says
    which). Never RUNNING.
    """

    def __init__(
        self,
        name: str,
        cache: TopicCache,
        topic: str,
        msg_type: Any,
        predicate: Callable[[Any], bool],
        *,
        max_age: float = 1.0,
        qos: QoSProfile | int = 10,
    ) -> None:
        super().__init__(name)
        self.cache = cache
        self.topic = topic
        self.predicate = predicate
        self.max_age = max_age
        cache.watch(topic, msg_type, qos)

    def evaluate(self) -> bool:
        entry = self.cache.latest(self.topic)
        if entry is None:
            self.feedback_message = f"no message on '{self.topic}' yet"
            return False
        msg, stamp = entry
        age = self.cache.clock() - stamp
        if age > self.max_age:
            self.feedback_message = (
                f"'{self.topic}' stale: last message {age:.2f} s old (max {self.max_age:g} s)"
            )
            return False
        ok = bool(self.predicate(msg))
        self.feedback_message = f"'{self.topic}': {'true' if ok else 'false'}"
        return ok


class TopicData(Action):
    """Copy the latest message on ``topic`` (or ``transform(message)``) to blackboard key ``key``.

    Reads: the topic (through ``cache``). Writes: ``key``.
    SUCCESS when a message no older than ``max_age`` seconds exists (it is written).
    RUNNING while none has arrived yet, for at most ``wait`` seconds from the start of the run.
    FAILURE when none arrived in ``wait`` seconds, or the latest is stale (nothing is written).
    """

    def __init__(
        self,
        name: str,
        cache: TopicCache,
        topic: str,
        msg_type: Any,
        key: str,
        *,
        transform: Callable[[Any], Any] | None = None,
        max_age: float = 1.0,
        wait: float = 0.0,
        qos: QoSProfile | int = 10,
    ) -> None:
        super().__init__(name)
        self.cache = cache
        self.topic = topic
        self.key = key
        self.transform = transform
        self.max_age = max_age
        self.wait = wait
        self._started = 0.0
        cache.watch(topic, msg_type, qos)
        self._bb = self.attach_blackboard_client(name=name)
        self._bb.register_key(key=key, access=py_trees.common.Access.WRITE)

    def initialise(self) -> None:
        self._started = self.cache.clock()

    def update(self) -> Status:
        entry = self.cache.latest(self.topic)
        now = self.cache.clock()
        if entry is None:
            if now - self._started < self.wait:
                self.feedback_message = f"waiting for '{self.topic}'"
                return Status.RUNNING
            return self.fail(f"no message on '{self.topic}'")
        msg, stamp = entry
        if now - stamp > self.max_age:
            return self.fail(
                f"'{self.topic}' stale: last message {now - stamp:.2f} s old (max {self.max_age:g} s)"
            )
        try:
            value = self.transform(msg) if self.transform is not None else msg
        except Exception as exc:
            return self.fail(f"cannot read '{self.topic}': {exc}")
        self._bb.set(self.key, value)
        self.feedback_message = f"{self.key} <- '{self.topic}'"
        return Status.SUCCESS


class TreeStatusPublisher:
    """Publishes a tree's encoded status as ``tlt_interfaces/TreeStatus`` messages (one per part).

    With ``period_s`` a status goes out at most once per period, after the first tick due (on the
    node's clock): the tree ticks faster than anyone watches it, and each status costs an encoding
    here and a message at every subscriber. ``publish_due(shape, tick_count)`` is that, for a tree
    ticked by hand; ``attach(tree)`` calls it after every tick of a
    ``py_trees.trees.BehaviourTree``, with tick count ``tree.count + 1`` (the first tick is 1).
    Call ``refresh()`` after changing the attached tree's structure so the shape hash and node list
    follow it.
    """

    def __init__(
        self,
        node: Node,
        agent: str,
        *,
        topic: str = "tree_status",
        period_s: float = 0.0,
        max_status_bytes: int = DEFAULT_MAX_STATUS_BYTES,
        qos: QoSProfile | int = 10,
    ) -> None:
        from tlt_interfaces.msg import TreeStatus

        self.node = node
        self.agent = agent
        self.period_s = period_s
        self.max_status_bytes = max_status_bytes
        self.publisher = node.create_publisher(TreeStatus, topic, qos)
        self._shape: TreeShape | None = None
        self._stale = False
        self._root: py_trees.behaviour.Behaviour | None = None
        self._seconds = node_clock(node)
        self._due = float("-inf")

    def publish(self, shape: TreeShape, tick_count: int) -> int:
        """Publish every part of ``shape``'s current status; return how many were sent."""
        stamp = self.node.get_clock().now().to_msg()
        parts = encode(shape, agent=self.agent, tick_count=tick_count, max_status_bytes=self.max_status_bytes)
        for part in parts:
            msg = part.to_msg()
            msg.header.stamp = stamp
            self.publisher.publish(msg)
        return len(parts)

    def publish_due(self, shape: TreeShape, tick_count: int) -> int:
        """:meth:`publish` when a period has passed since the last one, else nothing (0)."""
        return self.publish(shape, tick_count) if self._take_due() else 0

    def _take_due(self) -> bool:
        now = self._seconds()
        # A clock that went back (sim time restarted) starts the period again.
        if now < self._due and self._due - now <= self.period_s:
            return False
        self._due = now + self.period_s
        return True

    @property
    def shape(self) -> TreeShape | None:
        """The attached tree's shape (None before ``attach``)."""
        if self._stale and self._root is not None:
            self._shape = TreeShape.of(self._root)
            self._stale = False
        return self._shape

    def refresh(self) -> None:
        # Worked out when next asked for, not here: the ARS installs a request's branch on the
        # tick that answers the CRS, and walking a hundred behaviours is a millisecond of it.
        self._stale = True

    def attach(self, tree: py_trees.trees.BehaviourTree) -> None:
        """Publish (when due) after every tick of ``tree``."""
        self._root = tree.root
        self.refresh()

        def publish_after_tick(t: py_trees.trees.BehaviourTree) -> None:
            if self._take_due():
                shape = self.shape
                assert shape is not None  # the root was set above
                self.publish(shape, t.count + 1)

        tree.add_post_tick_handler(publish_after_tick)


__all__ = [
    "ActionGoal",
    "RosSeconds",
    "ServiceCall",
    "TopicCache",
    "TopicCondition",
    "TopicData",
    "TreeStatusPublisher",
    "default_feedback_text",
    "default_result_ok",
    "node_clock",
    "shared_action_client",
    "shared_service_client",
]
