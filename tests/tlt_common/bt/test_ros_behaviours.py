"""ROS behaviours against real rclpy action and service servers of tlt_interfaces.

The servers and the behaviours' node are spun by a MultiThreadedExecutor in a thread, as in the
CRS; the test thread ticks. Timeouts run on an injected clock advanced by the test, so they are
exact on a loaded machine; waiting for DDS uses bounded polls.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import py_trees
import pytest
import rclpy
from py_trees.common import Status
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from tlt_interfaces.action import AddMember
from tlt_interfaces.msg import GripperState
from tlt_interfaces.srv import SetBlackboardValue

from tlt_common.bt.ros import ActionGoal, ServiceCall, TopicCache, TopicCondition, TopicData
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.spin_loop import spin


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def wait_for(
    predicate: Callable[[], bool], timeout: float = 10.0, tick: Callable[[], None] | None = None
) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError("condition not reached in time")
        if tick is not None:
            tick()
        time.sleep(0.01)


class AddMemberServer:
    """A real AddMember action server whose behaviour each test chooses through ``mode``."""

    def __init__(self, node, name: str = "ars_x/add_member") -> None:
        self.mode = "succeed"
        self.release = threading.Event()  # lets a "hold" goal finish
        self.canceled: list[str] = []
        self.received: list[str] = []
        group = ReentrantCallbackGroup()
        self.server = ActionServer(
            node,
            AddMember,
            name,
            execute_callback=self.execute,
            goal_callback=self.on_goal,
            cancel_callback=lambda _req: CancelResponse.ACCEPT,
            callback_group=group,
        )

    def on_goal(self, goal) -> GoalResponse:
        self.received.append(goal.member_id)
        return GoalResponse.REJECT if self.mode == "reject" else GoalResponse.ACCEPT

    def execute(self, goal_handle):
        result = AddMember.Result()
        deadline = time.monotonic() + 20.0
        step = 0
        while time.monotonic() < deadline:
            if goal_handle.is_cancel_requested:
                self.canceled.append(goal_handle.request.member_id)
                goal_handle.canceled()
                result.reason = "canceled"
                return result
            feedback = AddMember.Feedback(step=f"Grab Member/step {step}", progress=min(1.0, step / 4))
            goal_handle.publish_feedback(feedback)
            step += 1
            if self.mode != "hold" and step >= 4:
                break
            if self.mode == "hold" and self.release.is_set():
                break
            time.sleep(0.02)
        if self.mode == "abort":
            goal_handle.abort()
            result.reason = "arm in protective stop"
            return result
        goal_handle.succeed()
        result.success = self.mode != "fail"
        result.reason = "" if result.success else "inspection failed twice"
        return result


@pytest.fixture(scope="module")
def ros():
    context = rclpy.Context()
    rclpy.init(context=context)
    server_node = rclpy.create_node("test_servers", context=context)
    client_node = rclpy.create_node("test_behaviours", context=context)
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    executor.add_node(server_node)
    executor.add_node(client_node)
    # Executor.spin goes on building wait sets after shutdown() returns: the nodes destroyed under
    # it failed the thread with InvalidHandle (a warning in clean-clone runs). This loop ends, and
    # is joined, before anything is destroyed.
    stop = threading.Event()
    thread = threading.Thread(target=spin, args=(executor, context, stop.is_set), daemon=True)
    thread.start()
    yield server_node, client_node
    stop.set()
    thread.join(timeout=5.0)
    assert not thread.is_alive(), "the spin thread did not end"
    executor.shutdown(timeout_sec=2.0)
    destroy_node(server_node)
    destroy_node(client_node)
    rclpy.shutdown(context=context)


@pytest.fixture(scope="module")
def action_server(ros):
    server_node, _ = ros
    return AddMemberServer(server_node)


@pytest.fixture(autouse=True)
def reset(request):
    py_trees.blackboard.Blackboard.clear()
    if "action_server" in request.fixturenames:
        server = request.getfixturevalue("action_server")
        server.mode = "succeed"
        server.release.clear()
        server.canceled.clear()
    yield


def goal(member_id: str = "bay1/vertical/x0_y1") -> AddMember.Goal:
    return AddMember.Goal(
        kind=AddMember.Goal.KIND_VERTICAL, bay=1, member_id=member_id, position="x0_y1", ars="ars_x"
    )


def run_to_end(behaviour, timeout: float = 10.0) -> list[str]:
    """Tick until not RUNNING; return the feedback messages seen while running."""
    seen = []
    deadline = time.monotonic() + timeout
    behaviour.tick_once()
    while behaviour.status is Status.RUNNING:
        seen.append(behaviour.feedback_message)
        assert time.monotonic() < deadline, "behaviour still RUNNING"
        time.sleep(0.01)
        behaviour.tick_once()
    return seen


def test_action_goal_succeeds_and_reports_feedback(ros, action_server):
    _, node = ros
    results = []
    behaviour = ActionGoal(
        "Add Far Vertical",
        node,
        AddMember,
        "ars_x/add_member",
        lambda: goal("bay1/vertical/x0_y1"),
        result_key="add_member_result",
        on_result=lambda result, ok, reason: results.append((ok, reason)),
    )
    seen = run_to_end(behaviour)
    assert behaviour.status is Status.SUCCESS
    assert any(text.startswith("Grab Member/step") for text in seen), seen
    assert results == [(True, "")]
    assert py_trees.blackboard.Blackboard.get("/add_member_result").success is True


def test_action_goal_failure_result_carries_reason(ros, action_server):
    _, node = ros
    action_server.mode = "fail"
    behaviour = ActionGoal("add", node, AddMember, "ars_x/add_member", goal())
    run_to_end(behaviour)
    assert behaviour.status is Status.FAILURE
    assert "inspection failed twice" in behaviour.feedback_message


def test_action_goal_aborted(ros, action_server):
    _, node = ros
    action_server.mode = "abort"
    behaviour = ActionGoal("add", node, AddMember, "ars_x/add_member", goal())
    run_to_end(behaviour)
    assert behaviour.status is Status.FAILURE
    assert "aborted" in behaviour.feedback_message
    assert "protective stop" in behaviour.feedback_message


def test_action_goal_rejected(ros, action_server):
    _, node = ros
    action_server.mode = "reject"
    behaviour = ActionGoal("add", node, AddMember, "ars_x/add_member", goal())
    run_to_end(behaviour)
    assert behaviour.status is Status.FAILURE
    assert "rejected" in behaviour.feedback_message


def test_ticks_do_not_wait_on_the_server(ros, action_server):
    """The server holds the goal until released: every tick meanwhile returns RUNNING at once."""
    _, node = ros
    action_server.mode = "hold"
    behaviour = ActionGoal("add", node, AddMember, "ars_x/add_member", goal())
    wait_for(lambda: "Grab Member" in behaviour.feedback_message, tick=behaviour.tick_once)
    for _ in range(20):
        behaviour.tick_once()  # would hang here (and hit the test timeout) if a tick waited
        assert behaviour.status is Status.RUNNING
    action_server.release.set()
    run_to_end(behaviour)
    assert behaviour.status is Status.SUCCESS


def test_preemption_cancels_goal_server_side(ros, action_server):
    _, node = ros
    action_server.mode = "hold"
    behaviour = ActionGoal("add", node, AddMember, "ars_x/add_member", goal("bay2/diagonal/face_x0"))
    stop = py_trees.behaviours.Failure("no pause")
    root = py_trees.composites.Selector("root", memory=False, children=[stop, behaviour])
    wait_for(lambda: "Grab Member" in behaviour.feedback_message, tick=root.tick_once)
    # A higher-priority branch now succeeds: the running goal is pre-empted.
    root.remove_child(stop)
    root.insert_child(py_trees.behaviours.Success("pause"), 0)
    root.tick_once()
    assert behaviour.status is Status.INVALID
    wait_for(lambda: "bay2/diagonal/face_x0" in action_server.canceled)


def test_server_not_available_times_out(ros):
    _, node = ros
    clock = FakeClock()
    behaviour = ActionGoal(
        "add", node, AddMember, "nobody/add_member", goal(), server_timeout=2.0, clock=clock
    )
    behaviour.tick_once()
    assert behaviour.status is Status.RUNNING
    clock.now += 2.5
    behaviour.tick_once()
    assert behaviour.status is Status.FAILURE
    assert "not available after 2 s" in behaviour.feedback_message


def test_result_timeout_fails_and_cancels(ros, action_server):
    _, node = ros
    action_server.mode = "hold"
    clock = FakeClock()
    behaviour = ActionGoal(
        "add",
        node,
        AddMember,
        "ars_x/add_member",
        goal("bay3/vertical/x1_y0"),
        result_timeout=30.0,
        clock=clock,
    )
    wait_for(lambda: "Grab Member" in behaviour.feedback_message, tick=behaviour.tick_once)
    clock.now += 31.0
    behaviour.tick_once()
    assert behaviour.status is Status.FAILURE
    assert "no result" in behaviour.feedback_message
    wait_for(lambda: "bay3/vertical/x1_y0" in action_server.canceled)


def test_goal_builder_error_fails_cleanly(ros, action_server):
    _, node = ros

    def broken():
        raise KeyError("current_bay")

    behaviour = ActionGoal("add", node, AddMember, "ars_x/add_member", broken)
    run_to_end(behaviour)
    assert behaviour.status is Status.FAILURE
    assert "cannot build goal" in behaviour.feedback_message


class BlackboardService:
    def __init__(self, node, name: str = "crs/set_blackboard_value") -> None:
        self.hold = threading.Event()
        self.service = node.create_service(
            SetBlackboardValue, name, self.handle, callback_group=ReentrantCallbackGroup()
        )

    def handle(self, request, response):
        self.hold.wait(timeout=10.0)
        response.accepted = request.key == "lifter_speed"
        response.reason = "" if response.accepted else f"unknown key '{request.key}'"
        return response


@pytest.fixture(scope="module")
def service(ros):
    server_node, _ = ros
    return BlackboardService(server_node)


def request(key: str) -> SetBlackboardValue.Request:
    return SetBlackboardValue.Request(key=key)


def test_service_call_success_and_response_key(ros, service):
    _, node = ros
    service.hold.set()
    call = ServiceCall(
        "set",
        node,
        SetBlackboardValue,
        "crs/set_blackboard_value",
        lambda: request("lifter_speed"),
        response_key="set_response",
    )
    run_to_end(call)
    assert call.status is Status.SUCCESS
    assert py_trees.blackboard.Blackboard.get("/set_response").accepted is True


def test_service_call_refused(ros, service):
    _, node = ros
    service.hold.set()
    call = ServiceCall("set", node, SetBlackboardValue, "crs/set_blackboard_value", request("nope"))
    run_to_end(call)
    assert call.status is Status.FAILURE
    assert "unknown key 'nope'" in call.feedback_message


def test_service_response_timeout(ros, service):
    _, node = ros
    service.hold.clear()
    clock = FakeClock()
    call = ServiceCall(
        "set",
        node,
        SetBlackboardValue,
        "crs/set_blackboard_value",
        request("lifter_speed"),
        timeout=5.0,
        clock=clock,
    )
    wait_for(lambda: call.feedback_message.startswith("request sent"), tick=call.tick_once)
    for _ in range(5):
        call.tick_once()
        assert call.status is Status.RUNNING
    clock.now += 6.0
    call.tick_once()
    assert call.status is Status.FAILURE
    assert "no response" in call.feedback_message
    service.hold.set()


def test_service_not_available(ros):
    _, node = ros
    clock = FakeClock()
    call = ServiceCall(
        "set", node, SetBlackboardValue, "nobody/set", request("x"), service_timeout=1.0, clock=clock
    )
    call.tick_once()
    assert call.status is Status.RUNNING
    clock.now += 1.5
    call.tick_once()
    assert call.status is Status.FAILURE
    assert "not available" in call.feedback_message


def test_topic_condition_and_data(ros):
    server_node, node = ros
    clock = FakeClock()
    cache = TopicCache(node, clock=clock)
    publisher = server_node.create_publisher(GripperState, "top_grippers/state", 10)
    engaged = TopicCondition(
        "top_gripper_engaged",
        cache,
        "top_grippers/state",
        GripperState,
        lambda m: all(m.engaged),
        max_age=0.5,
    )
    data = TopicData("read grippers", cache, "top_grippers/state", GripperState, "top_grippers", max_age=0.5)
    engaged.tick_once()
    assert engaged.status is Status.FAILURE
    assert "no message" in engaged.feedback_message
    data.tick_once()
    assert data.status is Status.FAILURE

    def publish(flags: list[bool]) -> None:
        publisher.publish(GripperState(group="top_grippers", engaged=flags))

    wait_for(lambda: cache.latest("top_grippers/state") is not None, tick=lambda: publish([True, True]))
    engaged.tick_once()
    assert engaged.status is Status.SUCCESS
    data.tick_once()
    assert data.status is Status.SUCCESS
    assert list(py_trees.blackboard.Blackboard.get("/top_grippers").engaged) == [True, True]

    clock.now += 1.0  # no message for a second: stale
    engaged.tick_once()
    assert engaged.status is Status.FAILURE
    assert "stale" in engaged.feedback_message
    data.tick_once()
    assert data.status is Status.FAILURE

    wait_for(
        lambda: not all(cache.latest("top_grippers/state")[0].engaged), tick=lambda: publish([True, False])
    )
    engaged.tick_once()
    assert engaged.status is Status.FAILURE
    assert engaged.feedback_message.endswith("false")


def test_topic_data_waits_then_fails(ros):
    _, node = ros
    clock = FakeClock()
    cache = TopicCache(node, clock=clock)
    data = TopicData("lifter", cache, "lifter/state_never", GripperState, "lifter", wait=2.0)
    data.tick_once()
    assert data.status is Status.RUNNING
    clock.now += 3.0
    data.tick_once()
    assert data.status is Status.FAILURE
    assert "no message" in data.feedback_message


def test_goals_on_one_server_share_a_client_and_keep_their_results(ros, action_server):
    _, node = ros
    # Discovery of the fixture's server took over the default 5 s in a loaded CI run.
    first = ActionGoal(
        "first", node, AddMember, "ars_x/add_member", goal("bay4/vertical/x0_y0"), server_timeout=30.0
    )
    second = ActionGoal(
        "second", node, AddMember, "ars_x/add_member", goal("bay4/vertical/x1_y1"), server_timeout=30.0
    )
    assert first.client is second.client
    both = py_trees.composites.Parallel(
        "both",
        policy=py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=False),
        children=[first, second],
    )
    run_to_end(both, timeout=40.0)
    assert both.status is Status.SUCCESS
    assert first.last_result.success and second.last_result.success
    assert {"bay4/vertical/x0_y0", "bay4/vertical/x1_y1"} <= set(action_server.received)


def test_result_recording_error_fails_cleanly(ros, action_server):
    _, node = ros

    def record(result, ok, reason):
        raise OSError("disk full")

    behaviour = ActionGoal(
        "add", node, AddMember, "ars_x/add_member", goal(), on_result=record, server_timeout=30.0
    )
    run_to_end(behaviour, timeout=40.0)
    assert behaviour.status is Status.FAILURE
    assert "could not be recorded: disk full" in behaviour.feedback_message


def test_topic_data_transform_error_fails(ros):
    server_node, node = ros
    cache = TopicCache(node)
    publisher = server_node.create_publisher(GripperState, "active_grippers/state", 10)
    data = TopicData(
        "pos", cache, "active_grippers/state", GripperState, "pos", transform=lambda m: m.position[3]
    )
    wait_for(
        lambda: cache.latest("active_grippers/state") is not None,
        tick=lambda: publisher.publish(GripperState(position=[0.1])),
    )
    data.tick_once()
    assert data.status is Status.FAILURE
    assert "cannot read 'active_grippers/state'" in data.feedback_message


def test_tree_status_published_in_parts_and_decoded(ros):
    from tlt_interfaces.msg import TreeStatus

    from tlt_common.bt.ros import TreeStatusPublisher
    from tlt_common.bt.status_codec import Reassembler, StatusPart, TreeShape

    server_node, node = ros
    leaves = [py_trees.behaviours.Success(f"leaf {i}") for i in range(9)] + [
        py_trees.behaviours.Running("busy")
    ]
    tree = py_trees.trees.BehaviourTree(py_trees.composites.Sequence("ARS", memory=False, children=leaves))
    publisher = TreeStatusPublisher(node, "ars_x", topic="ars_x/tree_status", max_status_bytes=1)
    publisher.attach(tree)
    ground_shape = TreeShape.from_definition(publisher.shape.definition())
    assembler = Reassembler(ground_shape)
    decoded = []
    server_node.create_subscription(
        TreeStatus,
        "ars_x/tree_status",
        lambda msg: decoded.append(assembler.add(StatusPart.from_msg(msg))),
        10,
    )
    wait_for(lambda: any(d is not None for d in decoded), tick=tree.tick)
    status = next(d for d in decoded if d is not None)
    assert status.agent == "ars_x" and status.tick_count >= 1
    assert [s for _, s in status.nodes] == publisher.shape.statuses()
    assert status.as_dict()["ARS/busy"] is Status.RUNNING


def test_each_shape_is_defined_before_its_first_status_and_a_late_subscriber_gets_it(ros):
    """The definition of the shape being ticked goes out once per shape (transient local: a
    subscriber that joins later still gets it) and names every node of the status."""
    from std_msgs.msg import String

    from tlt_common.bt.ros import TreeStatusPublisher
    from tlt_common.bt.shape_definition import parse_document_json

    server_node, node = ros
    root = py_trees.composites.Sequence("ARS", memory=False, children=[py_trees.behaviours.Success("idle")])
    tree = py_trees.trees.BehaviourTree(root)
    publisher = TreeStatusPublisher(
        node, "ars_x", topic="ars_x/defined_status", definition_topic="ars_x/tree_definition"
    )
    publisher.attach(tree)
    tree.tick()
    tree.tick()
    documents: list[tuple[str, object]] = []
    server_node.create_subscription(
        String,
        "ars_x/tree_definition",
        lambda msg: documents.append(parse_document_json(msg.data)),
        TreeStatusPublisher.DEFINITION_QOS,
    )
    wait_for(lambda: len(documents) == 1)
    agent, shape = documents[0]
    assert agent == "ars_x" and shape.hash == publisher.shape.hash
    root.add_child(py_trees.behaviours.Running("request"))
    publisher.refresh()
    tree.tick()
    wait_for(lambda: len(documents) == 2)
    assert [n.path for n in documents[1][1].nodes] == ["ARS", "ARS/idle", "ARS/request"]
    tree.tick()
    time.sleep(0.2)
    assert len(documents) == 2, "one definition per shape"


def test_tree_status_with_a_period_is_published_after_the_first_tick_that_is_due(ros):
    from rclpy.parameter import Parameter
    from rclpy.time import Time

    from tlt_common.bt.ros import TreeStatusPublisher

    _server_node, node = ros
    node.set_parameters([Parameter("use_sim_time", value=True)])
    clock = node.get_clock()
    tree = py_trees.trees.BehaviourTree(py_trees.behaviours.Running("busy"))
    publisher = TreeStatusPublisher(node, "ars_x", topic="ars_x/period_status", period_s=0.15)
    sent: list[int] = []
    publisher.publish = lambda shape, tick_count: sent.append(tick_count) or 1
    publisher.attach(tree)
    for step in range(10):  # ticks at 0.1 s of sim time
        clock.set_ros_time_override(Time(seconds=100.0 + 0.1 * step))
        tree.tick()
    assert sent == [1, 3, 5, 7, 9], "the first tick, then the first tick 0.15 s after the last one sent"
    clock.set_ros_time_override(Time(seconds=5.0))  # sim time restarted
    tree.tick()
    assert sent[-1] == 11
    node.set_parameters([Parameter("use_sim_time", value=False)])


def test_tree_status_follows_the_tree_after_a_refresh(ros):
    """A branch installed in the attached tree (an ARS request) is in the next status sent."""
    from tlt_common.bt.ros import TreeStatusPublisher

    _server_node, node = ros
    root = py_trees.composites.Sequence("ARS", memory=False, children=[py_trees.behaviours.Success("idle")])
    tree = py_trees.trees.BehaviourTree(root)
    publisher = TreeStatusPublisher(node, "ars_x", topic="ars_x/refresh_status")
    sent = []
    publisher.publish = lambda shape, tick_count: sent.append(shape) or 1
    publisher.attach(tree)
    tree.tick()
    root.add_child(py_trees.behaviours.Running("request"))
    tree.tick()
    assert sent[-1] is sent[0], "no refresh: the shape is kept"
    publisher.refresh()
    tree.tick()
    assert [n.path for n in sent[-1].nodes] == ["ARS", "ARS/idle", "ARS/request"]
    assert sent[-1].hash != sent[0].hash


class ServerWords:
    """A server process's readiness as ReadinessWatch gives it, set by the test."""

    def __init__(self) -> None:
        self.words = 1  # it said ready once, before the test's requests
        self.reason = ""

    def say(self, reason: str) -> None:
        self.words += 1
        self.reason = reason

    def heard(self) -> int:
        return self.words

    def not_ready(self) -> str:
        return self.reason


