"""Poses of the pieces a frame shows: the part inspector's pipelines fed from a camera frame, and
the gate that keeps only the detections that can be where a check looks."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tlt_vision import inspection
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.detections import Detection, detections_near
from tlt_vision.node_config import VisionConfig
from tlt_vision.part_inspection import PartInspector

Prior = Callable[[str, np.ndarray], np.ndarray | None]
# Told every frame's observations once posed (tlt_vision.pose_broadcast publishes them).
PosesListener = Callable[[CameraFrame, list[inspection.Observation]], None]


class FramePoser:
    """Certified poses of a frame's detections by ``inspector``'s pipelines.

    Reads the frame's depth, RGB and intrinsics, the camera's depth noise (node.yaml
    ``depth_noise``) and ``held_piece_gate``. An instance that cannot be posed is an observation
    with its reason, never an exception. ``listener``, if given, hears each frame's observations.
    """

    def __init__(
        self, inspector: PartInspector, config: VisionConfig, listener: PosesListener | None = None
    ) -> None:
        self.inspector = inspector
        self.config = config
        self.listener = listener

    def observe(
        self, pipeline: str, detections: list[Detection], frame: CameraFrame, prior: Prior | None = None
    ) -> list[inspection.Observation]:
        """The observations of ``pipeline`` (a part kind, "bay" or "rivet") for ``detections``."""
        observations = self.inspector.observe(
            pipeline,
            detections,
            frame.get("depth"),
            frame.intrinsics,
            frame.get("rgb"),
            prior,
            self.config.depth_noise_of(frame.camera, float(frame.camera_matrix[0, 0])),
        )
        self.tell(frame, observations)
        return observations

    def tell(self, frame: CameraFrame, observations: list[inspection.Observation]) -> None:
        """Hand the listener ``frame``'s observations (those made here, or by the inspector's own
        pipelines for InspectPart)."""
        if self.listener is not None:
            self.listener(frame, observations)

    def within(
        self,
        detections: list[Detection],
        frame: CameraFrame,
        camera_pose: np.ndarray,
        places: np.ndarray,
        piece: str,
        radius: float,
    ) -> list[Detection]:
        """The detections whose cloud lies within ``radius`` and ``piece``'s half size of one of
        ``places`` (in the frame of ``camera_pose``): the others would cost a pose each for nothing."""
        reach = radius + self.inspector.estimators[piece].model.diameter / 2
        return detections_near(detections, frame.get("depth"), frame.intrinsics, camera_pose, places, reach)

    def near(
        self,
        detections: list[Detection],
        frame: CameraFrame,
        camera_pose: np.ndarray,
        places: np.ndarray,
        piece: str,
    ) -> list[Detection]:
        """Only the ``piece`` detections that a check gated by ``held_piece_gate`` around
        ``places`` (world) could count."""
        return self.within(detections, frame, camera_pose, places, piece, self.config.raw["held_piece_gate"])
