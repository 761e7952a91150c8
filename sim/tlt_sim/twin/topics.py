"""Names of the topics the twin publishes besides the drivers' device links (docs/twin.md)."""

from __future__ import annotations

CLOCK = "/clock"
GROUND_TRUTH = "/twin/ground_truth"
SEGMENTATION_LABELS = "/cameras/segmentation_labels"
WORLD_FRAME = "world"
CAMERA_STREAMS = ("rgb", "depth", "segmentation", "camera_info")


def camera_topic(camera: str, stream: str) -> str:
    """``/cameras/<camera>/<stream>``; ``camera`` as in ``tlt_sim.model.names.cameras()``."""
    if stream not in CAMERA_STREAMS:
        raise ValueError(f"unknown camera stream {stream!r} (expected one of {CAMERA_STREAMS})")
    return f"/cameras/{camera}/{stream}"


def camera_frame(camera: str) -> str:
    """Frame id of a camera's optical frame (x right, y down, z forward)."""
    return f"{camera}_optical"


__all__ = [
    "CAMERA_STREAMS",
    "CLOCK",
    "GROUND_TRUTH",
    "SEGMENTATION_LABELS",
    "WORLD_FRAME",
    "camera_frame",
    "camera_topic",
]