class ForgetfulService:
    """Answers every request but those in ``lost`` (their process 'died' with them)."""

    def __init__(self, node, name: str) -> None:
        self.received: list[str] = []
        self.lost = threading.Event()  # set: the next request is never answered
        self.release = threading.Event()
        self.service = node.create_service(
            SetBlackboardValue, name, self.handle, callback_group=ReentrantCallbackGroup()
        )

    def handle(self, request, response):
        self.received.append(request.key)
        if self.lost.is_set():
            self.lost.clear()
            self.release.wait(timeout=10.0)
        response.accepted = True
        return response


@pytest.fixture
def forgetful(ros):
    server_node, _ = ros
    name = f"vision_{len(FORGETFUL)}/ask"
    FORGETFUL.append(name)
    service = ForgetfulService(server_node, name)
    yield service
    service.release.set()  # the held request is answered; its service goes with the node


FORGETFUL: list[str] = []


def asking(node, service: ForgetfulService, clock, state, retries: int = 2) -> ServiceCall:
    return ServiceCall(
        "ask",
        node,
        SetBlackboardValue,
        service.service.srv_name,
        request("lifter_speed"),
        timeout=30.0,
        clock=clock,
        retries=retries,
        server_state=state,
        back_within=100.0,
    )


def test_a_request_lost_with_a_restarted_server_is_asked_again_once_it_says_ready(ros, forgetful):
    _, node = ros
    clock, state = FakeClock(), ServerWords()
    forgetful.lost.set()
    call = asking(node, forgetful, clock, state)
    wait_for(lambda: len(forgetful.received) == 1, tick=call.tick_once)
    call.tick_once()
    assert call.status is Status.RUNNING
    state.say("no joint state for ur_x_shoulder_pan_joint yet")  # the new process, starting
    call.tick_once()
    assert call.status is Status.RUNNING and "restarted" in call.feedback_message
    for _ in range(3):
        clock.now += 10.0
        call.tick_once()
        assert call.status is Status.RUNNING
        assert "waiting for it to come back: no joint state" in call.feedback_message
    assert len(forgetful.received) == 1  # nothing asked of a process that is not ready
    state.say("")
    run_to_end(call)
    assert call.status is Status.SUCCESS
    assert forgetful.received == ["lifter_speed"] * 2


