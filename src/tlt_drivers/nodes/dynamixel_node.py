"""Base of the Dynamixel driver nodes: one chain interface, its trajectory and group position controllers.

Joints with ``controller: trajectory`` are driven through ``/<component>/follow_joint_trajectory``;
joints with ``controller: group_position`` through ``/<component>/position_command``
(``std_msgs/Float64MultiArray``, in the order the joints appear in the YAML). Health goes out on
``/<component>/hardware_status``; subclasses publish their own state message.
"""

from __future__ import annotations

from typing import Any

from tlt_common.ros.lean_node import LeanNode
from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
from tlt_drivers.nodes.driver_loop import DriverLoop


class DynamixelDriverNode(LeanNode):
    """A node owning one Dynamixel chain described by a validated chain config."""

    def __init__(
        self, node_name: str, config: dict[str, Any], *, motion_gate=None, start: bool = True, context=None
    ) -> None:
        super().__init__(node_name, context=context)
        self.config = config
        self.hw = DynamixelChainInterface(config)
        joints = config["joints"]
        self.loop = DriverLoop.for_chain(
            self,
            self.hw,
            config,
            joints,
            trajectory_joints=[j["name"] for j in joints if j["controller"] == "trajectory"],
            group_joints=[j["name"] for j in joints if j["controller"] == "group_position"],
            trajectory_tolerances=config["trajectory"],
            motion_gate=motion_gate,
            publish_state=self.publish_state,
        )
        if start:
            self.loop.start()

    def publish_state(self) -> None:
        """Subclasses publish their state message here (called at state_rate_hz)."""

    def shutdown(self) -> None:
        """Stop the control loop and close the chain."""
        self.loop.stop()
