"""Fresh camera frames on request: subscribe, take the first complete frame, unsubscribe.

The twin renders a camera only while one of its image topics has a subscriber, and rendering is
expensive, so a request subscribes to the streams it needs (``rgb``, ``depth``, ``segmentation``
under ``topics.image`` of ``config/vision/node.yaml``, with ``camera_info``) only while it waits.
:meth:`FrameGrabber.grab` returns a :class:`CameraFrame` whose images all carry one stamp no
earlier than the request (a frame rendered after the request was made), or raises
:class:`NoFrame` saying what did not arrive within the wall-clock ``timeout``. The subscriptions
are always destroyed before it returns.

Decoding follows sensor_msgs/Image: rgb8 (H, W, 3) uint8, 32FC1 (H, W) float32 metres, 32SC1
(H, W) int32; rows are read with the message's ``step``. A wrong encoding or size is a NoFrame.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Sequence

import numpy as np
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

from tlt_vision.camera_frame import CameraFrame
from tlt_vision.pointcloud import Intrinsics

IMAGE_STREAMS = ("rgb", "depth", "segmentation")
_ENCODINGS = {
    "rgb": ("rgb8", np.uint8, 3),
    "depth": ("32FC1", np.float32, 1),
    "segmentation": ("32SC1", np.int32, 1),
}


class NoFrame(RuntimeError):
    """No usable frame in time; the message says which stream was missing or wrong."""


def stamp_of(msg: object) -> float:
    s = msg.header.stamp  # type: ignore[attr-defined]
    return s.sec + s.nanosec * 1e-9


def decode_image(msg: Image, stream: str) -> np.ndarray:
    """The image of ``msg`` as numpy; NoFrame when its encoding or size is not the stream's."""
    encoding, dtype, channels = _ENCODINGS[stream]
    if msg.encoding != encoding:
        raise NoFrame(f"{stream} image has encoding {msg.encoding!r}, expected {encoding!r}")
    item = np.dtype(dtype).itemsize * channels
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = bytes(msg.data)
    if step < w * item or len(data) < step * h:
        raise NoFrame(f"{stream} image of {w}x{h} has {len(data)} bytes with step {step}")
    rows = np.frombuffer(data, dtype=np.uint8)[: step * h].reshape(h, step)[:, : w * item]
    arr = np.ascontiguousarray(rows).view(dtype)
    return arr.reshape(h, w, channels) if channels > 1 else arr.reshape(h, w)


class SegmentationLabels:
    """The twin's instance id -> (instance name, class) table, from its latched labels topic."""

    def __init__(self, node: Node, topic: str, group) -> None:
        self._lock = threading.Lock()
        self._table: tuple[list[str], list[str]] | None = None
        self._have = threading.Event()
        latched = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        node.create_subscription(String, topic, self._on_labels, latched, callback_group=group)

    def _on_labels(self, msg: String) -> None:
        try:
            data = json.loads(msg.data)
            table = (list(data["instances"]), list(data["classes"]))
        except (ValueError, KeyError, TypeError):
            return  # a malformed table is ignored; requests then say no labels arrived
        with self._lock:
            self._table = table
        self._have.set()

    def wait(self, timeout: float) -> tuple[list[str], list[str]] | None:
        self._have.wait(max(timeout, 0.0))
        with self._lock:
            return self._table


class _Pending:
    """Messages of one request, by stamp, until one stamp has every stream."""

    def __init__(self, streams: Sequence[str], since: float) -> None:
        self.streams = (*streams, "camera_info")
        self.since = since
        self.by_stamp: dict[float, dict[str, object]] = {}
        self.done = threading.Event()
        self.complete: dict[str, object] | None = None
        self.stale = 0  # messages older than the request
        self.lock = threading.Lock()

    def add(self, stream: str, msg: object) -> None:
        t = stamp_of(msg)
        with self.lock:
            if self.complete is not None:
                return
            if t + 1e-9 < self.since:
                self.stale += 1
                return
            got = self.by_stamp.setdefault(t, {})
            got[stream] = msg
            if all(s in got for s in self.streams):
                self.complete = got
                self.done.set()

    def missing(self) -> list[str]:
        with self.lock:
            best = max(self.by_stamp.values(), key=len, default={})
            return [s for s in self.streams if s not in best]


class FrameGrabber:
    """Takes one fresh frame of a camera per call (see the module docstring)."""

    def __init__(self, node: Node, image_topic: str) -> None:
        self.node = node
        self.image_topic = image_topic
        self.group = ReentrantCallbackGroup()
        self.qos = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)

    def topic(self, camera: str, stream: str) -> str:
        return self.image_topic.format(camera=camera, stream=stream)

    def grab(self, camera: str, streams: Sequence[str], since: float, timeout: float) -> CameraFrame:
        """A frame of ``camera`` with ``streams`` stamped at or after ROS time ``since``."""
        pending = _Pending(streams, since)
        subs = []
        try:
            for stream in pending.streams:
                kind = CameraInfo if stream == "camera_info" else Image
                subs.append(
                    self.node.create_subscription(
                        kind,
                        self.topic(camera, stream),
                        lambda msg, s=stream: pending.add(s, msg),
                        self.qos,
                        callback_group=self.group,
                        # No QoS event handlers: an executor building its wait set while this
                        # thread destroys the subscription fails on a destroyed event handler.
                        event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False),
                    )
                )
            deadline = time.monotonic() + timeout
            while not pending.done.wait(0.05):
                if time.monotonic() >= deadline:
                    missing = ", ".join(pending.missing())
                    older = f" ({pending.stale} older message(s) ignored)" if pending.stale else ""
                    raise NoFrame(
                        f"no camera frame from {camera} within {timeout:.1f} s: missing {missing}{older}"
                    )
        finally:
            for sub in subs:
                self.node.destroy_subscription(sub)
        msgs = pending.complete or {}
        info: CameraInfo = msgs["camera_info"]  # type: ignore[assignment]
        k = np.asarray(info.k, dtype=float).reshape(3, 3)
        if not (k[0, 0] > 0 and k[1, 1] > 0):
            raise NoFrame(f"camera_info of {camera} has no valid focal length")
        images = {s: decode_image(msgs[s], s) for s in streams}  # type: ignore[arg-type]
        for s, img in images.items():
            if img.shape[:2] != (info.height, info.width):
                raise NoFrame(
                    f"{s} image is {img.shape[1]}x{img.shape[0]}, camera_info {info.width}x{info.height}"
                )
        return CameraFrame(camera, stamp_of(info), info.header.frame_id, Intrinsics.from_matrix(k), k, images)


__all__ = ["IMAGE_STREAMS", "CameraFrame", "FrameGrabber", "NoFrame", "SegmentationLabels", "decode_image"]