def test_a_request_unanswered_in_time_is_asked_again_only_once_the_process_is_back(ros, forgetful):
    _, node = ros
    clock, state = FakeClock(), ServerWords()
    forgetful.lost.set()
    call = asking(node, forgetful, clock, state)
    wait_for(lambda: len(forgetful.received) == 1, tick=call.tick_once)
    clock.now += 31.0
    call.tick_once()
    assert call.status is Status.RUNNING and "within 30 s" in call.feedback_message
    clock.now += 50.0
    call.tick_once()
    assert call.status is Status.RUNNING and "no word from its process" in call.feedback_message
    state.say("")  # a new process said ready at once
    run_to_end(call)
    assert call.status is Status.SUCCESS and len(forgetful.received) == 2


def test_a_process_that_does_not_come_back_in_time_fails_the_request(ros, forgetful):
    _, node = ros
    clock, state = FakeClock(), ServerWords()
    forgetful.lost.set()
    call = asking(node, forgetful, clock, state)
    wait_for(lambda: len(forgetful.received) == 1, tick=call.tick_once)
    clock.now += 31.0
    call.tick_once()
    clock.now += 101.0
    call.tick_once()
    assert call.status is Status.FAILURE
    assert "no response" in call.feedback_message and "not back within 100 s" in call.feedback_message


