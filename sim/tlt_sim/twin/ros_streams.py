"""What the twin publishes besides its device links: /clock, camera images and ground-truth poses.

Topics (names in :mod:`tlt_sim.twin.topics`):

* ``/clock`` (``rosgraph_msgs/Clock``): the sim time after every sync period;
* per camera (``zed_1``, ``zed_2``, ``ars_x/d405_a`` ...) under ``/cameras/<camera>/``: ``rgb``
  (``sensor_msgs/Image`` rgb8), ``depth`` (32FC1, metres along the optical axis, 0 where nothing),
  ``segmentation`` (32SC1 instance ids, -1 where nothing) and ``camera_info``
  (``sensor_msgs/CameraInfo``, plumb-bob with zero distortion). A camera renders only while one
  of its image topics has a subscriber (the publisher's subscription count), at most
  ``rate_hz`` frames per simulated second, and only the images someone subscribes to. Colour and
  depth are what the camera's sensor model (:mod:`tlt_sim.model.camera_sensor`) makes of the
  render; the segmentation stays exact (the twin's labels, for judging and diagnosis);
* ``/cameras/segmentation_labels`` (``std_msgs/String``, transient local): JSON
  ``{"instances": [...], "classes": [...]}``, instance id -> geom instance name and its class;
* ``/twin/ground_truth`` (``tlt_interfaces/TransformArray``, while subscribed,
  ``ground_truth_rate_hz`` per simulated second): one ``TransformStamped`` per object, all of one
  instant, ``header.frame_id`` ``world``, ``child_frame_id`` the payload (``tower``), every part
  body (``part/<dispenser>/<index>``), each EE (``ars_x/ee``) and each camera's optical frame
  (``<camera>_optical``). One message per publication: one per object (270 a simulated second)
  cost the twin and every subscriber (the recorder) a callback each.

All stamps are sim time. Everything here runs on the simulation thread (the Scene is not
thread-safe).
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter

import numpy as np
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String
from tlt_interfaces.msg import TransformArray

from tlt_common.geometry.transforms import rotation_to_quaternion
from tlt_common.ros.stamps import set_stamp
from tlt_sim.model import names
from tlt_sim.model.camera_sensor import CameraSensors
from tlt_sim.model.scene import Scene
from tlt_sim.twin import topics
from tlt_sim.twin.settings import TwinSettings

IMAGE_STREAMS = ("rgb", "depth", "segmentation")


def _next_due(due: float, period: float, t: float) -> float:
    """The next time on the rate's grid; after a pause (nobody subscribed) a new grid from ``t``."""
    due += period
    return due if due > t + 1e-9 else t + period


class ClockPublisher:
    def __init__(self, node: Node) -> None:
        self._pub = node.create_publisher(Clock, topics.CLOCK, 10)
        self._msg = Clock()

    def publish(self, t: float) -> None:
        set_stamp(self._msg.clock, t)
        self._pub.publish(self._msg)


