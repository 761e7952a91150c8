"""The ``tlt_interfaces/msg/GripperState`` a gripper group's driver node publishes.

The Active Grippers (Dynamixel) and the Top Grippers (MightyZAP) report alike, so the CRS's gripper
checks read one message whatever drives the pins; each node says only which of its joints count
as engaged, since that rule is the hardware's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rclpy.node import Node
from tlt_interfaces.msg import GripperState

from tlt_drivers.hardware_interface import Lifecycle

if TYPE_CHECKING:
    from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
    from tlt_drivers.mightyzap.chain_interface import MightyZapChainInterface


def gripper_state(
    node: Node, hw: DynamixelChainInterface | MightyZapChainInterface, group: str, engaged: list[bool]
) -> GripperState:
    """The group's state now: positions and goals per joint in ``hw.joint_names`` order, the low
    byte of each servo's hardware error, and the interface's torque and fault state."""
    msg = GripperState()
    msg.header.stamp = node.get_clock().now().to_msg()
    msg.group = group
    names = hw.joint_names
    msg.joint_names = names
    msg.position = [hw.position[n] for n in names]
    msg.goal_position = [hw.command[n] for n in names]
    msg.engaged = engaged
    msg.hardware_error = [hw.hardware_error[n] & 0xFF for n in names]
    msg.torque_enabled = hw.state == Lifecycle.ACTIVE
    msg.fault = hw.state == Lifecycle.ERROR
    msg.fault_reason = hw.fault
    return msg
