"""One camera's images of one instant, as the vision node works on them.

A plain record with no ROS in it, so that what segments frames (the trainer's validation as the
node segments, the benchmarks) imports where rclpy is not installed; :mod:`tlt_vision.camera_frames`
fills it from the camera's topics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tlt_vision.pointcloud import Intrinsics


@dataclass
class CameraFrame:
    camera: str
    stamp: float  # ROS time, s
    frame_id: str
    intrinsics: Intrinsics
    camera_matrix: np.ndarray  # 3x3
    images: dict[str, np.ndarray] = field(default_factory=dict)

    def get(self, stream: str) -> np.ndarray | None:
        return self.images.get(stream)
