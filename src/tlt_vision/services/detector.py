"""What a request sees in a frame: the node's segmenter (``segmentation.source``: the twin's labels
or Mask R-CNN) at the node's scores."""

from __future__ import annotations

from typing import Any, Protocol

from tlt_vision.camera_frame import CameraFrame
from tlt_vision.camera_frames import NoFrame
from tlt_vision.detections import Detection
from tlt_vision.node_config import VisionConfig
from tlt_vision.part_inspection import LookCloser


class Segmenter(Protocol):
    """:class:`~tlt_vision.segmentation_source.TwinLabels` or
    :class:`~tlt_vision.segmentation_source.MaskRcnnSegmenter` (which also has ``detect_in``)."""

    streams: tuple[str, ...]

    def detect(self, frame: CameraFrame) -> list[Detection]: ...


class Detector:
    """A frame's detections by ``segmenter``.

    Reads node.yaml's ``segmentation`` (``min_score``; ``second_look_closer``, the closer look).
    Raises :class:`NoFrame` when the segmenter refuses the frame. ``segmenter`` may be replaced
    (the tests segment as Mask R-CNN would from the twin's labels).
    """

    def __init__(self, segmenter: Segmenter | Any, config: VisionConfig) -> None:
        self.segmenter = segmenter
        self.config = config
        self.min_score: float = config.raw["segmentation"]["min_score"]

    def streams(self) -> tuple[str, ...]:
        """The streams a frame needs: its depth and what the segmenter reads."""
        return ("depth", *self.segmenter.streams)

    def detect(self, frame: CameraFrame, doubtful: bool = False) -> list[Detection]:
        """The frame's detections scoring ``min_score`` or more; with ``doubtful`` down to the
        second look's score too (InspectPart's strut decides which it looks at again)."""
        try:
            detections = self.segmenter.detect(frame)
        except ValueError as exc:
            raise NoFrame(f"segmentation failed: {exc}") from exc
        if doubtful:
            return detections
        return [d for d in detections if d.score >= self.min_score]

    def closer(self, frame: CameraFrame) -> LookCloser | None:
        """The strut's closer look at a region of ``frame`` (``segmentation.second_look_closer``):
        Mask R-CNN only; the twin's labels leave nothing unseen to look for."""
        closer = self.config.raw["segmentation"]["second_look_closer"]
        if closer is None or not hasattr(self.segmenter, "detect_in"):
            return None
        return lambda region: self.segmenter.detect_in(frame, region, closer["scale"])
