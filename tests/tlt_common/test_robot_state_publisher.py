"""tlt-robot-state (tlt_common.robot_state_publisher): the drivers' joint states and the EDU's URDF
give the transform tree the twin has, and the node publishes it."""

from __future__ import annotations

import threading
import time

import mujoco
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage
from tlt_sim.model import names, urdf
from tlt_sim.model.scene import Scene

from tlt_common import ros_names
from tlt_common.geometry.transforms import quaternion_to_rotation
from tlt_common.robot_state_publisher import (
    RobotStatePublisher,
    moving_message,
    parse_urdf,
    static_message,
    urdf_joint_name,
)
from tlt_common.ros.spin_loop import spin
from tlt_common.ros.transform_messages import TF_STATIC_QOS

ARM = np.array([0.4, -1.1, 1.3, -0.9, -1.2, 0.7])


def _driver_state(scene: Scene) -> JointState:
    """What the UR X driver and the camera mounts driver report for ``scene``'s joints."""
    msg = JointState()
    msg.header.stamp.sec = 12
    for joint in names.arm_joints("ars_x"):
        msg.name.append(f"ur_x_{joint.split('/')[1]}")
        msg.position.append(scene.position(joint))
    msg.name.append(names.camera_mount(0))
    msg.position.append(scene.position(names.camera_mount(0)))
    return msg


def _edges(*messages: TFMessage) -> dict[str, tuple[str, np.ndarray, np.ndarray]]:
    out = {}
    for msg in messages:
        for t in msg.transforms:
            p, q = t.transform.translation, t.transform.rotation
            out[t.child_frame_id] = (
                t.header.frame_id,
                np.array([p.x, p.y, p.z]),
                quaternion_to_rotation([q.x, q.y, q.z, q.w]),
            )
    return out


def test_joint_states_and_the_urdf_put_the_arm_and_camera_where_the_twin_has_them(tmp_path):
    with Scene(out_dir=tmp_path / "model") as scene:
        scene.pose_arm("ars_x", ARM)
        scene.set_joint_state(names.camera_mount(0), 0.6)
        mujoco.mj_kinematics(scene.model, scene.data)
        mujoco.mj_camlight(scene.model, scene.data)
        joints = parse_urdf(urdf.urdf(scene.model))
        state = _driver_state(scene)
        moving = moving_message(joints, state)
        assert {t.child_frame_id for t in moving.transforms} == {
            *(f"ars_x/link_{i}" for i in range(1, 7)),
            "camera_mount_1",
        }
        edges = _edges(static_message(joints), moving)

        def world(frame: str) -> tuple[np.ndarray, np.ndarray]:
            if frame == "world":
                return np.zeros(3), np.eye(3)
            parent, p, r = edges[frame]
            pp, pr = world(parent)
            return pp + pr @ p, pr @ r

        for body in ("ars_x/ee", "ars_x/gripper_a", "camera_mount_1"):
            p, r = scene.body_pose(body)
            assert np.allclose(world(body)[0], p, atol=1e-5), body
            assert np.allclose(world(body)[1], r, atol=1e-5), body
        p, _ = scene.camera_pose(names.zed_camera(0))
        assert np.allclose(world(names.optical_frame(names.zed_camera(0)))[0], p, atol=1e-5)


def test_driver_names_become_urdf_names_and_a_bad_document_is_refused():
    assert urdf_joint_name("ur_y_wrist_3_joint") == "ars_y/wrist_3_joint"
    assert urdf_joint_name("camera_mount_2") == "camera_mount_2"
    with pytest.raises(ValueError, match="not a URDF"):
        parse_urdf("<mujoco/>")
    with pytest.raises(ValueError, match="not a URDF"):
        parse_urdf("<robot")


def test_the_node_publishes_the_description_the_fixed_joints_and_each_joint_state(tmp_path):
    with Scene(out_dir=tmp_path / "model") as scene:
        description = urdf.urdf(scene.model)
        state = _driver_state(scene)
    context = Context()
    rclpy.init(context=context)
    node = RobotStatePublisher(description, context=context)
    probe = Node("robot_state_probe", context=context)
    got: dict[str, list] = {"tf": [], "static": []}
    probe.create_subscription(TFMessage, ros_names.TF, got["tf"].append, 10)
    probe.create_subscription(TFMessage, ros_names.TF_STATIC, got["static"].append, TF_STATIC_QOS)
    joints = probe.create_publisher(JointState, ros_names.joint_states_topic("ur_x"), 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(probe)
    stop = threading.Event()
    spinner = threading.Thread(target=spin, args=(executor, context, stop.is_set), daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 10.0
        while not (got["tf"] and got["static"]) and time.monotonic() < deadline:
            joints.publish(state)
            time.sleep(0.1)
    finally:
        stop.set()
        spinner.join(timeout=10)
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown(context=context)
    assert got["static"] and got["tf"]
    assert "ars_x/ee" in {t.child_frame_id for t in got["static"][0].transforms}
    assert got["tf"][0].transforms[0].header.stamp.sec == 12
