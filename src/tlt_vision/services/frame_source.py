"""The frames a vision request reads: the camera a requested name means, the request's time, and
one fresh frame of a camera within it (:class:`~tlt_vision.camera_frames.FrameGrabber` subscribes
only while it waits)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

from tlt_vision.camera_frame import CameraFrame
from tlt_vision.camera_frames import FrameGrabber, NoFrame
from tlt_vision.node_config import VisionConfig


class FrameSource:
    """Fresh frames of the node's cameras for one request.

    Reads node.yaml's ``cameras``, ``camera_aliases`` and ``timeouts`` (``request_s``, a request's
    time; ``frame_s``, the longest wait for one frame) and ``clock`` (ROS time, s: a frame must be
    taken after the request came). Raises :class:`NoFrame` for an unknown camera, a request out of
    time, or no frame in time.
    """

    def __init__(self, grabber: FrameGrabber, config: VisionConfig, clock: Callable[[], float]) -> None:
        self.grabber = grabber
        self.config = config
        self.clock = clock

    def camera(self, name: str) -> str:
        """The camera ``name`` means (a camera or an alias of one)."""
        camera = self.config.resolve_camera(name)
        if camera is None:
            known = ", ".join([*self.config.cameras, *self.config.raw["camera_aliases"]])
            raise NoFrame(f"unknown camera {name!r} (known: {known})")
        return camera

    def deadline(self) -> float:
        """When a request starting now must be answered (``time.monotonic()`` s)."""
        return time.monotonic() + self.config.raw["timeouts"]["request_s"]

    def grab(self, camera: str, streams: Sequence[str], deadline: float) -> CameraFrame:
        """``camera``'s next frame with ``streams``, waiting at most ``frame_s`` and not past
        ``deadline``."""
        timeout = min(self.config.raw["timeouts"]["frame_s"], deadline - time.monotonic())
        if timeout <= 0:
            raise NoFrame(f"no time left for a frame from {camera}")
        return self.grabber.grab(camera, streams, self.clock(), timeout)
