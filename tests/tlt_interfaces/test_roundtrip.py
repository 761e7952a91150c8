"""Every message, service and action of tlt_interfaces crosses between two real processes over DDS
with every field intact."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import rclpy
from rclpy.action.client import GoalStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from tlt_common.interfaces import iter_interfaces, message_parts, sample_message
from tlt_common.ros.action_client import SerialisedActionClient
from tlt_common.ros.spin_loop import spin

INTERFACES = list(iter_interfaces())
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
TIMEOUT_S = 20.0


def _ids(kind: str) -> list[str]:
    return [name for k, name, _ in INTERFACES if k == kind]


def test_the_package_holds_what_the_system_needs():
    names = {name for _, name, _ in INTERFACES}
    assert {"AddCrossFrame", "AddMember", "AffixMember", "FoundationRivet", "FollowJointTrajectory"} <= set(
        _ids("action")
    )
    assert {
        "LifterState",
        "GripperState",
        "EndEffectorState",
        "TreeStatus",
        "MissionProgress",
        "InspectionReport",
        "CertifiedPose",
    } <= set(_ids("msg"))
    assert {
        "InspectPart",
        "InspectBay",
        "CheckAlignment",
        "LocateTag",
        "SetLifterMode",
        "SetBlackboardValue",
        "SetActuatorState",
        "GroundCommand",
    } <= set(_ids("srv"))
    assert len(names) == len(INTERFACES)


def test_samples_set_every_field_away_from_its_default():
    for kind, _name, cls in INTERFACES:
        for part_cls in message_parts(kind, cls).values():
            if not part_cls.get_fields_and_field_types():
                continue
            assert sample_message(part_cls, 1) != part_cls(), part_cls
            assert sample_message(part_cls, 1) != sample_message(part_cls, 2), part_cls


@pytest.fixture(scope="module")
def peer():
    script = Path(__file__).with_name("roundtrip_peer.py")
    proc = subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert "peer ready" in line, line + proc.stdout.read()
    yield proc
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:  # an executor stuck in shutdown is not what this test is about
        proc.kill()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def node(peer):
    rclpy.init()
    node = Node("tlt_roundtrip_test")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    # Each test destroys its clients while this thread spins: rclpy's own spin loop died of one
    # destroyed as it built its wait set, and every later action test timed out (a clean run).
    done = threading.Event()
    spinner = threading.Thread(target=spin, args=(executor,), kwargs={"stop": done.is_set}, daemon=True)
    spinner.start()
    yield node
    # The spin thread ends before the node goes: a node destroyed under it failed that thread with
    # InvalidHandle as it added the node's event handlers to its wait set.
    done.set()
    spinner.join(timeout=5)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


def _wait(event: threading.Event, what: str, resend=None) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not event.wait(0.1):
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        if resend:
            resend()


@pytest.mark.parametrize("name", _ids("msg"))
def test_message_round_trip(node, name):
    cls = next(c for k, n, c in INTERFACES if k == "msg" and n == name)
    sent = sample_message(cls, 5)
    received = []
    got = threading.Event()

    def on_pong(msg):
        received.append(msg)
        got.set()

    sub = node.create_subscription(cls, f"rt/msg/{name}/pong", on_pong, QOS)
    pub = node.create_publisher(cls, f"rt/msg/{name}/ping", QOS)
    try:
        # Re-sent until the echo comes back: the first ones may go out before discovery matched.
        _wait(got, f"{name} echo", resend=lambda: pub.publish(sent))
        assert received[0] == sent
    finally:
        node.destroy_subscription(sub)
        node.destroy_publisher(pub)


@pytest.mark.parametrize("name", _ids("srv"))
def test_service_round_trip(node, name):
    cls = next(c for k, n, c in INTERFACES if k == "srv" and n == name)
    client = node.create_client(cls, f"rt/srv/{name}")
    try:
        assert client.wait_for_service(timeout_sec=TIMEOUT_S), f"service rt/srv/{name} not found"
        future = client.call_async(sample_message(cls.Request, 1))
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        _wait(done, f"{name} response")
        assert future.result() == sample_message(cls.Response, 2)
    finally:
        node.destroy_client(client)


@pytest.mark.parametrize("name", _ids("action"))
def test_action_round_trip(node, name):
    cls = next(c for k, n, c in INTERFACES if k == "action" and n == name)
    # The test thread sends while the executor thread takes responses: rclpy's own client can drop
    # a response taken before its future is registered, which the serialised client cannot.
    client = SerialisedActionClient(node, cls, f"rt/action/{name}")
    feedback = []
    try:
        assert client.wait_for_server(timeout_sec=TIMEOUT_S), f"action rt/action/{name} not found"
        goal_future = client.send_goal_async(
            sample_message(cls.Goal, 1), feedback_callback=lambda fb: feedback.append(fb.feedback)
        )
        accepted = threading.Event()
        goal_future.add_done_callback(lambda _: accepted.set())
        _wait(accepted, f"{name} goal acceptance")
        handle = goal_future.result()
        assert handle.accepted
        result_future = handle.get_result_async()
        finished = threading.Event()
        result_future.add_done_callback(lambda _: finished.set())
        _wait(finished, f"{name} result")
        outcome = result_future.result()
        assert outcome.status == GoalStatus.STATUS_SUCCEEDED
        assert outcome.result == sample_message(cls.Result, 2)
        assert sample_message(cls.Feedback, 3) in feedback
    finally:
        client.destroy()
