"""tlt-live-bridge (tlt_common.foxglove_bridge): a viewer speaking Foxglove's WebSocket protocol sees
the graph's topics with their ros2msg schemas, gets a latched topic's CDR bytes once it subscribes,
and the bridge subscribes to ROS only while a viewer does."""

from __future__ import annotations

import json
import struct
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from websockets.sync.client import connect

from tlt_common import ros_names
from tlt_common.foxglove_bridge import LAYOUT, FoxgloveBridge
from tlt_common.ros.spin_loop import spin
from tlt_common.ros.transform_messages import TF_STATIC_QOS, tf_message

ROOT = Path(__file__).resolve().parents[2]
MESSAGE_DATA = 0x01  # the server's binary message-data opcode


def _until(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


def test_a_viewer_subscribes_to_a_latched_topic_and_gets_its_cdr_bytes():
    context = Context()
    rclpy.init(context=context)
    talker = Node("bridge_test_talker", context=context)
    static = talker.create_publisher(TFMessage, ros_names.TF_STATIC, TF_STATIC_QOS)
    talker.create_publisher(String, "/bridge_test/chatter", 10)
    sent = tf_message("world", {"lifter": (np.array([0.1, 0.2, 0.3]), np.eye(3))}, 4.5)
    static.publish(sent)
    bridge = FoxgloveBridge(port=0, discovery_period_s=0.2, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(talker)
    executor.add_node(bridge)
    stop = threading.Event()
    spinner = threading.Thread(target=spin, args=(executor, context, stop.is_set), daemon=True)
    spinner.start()
    try:
        assert bridge.address.startswith("ws://127.0.0.1:")
        _until(lambda: ros_names.TF_STATIC in bridge.topics, 10.0, f"never offered: {bridge.topics}")
        assert talker.count_subscribers(ros_names.TF_STATIC) == 0, "subscribed before any viewer"
        with connect(bridge.address, subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            channels: dict[str, dict] = {}
            while ros_names.TF_STATIC not in channels:
                op = json.loads(ws.recv(timeout=10))
                if op["op"] == "advertise":
                    channels.update({c["topic"]: c for c in op["channels"]})
            tf_static = channels[ros_names.TF_STATIC]
            assert tf_static["schemaName"] == "tf2_msgs/msg/TFMessage"
            assert tf_static["schemaEncoding"] == "ros2msg" and tf_static["encoding"] == "cdr"
            assert "MSG: geometry_msgs/TransformStamped" in tf_static["schema"]
            ws.send(
                json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": tf_static["id"]}]})
            )
            while True:
                frame = ws.recv(timeout=10)
                if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                    break
            subscription_id, _log_time = struct.unpack_from("<IQ", frame, 1)
            assert subscription_id == 7
            got = deserialize_message(frame[13:], TFMessage)
            assert [t.child_frame_id for t in got.transforms] == ["lifter"]
            assert got.transforms[0].transform.translation.z == 0.3
            ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [7]}))
            _until(lambda: talker.count_subscribers(ros_names.TF_STATIC) == 0, 10.0, "still subscribed")
    finally:
        stop.set()
        spinner.join(timeout=10)
        executor.shutdown()
        bridge.destroy_node()
        talker.destroy_node()
        rclpy.try_shutdown(context=context)


def test_the_shipped_layout_shows_only_topics_the_system_publishes():
    """config/foxglove/tlt_edu.json (docs/live-view.md): its panels name topics that exist."""
    layout = json.loads((ROOT / LAYOUT).read_text())
    named: set[str] = set()

    def walk(value) -> None:
        if isinstance(value, dict):
            for key, item in value.items():
                if key == "topics" and isinstance(item, dict):
                    named.update(item)
                elif key in ("topic", "topicPath", "topicToRender") and isinstance(item, str):
                    named.add(item)
                else:
                    walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)

    walk(layout["configById"])
    published = {
        ros_names.ROBOT_DESCRIPTION,
        ros_names.VISION_MARKERS,
        ros_names.CRS_MISSION_PROGRESS,
        "/twin/markers",
        "/rosout",
    }
    assert named and named <= published, named - published
    panels = set(layout["configById"])
    assert {"3D!edu", "RosOut!log"} <= panels

    def leaves(node) -> set[str]:
        return leaves(node["first"]) | leaves(node["second"]) if isinstance(node, dict) else {node}

    assert leaves(layout["layout"]) == panels
