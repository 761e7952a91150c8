"""Names of the topics the twin publishes besides the drivers' device links (docs/twin.md)."""

from __future__ import annotations

from tlt_sim.model import names

CLOCK = "/clock"
GROUND_TRUTH = "/twin/ground_truth"
SEGMENTATION_LABELS = "/cameras/segmentation_labels"
# visualization_msgs/MarkerArray, latched: the payload's and the parts' shapes (tlt_sim.twin.live_view).
MARKERS = "/twin/markers"
WORLD_FRAME = "world"
CAMERA_STREAMS = ("rgb", "depth", "segmentation", "camera_info")


def camera_topic(camera: str, stream: str) -> str:
    """``/cameras/<camera>/<stream>``; ``camera`` as in ``tlt_sim.model.names.cameras()``."""
    if stream not in CAMERA_STREAMS:
        raise ValueError(f"unknown camera stream {stream!r} (expected one of {CAMERA_STREAMS})")
    return f"/cameras/{camera}/{stream}"


def camera_frame(camera: str) -> str:
    """Frame id of a camera's optical frame (x right, y down, z forward)."""
    return names.optical_frame(camera)


__all__ = [
    "CAMERA_STREAMS",
    "CLOCK",
    "GROUND_TRUTH",
    "MARKERS",
    "SEGMENTATION_LABELS",
    "WORLD_FRAME",
    "camera_frame",
    "camera_topic",
]
