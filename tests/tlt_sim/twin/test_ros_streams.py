"""Cameras render only while subscribed, at their rate, and their segmentation carries the objects in
view; ground-truth poses come out as the model has them."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String
from tlt_interfaces.msg import TransformArray
from tlt_sim.model.camera_sensor import load_camera_sensors
from tlt_sim.twin import topics
from tlt_sim.twin.ros_streams import CameraStreams, GroundTruth


@pytest.fixture
def ros():
    ctx = Context()
    rclpy.init(context=ctx)
    twin_node = Node("twin_under_test", context=ctx)
    probe = Node("probe", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(probe)
    yield twin_node, probe, executor
    executor.shutdown()
    probe.destroy_node()
    twin_node.destroy_node()
    rclpy.shutdown(context=ctx)


def _run(twin, streams, executor, until, wall_s: float = 20.0) -> None:
    deadline = time.monotonic() + wall_s
    while not until() and time.monotonic() < deadline:
        t = twin.tick()
        for s in streams:
            s.publish_due(t)
        executor.spin_once(timeout_sec=0.0)
    for _ in range(20):  # let messages in flight arrive
        executor.spin_once(timeout_sec=0.01)


def test_camera_renders_only_when_subscribed_and_segments_the_part_in_view(make_twin, ros):
    twin_node, probe, executor = ros
    twin = make_twin()
    scene = twin.scene
    part = next(p for p in scene.info.parts.values() if p.kind == "vertical")
    scene.place_in_view(part.name, "zed_1", 0.6)
    cams = CameraStreams(twin_node, scene, twin.settings.replace(camera_rate_hz=10.0), load_camera_sensors())

    _run(twin, [cams], executor, lambda: scene.time >= 0.5, wall_s=5.0)
    assert sum(cams.renders.values()) == 0, "nobody subscribed: nothing rendered"

    got: dict[str, list] = {"seg": [], "info": [], "labels": []}
    probe.create_subscription(Image, topics.camera_topic("zed_1", "segmentation"), got["seg"].append, 10)
    probe.create_subscription(CameraInfo, topics.camera_topic("zed_1", "camera_info"), got["info"].append, 10)
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    probe.create_subscription(String, topics.SEGMENTATION_LABELS, got["labels"].append, latched)
    start = scene.time
    _run(twin, [cams], executor, lambda: len(got["seg"]) >= 3 and got["labels"])
    sim_span = scene.time - start

    assert set(cams.renders) == {"zed_1"}, "only the subscribed camera renders"
    assert cams.renders["zed_1"] <= 10.0 * sim_span + 1, "no more than rate_hz frames per sim second"
    msg = got["seg"][0]
    w, h = cams.settings.zed_size
    assert (msg.encoding, msg.width, msg.height) == ("32SC1", w, h)
    assert msg.header.frame_id == "zed_1_optical"
    ids = np.frombuffer(bytes(msg.data), dtype=np.int32).reshape(h, w)
    labels = json.loads(got["labels"][0].data)
    seen = {labels["instances"][i] for i in np.unique(ids[ids >= 0])}
    assert f"{part.body}/tube" in seen
    assert labels["classes"][labels["instances"].index(f"{part.body}/tube")] == "strut_tube"
    info = got["info"][0]
    assert info.k[0] == pytest.approx(h / 2 / np.tan(np.radians(scene.cameras.camera_fovy("zed_1")) / 2))


def test_ground_truth_poses_match_the_model(make_twin, ros):
    twin_node, probe, executor = ros
    twin = make_twin()
    truth = GroundTruth(twin_node, twin.scene, 10.0)
    poses: dict[str, TransformStamped] = {}
    messages: list[TransformArray] = []

    def take(msg: TransformArray) -> None:
        messages.append(msg)
        poses.update((tf.child_frame_id, tf) for tf in msg.transforms)

    probe.create_subscription(TransformArray, topics.GROUND_TRUTH, take, 10)
    body = next(iter(twin.scene.info.parts.values())).body
    _run(twin, [truth], executor, lambda: body in poses and "ars_y/d405_b_optical" in poses)
    expected = truth.poses()
    assert set(poses) == set(expected)
    pos, _ = twin.scene.body_pose(body)
    got = poses[body].transform.translation
    assert [got.x, got.y, got.z] == pytest.approx(list(pos), abs=1e-6)
    assert poses["tower"].header.frame_id == "world"
    # All objects of one instant in one message.
    assert len(messages[0].transforms) == len(expected)
    assert len({tf.header.stamp.nanosec for tf in messages[0].transforms}) == 1


def test_every_renderer_is_made_before_the_first_frame(make_twin, ros, monkeypatch):
    # Making a renderer holds the interpreter lock for a third of a second or more: mid-run it kept
    # the twin's pty threads from answering every serial driver at once. Frames only render.
    from tlt_sim.model import cameras

    made = []
    real_init = cameras.CameraRenderer.__init__

    def counting_init(self, *args, **kwargs):
        made.append(kwargs.get("antialias", args[3] if len(args) > 3 else True))
        real_init(self, *args, **kwargs)

    monkeypatch.setattr(cameras.CameraRenderer, "__init__", counting_init)
    twin_node, probe, executor = ros
    twin = make_twin()
    cams = CameraStreams(
        twin_node, twin.scene, twin.settings.replace(camera_rate_hz=10.0), load_camera_sensors()
    )
    assert sorted(made) == [False, True], "the multisampled renderer for colour, the exact one for depth"
    made.clear()

    got: list = []
    for camera, stream in (("zed_1", "rgb"), ("zed_1", "depth"), ("ars_x/d405_a", "segmentation")):
        probe.create_subscription(Image, topics.camera_topic(camera, stream), got.append, 10)
    _run(twin, [cams], executor, lambda: len(got) >= 6)
    assert cams.renders["zed_1"] and cams.renders["ars_x/d405_a"]
    assert made == [], "no renderer made while the links are served"
