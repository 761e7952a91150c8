"""A node destroyed with destroy_node leaves nothing in the graph that later nodes of the same
process would find; rclpy's Node.destroy_node leaves its action servers."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.action import ActionServer
from rclpy.node import Node
from tlt_interfaces.action import AddMember

from tlt_common.ros.action_graph import describe_action_server_graph
from tlt_common.ros.node_teardown import destroy_node

pytestmark = pytest.mark.timeout(60)

STALE = "/teardown_probe/stale"
CANARY = "/teardown_probe/canary"


def _served(node: Node, action: str) -> bool:
    return "request readers 0," not in describe_action_server_graph(node, action).split(";")[0]


def _wait_until(predicate, what: str, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def _serve_and_shut_down(action: str, destroy) -> None:
    """A node serving ``action`` in a context of its own, destroyed with ``destroy`` and its
    context shut down, as a test or a restarted agent leaves it."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("teardown_server", context=context)
    server = ActionServer(node, AddMember, action, execute_callback=lambda handle: None)
    destroy(node)
    del server  # the node keeps it (node.waitables), as agents' nodes keep theirs
    rclpy.try_shutdown(context=context)


@pytest.fixture
def probe():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("teardown_probe", context=context)
    yield node
    destroy_node(node)
    rclpy.try_shutdown(context=context)


def test_a_node_destroy_node_left_still_serves_its_action_to_later_nodes():
    # Why destroy_node exists: were rclpy to destroy the servers itself, this would fail.
    plain = []
    _serve_and_shut_down(STALE, lambda node: (plain.append(node), node.destroy_node()))
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = Node("teardown_probe", context=context)
    try:
        _wait_until(lambda: _served(probe, STALE), "the stale server to be listed")
    finally:
        for node in plain:
            destroy_node(node)
        destroy_node(probe)
        rclpy.try_shutdown(context=context)


def test_a_node_destroyed_with_its_servers_is_not_found_by_later_nodes(probe):
    _serve_and_shut_down(STALE, destroy_node)
    # A live server in another context, started after, shows discovery has had its time.
    context = rclpy.Context()
    rclpy.init(context=context)
    canary = Node("teardown_canary", context=context)
    ActionServer(canary, AddMember, CANARY, execute_callback=lambda handle: None)
    try:
        _wait_until(lambda: _served(probe, CANARY), "the live server to be listed")
        time.sleep(0.5)
        assert not _served(probe, STALE), describe_action_server_graph(probe, STALE)
    finally:
        destroy_node(canary)
        rclpy.try_shutdown(context=context)


def test_the_graph_description_names_each_endpoints_node(probe):
    server = Node("teardown_server", namespace="/rig", context=probe.context)
    ActionServer(server, AddMember, STALE, execute_callback=lambda handle: None)
    try:
        _wait_until(lambda: _served(probe, STALE), "the server to be listed")
        text = describe_action_server_graph(probe, STALE)
        assert text.startswith(
            f"{STALE} as teardown_probe sees it: send_goal: request readers 1 (/rig/teardown_server)"
        )
        assert "status writers 1 (/rig/teardown_server); feedback writers 1 (/rig/teardown_server)" in text
    finally:
        destroy_node(server)
    _wait_until(lambda: not _served(probe, STALE), "the server to leave the graph")
    assert "request readers 0, response writers 0" in describe_action_server_graph(probe, STALE)
