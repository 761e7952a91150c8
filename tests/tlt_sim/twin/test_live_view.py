"""The twin's live view (tlt_sim.twin.live_view): the transform tree of the running model, the
shapes of the parts, and a twin process that publishes /tf, /tf_static and /robot_description."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from tlt_sim.model import names, urdf
from tlt_sim.model.generate import RIVET_GROUP
from tlt_sim.model.scene import Scene
from tlt_sim.twin import live_view
from visualization_msgs.msg import Marker

from tlt_common import ros_names
from tlt_common.geometry.transforms import quaternion_to_rotation
from tlt_common.ros.transform_messages import TF_STATIC_QOS


def _pose(m) -> tuple[np.ndarray, np.ndarray]:
    t, q = m.transform.translation, m.transform.rotation
    return np.array([t.x, t.y, t.z]), quaternion_to_rotation([q.x, q.y, q.z, q.w])


def test_static_and_moving_transforms_place_every_body_where_the_twin_has_it(tmp_path):
    with Scene(out_dir=tmp_path / "model") as scene:
        scene.pose_arm("ars_y", np.array([-0.4, -1.0, 1.2, -0.8, -1.4, 0.9]))
        scene.step()
        tree = urdf.links(scene.model)
        edges = {}
        for msg in (
            live_view.static_transforms(scene),
            live_view.MovingTransforms(scene, tree).at(scene.time),
        ):
            for m in msg.transforms:
                assert m.child_frame_id not in edges, f"{m.child_frame_id} has two parents"
                edges[m.child_frame_id] = (m.header.frame_id, *_pose(m))

        def world(frame: str) -> tuple[np.ndarray, np.ndarray]:
            if frame == "world":
                return np.zeros(3), np.eye(3)
            parent, p, r = edges[frame]
            pp, pr = world(parent)
            return pp + pr @ p, pr @ r

        for body in ("ars_y/ee", "ars_y/jaw_b", "lifter_carriage_2", "camera_mount_1", "payload"):
            p, r = scene.body_pose(body)
            assert np.allclose(world(body)[0], p, atol=1e-6), body
            assert np.allclose(world(body)[1], r, atol=1e-6), body
        for camera in names.cameras():
            p, r = scene.camera_pose(camera)
            assert np.allclose(world(names.optical_frame(camera))[0], p, atol=1e-6), camera
        assert np.allclose(world(live_view.TOWER_FRAME)[0], scene.tower_pose()[0])
        for part in scene.info.parts.values():
            assert edges[part.body][0] == "world"
            assert np.allclose(edges[part.body][1], scene.body_pose(part.body)[0])
        clear, *markers = live_view.free_body_markers(scene.model).markers
        assert clear.action == Marker.DELETEALL
        parts = {m.header.frame_id for m in markers}
        assert parts == {"payload", *(p.body for p in scene.info.parts.values())}
        assert all(m.frame_locked and m.scale.x > 0 and m.color.a > 0 for m in markers)


def test_a_rivet_set_in_the_tower_appears_among_the_markers(tmp_path):
    with Scene(out_dir=tmp_path / "model") as scene:
        strut = next(p for p in scene.info.parts.values() if p.kind == "vertical")

        def rivets_shown() -> int:
            markers = live_view.free_body_markers(scene.model).markers
            return sum(m.ns == strut.body and m.color.r > 0.8 and m.color.g < 0.2 for m in markers)

        before = rivets_shown()
        rivet = scene.model.geom(f"{strut.body}/rivet_a").id
        scene.model.geom_group[rivet] = RIVET_GROUP  # as Assembly.rivet shows a rivet it sets
        assert rivets_shown() > before


def test_a_twin_process_publishes_tf_its_static_frames_and_its_robot_description(tmp_path):
    args = ["--rtf", "1", "--run-dir", str(tmp_path / "run"), "--duration", "60"]
    args += ["--ur-x-host", "127.0.76.2", "--ur-y-host", "127.0.76.3"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "tlt_sim.twin.main", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ),
    )
    ctx = Context()
    rclpy.init(context=ctx)
    node = Node("live_view_probe", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    got: dict[str, list] = {"tf": [], "static": [], "description": []}
    node.create_subscription(TFMessage, ros_names.TF, got["tf"].append, 100)
    node.create_subscription(TFMessage, ros_names.TF_STATIC, got["static"].append, TF_STATIC_QOS)
    node.create_subscription(String, ros_names.ROBOT_DESCRIPTION, got["description"].append, TF_STATIC_QOS)
    try:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not (
            len(got["tf"]) >= 3 and got["static"] and got["description"]
        ):
            executor.spin_once(timeout_sec=0.05)
            assert proc.poll() is None, proc.stdout.read()
    finally:
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=30)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    assert proc.returncode == 0, output
    assert len(got["tf"]) >= 3 and got["static"] and got["description"], output
    moving = {m.child_frame_id for m in got["tf"][-1].transforms}
    assert {"payload", "lifter_carriage_0", "ars_x/link_6", "ars_y/jaw_a"} <= moving
    assert names.optical_frame("zed_1") in {m.child_frame_id for m in got["static"][0].transforms}
    joints = {j.get("name") for j in ET.fromstring(got["description"][0].data).findall("joint")}
    assert set(names.all_actuated_joints()) <= joints
