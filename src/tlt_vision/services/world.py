"""Where a request's pieces are in the world: the tower's frame while a bay is built, an estimate
moved from its camera into the world, and when two pieces seen are one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tlt_common.mission.schema import Mission
from tlt_vision.node_config import VisionConfig
from tlt_vision.pose.estimator import PoseEstimate

SAME_PIECE_M = 0.02  # pieces seen by two cameras closer than this are one piece


def tower_origin(config: VisionConfig, mission: Mission, bay: int) -> np.ndarray:
    """Where the mission's tower frame stands (world) while bay ``bay`` is built and tested
    (node.yaml ``site``): the lifter holds the bays above at the build level, bay ``bay``'s frame on
    the floor."""
    site = config.raw["site"]
    return np.asarray(site["base_origin"]) + np.array(
        [0.0, 0.0, site["build_level"] + bay * mission.bay_height]
    )


def in_world(e: PoseEstimate, camera_pose: np.ndarray) -> PoseEstimate:
    """The estimate moved from the camera frame to the world."""
    r, t = camera_pose[:3, :3], camera_pose[:3, 3]
    return replace(
        e,
        rotation=r @ e.rotation,
        translation=r @ e.translation + t,
        keypoints=e.keypoints @ r.T + t,
    )
