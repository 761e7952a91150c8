"""Two small rclpy programs for the launcher tests: an AddMember action server and a client that
sends it a goal every 0.2 s and prints each result. Run as ``action_pair.py server|client``."""

from __future__ import annotations

import sys

import rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.node import Node
from tlt_interfaces.action import AddMember


def serve() -> None:
    node = Node("pair_server")

    def execute(handle):
        handle.succeed()
        return AddMember.Result(success=True, reason=f"placed {handle.request.member_id}")

    ActionServer(node, AddMember, "pair/add_member", execute)
    print("server up", flush=True)
    rclpy.spin(node)


def client() -> None:
    node = Node("pair_client")
    action = ActionClient(node, AddMember, "pair/add_member")
    count = 0
    pending = []

    def send() -> None:
        nonlocal count
        if pending or not action.server_is_ready():
            return
        count += 1
        future = action.send_goal_async(AddMember.Goal(member_id=f"m{count}", bay=1))
        pending.append(future)
        future.add_done_callback(on_accepted)

    def on_accepted(future) -> None:
        future.result().get_result_async().add_done_callback(on_result)

    def on_result(future) -> None:
        pending.clear()
        result = future.result().result
        print(f"result success={result.success} reason={result.reason}", flush=True)

    node.create_timer(0.2, send)
    rclpy.spin(node)


if __name__ == "__main__":
    rclpy.init()
    try:
        {"server": serve, "client": client}[sys.argv[1]]()
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