class CameraStreams:
    """Renders and publishes the model's cameras on demand, through ``sensors`` (the cameras' models;
    exact frames where ``sensors.realistic`` is false). ``renders`` counts frames per camera, and
    frame n of a camera draws its sensor effects from (seed, camera, n)."""

    def __init__(self, node: Node, scene: Scene, settings: TwinSettings, sensors: CameraSensors) -> None:
        self.scene = scene
        self.settings = settings
        self.sensors = sensors
        self.period = 1.0 / settings.camera_rate_hz
        self.renders: Counter[str] = Counter()
        qos = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
        self._pubs: dict[str, dict[str, object]] = {}
        self._next: dict[str, float] = {}
        for camera in names.cameras():
            self._pubs[camera] = {
                stream: node.create_publisher(
                    CameraInfo if stream == "camera_info" else Image, topics.camera_topic(camera, stream), qos
                )
                for stream in topics.CAMERA_STREAMS
            }
            self._next[camera] = 0.0
        latched = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        self._labels = node.create_publisher(String, topics.SEGMENTATION_LABELS, latched)
        self._labels_sent = False
        # The renderers every camera's frames need, made now, before the device links are served:
        # making one holds the interpreter lock for a third of a second (longer on a loaded
        # machine), and made on the first frame mid-run it would starve the pty threads past every
        # serial driver's packet timeout at once. Rendering itself lets go of the lock.
        width = max(settings.camera_size(camera)[0] for camera in names.cameras())
        height = max(settings.camera_size(camera)[1] for camera in names.cameras())
        for antialias in {False, settings.camera_antialias}:  # depth and ids come from single samples
            scene.renderer(width, height, antialias)

    def _publish_labels(self) -> None:
        labels = self.scene.renderer(antialias=self.settings.camera_antialias).labels
        self._labels.publish(
            String(data=json.dumps({"instances": labels.instance_names, "classes": labels.classes}))
        )
        self._labels_sent = True

    def publish_due(self, t: float) -> None:
        """Render and publish every camera that is subscribed and due at sim time ``t``."""
        for camera, pubs in self._pubs.items():
            wanted = {s for s in IMAGE_STREAMS if pubs[s].get_subscription_count() > 0}
            if not wanted or t + 1e-9 < self._next[camera]:
                continue
            self._next[camera] = _next_due(self._next[camera], self.period, t)
            if not self._labels_sent:
                self._publish_labels()
            width, height = self.settings.camera_size(camera)
            realistic = self.sensors.realistic
            # The depth's specular holes are found on the colours: rendered with the depth (one
            # cheap pass without multisampling) when nobody asks for the colours.
            colour = "rgb" in wanted or (realistic and "depth" in wanted)
            frame = self.scene.render(
                camera,
                width,
                height,
                depth="depth" in wanted,
                segmentation="segmentation" in wanted,
                rgb=colour,
                antialias=self.settings.camera_antialias and "rgb" in wanted,
            )
            if realistic:
                rng = self.sensors.frame_rng(camera, self.renders[camera])
                rgb, depth = self.sensors.for_camera(camera).apply(
                    frame.rgb, frame.depth, frame.intrinsics.fx, rng
                )
                frame = dataclasses.replace(frame, rgb=rgb, depth=depth)
            self.renders[camera] += 1
            frame_id = topics.camera_frame(camera)
            if "rgb" in wanted:
                pubs["rgb"].publish(_image(frame.rgb, "rgb8", 3 * width, t, frame_id))
            if "depth" in wanted:
                pubs["depth"].publish(_image(frame.depth.astype(np.float32), "32FC1", 4 * width, t, frame_id))
            if "segmentation" in wanted:
                pubs["segmentation"].publish(
                    _image(frame.segmentation.astype(np.int32), "32SC1", 4 * width, t, frame_id)
                )
            pubs["camera_info"].publish(_camera_info(frame.intrinsics, t, frame_id))


def _image(array: np.ndarray, encoding: str, step: int, t: float, frame_id: str) -> Image:
    msg = Image()
    set_stamp(msg.header.stamp, t)
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(array.shape[0]), int(array.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = step
    msg.data = np.ascontiguousarray(array).tobytes()
    return msg


def _camera_info(k, t: float, frame_id: str) -> CameraInfo:
    msg = CameraInfo()
    set_stamp(msg.header.stamp, t)
    msg.header.frame_id = frame_id
    msg.width, msg.height = k.width, k.height
    msg.distortion_model = "plumb_bob"
    msg.d = [0.0] * 5
    msg.k = [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return msg


class GroundTruth:
    """Poses of the payload, the parts, the EEs and the cameras, while subscribed."""

    def __init__(self, node: Node, scene: Scene, rate_hz: float) -> None:
        self.scene = scene
        self.period = 1.0 / rate_hz
        self._pub = node.create_publisher(TransformArray, topics.GROUND_TRUTH, 10)
        self._next = 0.0

    def poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Object name -> (world position, rotation matrix), as published."""
        s = self.scene
        out = {"tower": s.tower_pose()}
        for part in s.info.parts.values():
            out[part.body] = s.body_pose(part.body)
        for arm in names.ARMS:
            out[names.ee_body(arm)] = s.body_pose(names.ee_body(arm))
        for camera in names.cameras():
            out[topics.camera_frame(camera)] = s.camera_pose(camera)
        return out

    def publish_due(self, t: float) -> None:
        if self._pub.get_subscription_count() == 0 or t + 1e-9 < self._next:
            return
        self._next = _next_due(self._next, self.period, t)
        out = TransformArray()
        for name, (pos, rot) in self.poses().items():
            msg = TransformStamped()
            set_stamp(msg.header.stamp, t)
            msg.header.frame_id = topics.WORLD_FRAME
            msg.child_frame_id = name
            msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = (
                float(v) for v in pos
            )
            q = msg.transform.rotation
            q.x, q.y, q.z, q.w = rotation_to_quaternion(rot)
            out.transforms.append(msg)
        self._pub.publish(out)


__all__ = ["IMAGE_STREAMS", "CameraStreams", "ClockPublisher", "GroundTruth"]
