"""A SerialisedActionClient can be taken from by an executor from the moment its node holds it."""

from __future__ import annotations

import rclpy
from rclpy.node import Node
from tlt_interfaces.action import AddMember

from tlt_common.ros.action_client import SerialisedActionClient


def test_a_client_is_usable_by_the_executor_as_soon_as_the_node_holds_it(monkeypatch):
    # An executor spinning the node on another thread may take data from a waitable the moment it
    # is added, before the client's own constructor has returned: that take is done here, at once.
    taken = []
    add_waitable = Node.add_waitable

    def add_and_take(node, waitable):
        add_waitable(node, waitable)
        # What the executor's is_ready() would find of a client with no server: nothing ready.
        for kind in ("feedback", "status", "goal_response", "cancel_response", "result_response"):
            setattr(waitable, f"_is_{kind}_ready", False)
        taken.append(waitable.take_data())

    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("serialised_client_probe", context=context)
    try:
        monkeypatch.setattr(Node, "add_waitable", add_and_take)
        client = SerialisedActionClient(node, AddMember, "/probe/add_member")
        assert taken == [{}], "nothing to take yet, and no error taking it"
        client.destroy()
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