def test_requests_are_asked_again_at_most_retries_times(ros, forgetful):
    _, node = ros
    clock, state = FakeClock(), ServerWords()
    call = asking(node, forgetful, clock, state, retries=1)
    for _ in range(2):
        forgetful.lost.set()
        asked = len(forgetful.received)
        wait_for(lambda asked=asked: len(forgetful.received) == asked + 1, tick=call.tick_once)
        state.say("")  # a restarted process says ready
        call.tick_once()
    assert call.status is Status.FAILURE
    assert "restarted" in call.feedback_message and "(asked 2 times)" in call.feedback_message


def test_without_retries_a_word_from_the_process_changes_nothing(ros, forgetful):
    _, node = ros
    clock, state = FakeClock(), ServerWords()
    forgetful.lost.set()
    call = asking(node, forgetful, clock, state, retries=0)
    wait_for(lambda: len(forgetful.received) == 1, tick=call.tick_once)
    state.say("")
    call.tick_once()
    assert call.status is Status.RUNNING
    clock.now += 31.0
    call.tick_once()
    assert call.status is Status.FAILURE and call.feedback_message.endswith("within 30 s")


def test_the_first_word_heard_after_the_request_went_out_is_not_a_restart(ros, forgetful):
    """A caller that has just subscribed can hear the server's latched word after its request."""
    _, node = ros
    clock, state = FakeClock(), ServerWords()
    state.words = 0
    forgetful.lost.set()
    call = asking(node, forgetful, clock, state)
    wait_for(lambda: len(forgetful.received) == 1, tick=call.tick_once)
    state.say("")
    call.tick_once()
    assert call.status is Status.RUNNING and call.feedback_message.startswith("request sent")
    forgetful.release.set()
    run_to_end(call)
    assert call.status is Status.SUCCESS and len(forgetful.received) == 1
