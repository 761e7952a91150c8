"""The far end of the interface round-trip test, run as its own process.

For every tlt_interfaces message it echoes ``rt/msg/<Name>/ping`` to ``rt/msg/<Name>/pong``; for
every service it serves ``rt/srv/<Name>`` and every action ``rt/action/<Name>``. A request or goal
equal to ``sample_message(..., seed=1)`` is answered with the seed-2 response or result (and the
seed-3 feedback); anything else gets a default response, which the test sees as a failure.
"""

from __future__ import annotations

import time

import rclpy
from rclpy.action import ActionServer
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from tlt_common.interfaces import iter_interfaces, sample_message

QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def main() -> None:
    rclpy.init()
    node = Node("tlt_roundtrip_peer")
    keep = []
    for kind, name, cls in iter_interfaces():
        if kind == "msg":
            pub = node.create_publisher(cls, f"rt/msg/{name}/pong", QOS)
            keep.append(node.create_subscription(cls, f"rt/msg/{name}/ping", pub.publish, QOS))
        elif kind == "srv":

            def serve(request, response, cls=cls):
                expected = sample_message(cls.Request, 1)
                return sample_message(cls.Response, 2) if request == expected else response

            keep.append(node.create_service(cls, f"rt/srv/{name}", serve))
        else:

            def execute(handle, cls=cls):
                if handle.request != sample_message(cls.Goal, 1):
                    handle.abort()
                    return cls.Result()
                # Repeated: the client's feedback subscription may still be matching.
                for _ in range(10):
                    handle.publish_feedback(sample_message(cls.Feedback, 3))
                    time.sleep(0.05)
                handle.succeed()
                return sample_message(cls.Result, 2)

            keep.append(ActionServer(node, cls, f"rt/action/{name}", execute))
    print("peer ready", flush=True)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
