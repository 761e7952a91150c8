"""``camera_mounts`` driver node: one MX-106T per ZED camera mount (paper §V.B), trajectory-controlled.

Publishes ``sensor_msgs/JointState`` on ``/camera_mounts/joint_states`` (position rad, velocity
rad/s, effort as a fraction of stall current) and ``HardwareStatus``.
"""

from __future__ import annotations

from typing import Any

from sensor_msgs.msg import JointState

from tlt_common import ros_names
from tlt_drivers.dynamixel.config import load_chain
from tlt_drivers.node_main import Driver, chain_driver, run_driver
from tlt_drivers.nodes.dynamixel_node import DynamixelDriverNode


class CameraMountsNode(DynamixelDriverNode):
    def __init__(self, config: dict[str, Any], *, start: bool = True, context=None) -> None:
        super().__init__(config["component"], config, start=False, context=context)
        topic = ros_names.joint_states_topic(config["component"])
        self.state_pub = self.create_publisher(JointState, topic, 10)
        if start:
            self.loop.start()

    def publish_state(self) -> None:
        names = self.hw.joint_names
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = names
        msg.position = [self.hw.position[n] for n in names]
        msg.velocity = [self.hw.velocity[n] for n in names]
        msg.effort = [self.hw.effort[n] for n in names]
        self.state_pub.publish(msg)


def driver(args: list[str]) -> Driver:
    """The camera mounts' driver from its arguments (``chain_driver``'s)."""
    return chain_driver("camera_mounts", "camera_mounts.yaml", load_chain, CameraMountsNode, args)


def main(argv: list[str] | None = None) -> int:
    return run_driver("tlt-camera-mounts", driver, argv)


if __name__ == "__main__":
    raise SystemExit(main())
