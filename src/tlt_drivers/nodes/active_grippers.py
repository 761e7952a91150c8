"""``active_grippers`` driver node: four MX-106T on lead screws (paper §V.B.3), trajectory-controlled.

Publishes ``tlt_interfaces/msg/GripperState`` on ``/active_grippers/state``; a gripper counts as
engaged when its position is beyond the joint's ``engaged_above``.
"""

from __future__ import annotations

from typing import Any

from tlt_interfaces.msg import GripperState

from tlt_common import ros_names
from tlt_drivers.dynamixel.config import load_chain
from tlt_drivers.node_main import Driver, chain_driver, run_driver
from tlt_drivers.nodes.dynamixel_node import DynamixelDriverNode
from tlt_drivers.nodes.gripper_state import gripper_state


class GripperGroupNode(DynamixelDriverNode):
    """A Dynamixel gripper group publishing GripperState."""

    def __init__(
        self, config: dict[str, Any], *, node_name: str | None = None, start: bool = True, context=None
    ) -> None:
        super().__init__(node_name or config["component"], config, start=False, context=context)
        self.state_pub = self.create_publisher(GripperState, ros_names.state_topic(config["component"]), 10)
        if start:
            self.loop.start()

    def publish_state(self) -> None:
        engaged = [
            j.engaged_above is not None and self.hw.position[j.name] >= j.engaged_above
            for j in self.hw.joints
        ]
        self.state_pub.publish(gripper_state(self, self.hw, self.config["component"], engaged))


def driver(args: list[str]) -> Driver:
    """The Active Grippers' driver from its arguments (``chain_driver``'s)."""
    return chain_driver("active_grippers", "active_grippers.yaml", load_chain, GripperGroupNode, args)


def main(argv: list[str] | None = None) -> int:
    return run_driver("tlt-active-grippers", driver, argv)


if __name__ == "__main__":
    raise SystemExit(main())
