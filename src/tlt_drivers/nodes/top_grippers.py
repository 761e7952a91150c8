"""``top_grippers`` driver node: MightyZAP push pins on one IR-USB02 port (paper §V.B.2).

Position commands (metres of stroke, one per actuator in YAML order) arrive as
``std_msgs/Float64MultiArray`` on ``/top_grippers/position_command`` (JointGroupPositionController);
``tlt_interfaces/msg/GripperState`` goes out on ``/top_grippers/state``, with ``engaged`` from the
measured stroke against each actuator's ``engaged_above``.
"""

from __future__ import annotations

from typing import Any

from tlt_interfaces.msg import GripperState

from tlt_common import ros_names
from tlt_common.ros.lean_node import LeanNode
from tlt_drivers.mightyzap.chain_interface import MightyZapChainInterface
from tlt_drivers.mightyzap.config import load_mightyzap
from tlt_drivers.node_main import Driver, chain_driver, run_driver
from tlt_drivers.nodes.driver_loop import DriverLoop
from tlt_drivers.nodes.gripper_state import gripper_state


class TopGrippersNode(LeanNode):
    def __init__(self, config: dict[str, Any], *, start: bool = True, context=None) -> None:
        super().__init__(config["component"], context=context)
        self.config = config
        self.hw = MightyZapChainInterface(config)
        acts = config["actuators"]
        self.loop = DriverLoop.for_chain(
            self,
            self.hw,
            config,
            acts,
            group_joints=[a["name"] for a in acts],
            publish_state=self.publish_state,
        )
        self.state_pub = self.create_publisher(GripperState, ros_names.state_topic(config["component"]), 10)
        if start:
            self.loop.start()

    def publish_state(self) -> None:
        engaged = [self.hw.position[a["name"]] >= a["engaged_above"] for a in self.hw.actuators]
        self.state_pub.publish(gripper_state(self, self.hw, self.config["component"], engaged))

    def shutdown(self) -> None:
        """Stop the control loop and close the board's port."""
        self.loop.stop()


def driver(args: list[str]) -> Driver:
    """The Top Grippers' driver from its arguments (``chain_driver``'s)."""
    return chain_driver("top_grippers", "top_grippers.yaml", load_mightyzap, TopGrippersNode, args)


def main(argv: list[str] | None = None) -> int:
    return run_driver("tlt-top-grippers", driver, argv)


if __name__ == "__main__":
    raise SystemExit(main())
