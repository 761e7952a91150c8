"""Where the vision node's instance masks come from (``segmentation.source`` of node.yaml).

* :class:`TwinLabels` reads the twin's ground-truth instance segmentation image (instance id per
  pixel) and its label table (id -> geom instance name and class). Each instance of a part class
  (``tlt_vision.cad.models.CLASSES``) becomes a :class:`~tlt_vision.pipeline.Detection` with
  score 1; the machine, tags and anything else are dropped. It needs the ``segmentation`` stream.
* :class:`MaskRcnnSegmenter` runs the plain-torch Mask R-CNN on the RGB image with trained
  weights; it needs the ``rgb`` stream. The model's configuration and input size are the ones
  the weights' manifest records (``segmentation.inference``). Weights that are missing or do not
  fit the model are refused when it is built (:class:`~tlt_vision.weights.WeightsError` names the
  path and the tensor shape expected). Given a :class:`~tlt_vision.segmentation.depth_split.DepthSplit`,
  its thin-part regions are cut where the frame's depth jumps, pieces of one straight part
  joined again, and, given the parts' radii, pieces not as wide as their part scored down
  (node.yaml ``segmentation.depth_split``). Given a
  :class:`~tlt_vision.segmentation.semantic_trim.SemanticTrim`, the masks of its classes lose the
  pixels the semantic head holds to be a thin part, and those of its ``cores`` keep their masks
  whole with the trimmed mask beside them as the detection's core (``segmentation.semantic_trim``,
  :mod:`~tlt_vision.segmentation.semantic_trim`). Given
  :class:`~tlt_vision.segmentation.overlap.ExclusiveOverlaps`, two masks of one of its classes
  share no pixel but as duplicates of one part (``segmentation.exclusive_overlaps``).
  :meth:`MaskRcnnSegmenter.from_config` builds it as the vision node does.

Both answer ``detect(frame) -> list[Detection]`` or raise ``ValueError`` with the reason (no
labels received, no image). Mask R-CNN also answers ``detect_in(frame, region, scale)``: the
detections in a region of the frame, enlarged first (a strut's second look at a missing fitting's
place, :mod:`tlt_vision.part_inspection`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from tlt_vision.cad.models import CLASSES
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.depth_noise import DepthNoise
from tlt_vision.detections import Detection, detections_from_mask_rcnn
from tlt_vision.segmentation.depth_split import DepthSplit, radii_by_label, split_by_depth
from tlt_vision.segmentation.overlap import ExclusiveOverlaps, resolve_overlaps
from tlt_vision.segmentation.semantic_trim import SemanticTrim, semantic_cores, trim_by_semantic
from tlt_vision.weights import WeightsError

if TYPE_CHECKING:
    from tlt_vision.node_config import VisionConfig
    from tlt_vision.segmentation.model import MaskRCNN

MASK_RCNN_KIND = "mask_rcnn"


class TwinLabels:
    streams = ("segmentation",)

    def __init__(self, labels: Callable[[], tuple[list[str], list[str]] | None]) -> None:
        self.labels = labels

    def detect(self, frame: CameraFrame) -> list[Detection]:
        seg = frame.get("segmentation")
        if seg is None:
            raise ValueError("no segmentation image")
        table = self.labels()
        if table is None:
            raise ValueError("no segmentation labels received from the twin")
        names, classes = table
        out = []
        for i in np.unique(seg[seg >= 0]):
            if i >= len(names) or classes[i] not in CLASSES:
                continue
            out.append(Detection(classes[i], seg == i, 1.0, names[i]))
        return out

    @classmethod
    def detect_render(cls, render: Any, camera: str) -> list[Detection]:
        """The instances of a twin frame rendered in this process (``tlt_sim.model.Scene.render``)
        by its own labels, as the launch set's vision takes the twin's frames over ROS."""
        labels = cls(lambda: (render.labels.instance_names, render.labels.classes))
        images = {"depth": render.depth, "segmentation": render.segmentation, "rgb": render.rgb}
        k = render.intrinsics
        return labels.detect(CameraFrame(camera, 0.0, f"{camera}_optical", k, k.matrix, images))


class MaskRcnnSegmenter:
    streams = ("rgb",)

    def __init__(
        self,
        model: MaskRCNN,
        max_size: int | None,
        min_score: float,
        depth_split: DepthSplit | None = None,
        radii: Mapping[str, float] | None = None,
        trim: SemanticTrim | None = None,
        overlaps: ExclusiveOverlaps | None = None,
        camera_noise: Mapping[str, DepthNoise] | None = None,
        inference: Mapping[str, Any] | None = None,
    ) -> None:
        """Segment with ``model`` at ``max_size`` (the image size it was trained at); ValueError
        for a trim or overlap rule naming a class its semantic head segments."""
        # ``inference`` (MaskRCNN.set_inference) is the node's choice, not the weights'.
        self.model = model
        self.inference = dict(inference or {})
        self.model.set_inference(**self.inference)
        self.cfg = self.model.cfg
        self.max_size = max_size
        self.min_score = min_score
        self.depth_split = depth_split
        # Each camera's depth noise (a fraction of the depth), which the bend cut allows for; a
        # camera not named has depth_split's own.
        self.camera_noise = dict(camera_noise or {})
        self.radii = radii_by_label(self.cfg.classes, radii or {})  # for depth_split's width check
        self.trim, self.overlaps = trim, overlaps
        named = [
            ("semantic_trim.classes", trim and trim.classes),
            ("semantic_trim.cores", trim and trim.cores),
            ("exclusive_overlaps.classes", overlaps and overlaps.classes),
        ]
        for key, names in named:
            if names and (thin := sorted(set(names) & set(self.cfg.semantic_classes))):
                raise ValueError(
                    f"its semantic head segments {', '.join(thin)}, which "
                    f"segmentation.{key} may not name (it acts on box masks)"
                )

    @classmethod
    def load(cls, weights: str | Path, min_score: float, **options: Any) -> MaskRcnnSegmenter:
        """The segmenter of trained ``weights``: the model's configuration and image size from
        their manifest, as trained; WeightsError naming the path for weights that do not fit."""
        from tlt_vision.segmentation.inference import load_mask_rcnn

        model, manifest = load_mask_rcnn(weights)
        try:
            return cls(model, manifest["settings"].get("max_size"), min_score, **options)
        except ValueError as exc:
            raise WeightsError(weights, str(exc)) from exc

    @classmethod
    def from_config(
        cls,
        config: VisionConfig,
        weights: str | Path | None = None,
        *,
        model: MaskRCNN | None = None,
        max_size: int | None = None,
    ) -> MaskRcnnSegmenter:
        """The segmenter of a vision node run with ``config``, with other ``weights`` if given, or
        around a ``model`` in memory (one being trained) that sees images of ``max_size``."""
        from tlt_vision.cad.models import thin_part_radii
        from tlt_vision.node_config import repo_path

        options = {
            "depth_split": config.depth_split,
            "radii": thin_part_radii(),
            "trim": config.semantic_trim,
            "overlaps": config.exclusive_overlaps,
            "camera_noise": {camera: config.depth_noise_of(camera) for camera in config.cameras},
            "inference": config.mask_rcnn_inference,
        }
        if model is not None:
            return cls(model, max_size, config.score_floor, **options)
        return cls.load(
            weights or repo_path(config.raw["segmentation"]["weights"]), config.score_floor, **options
        )

    def detect(self, frame: CameraFrame) -> list[Detection]:
        from tlt_vision.segmentation.inference import detect_rgb

        rgb = frame.get("rgb")
        if rgb is None:
            raise ValueError("no RGB image")
        result = self.refine(
            detect_rgb(self.model, rgb, self.max_size), frame.get("depth"), frame.camera_matrix, frame.camera
        )
        return detections_from_mask_rcnn(result, self.cfg.classes, self.min_score)

    def refine(
        self,
        result: dict[str, Any],
        depth: np.ndarray | None,
        camera_matrix: np.ndarray | None,
        camera: str = "",
    ) -> dict[str, Any]:
        """The model's ``result`` for one frame of ``camera`` with its box-branch masks made
        exclusive, its thin parts cut by depth (allowing for that camera's noise) and its
        box-branch masks trimmed, as configured."""
        result = self._exclusive(result)
        split = self.depth_split
        if split is not None:
            if camera in self.camera_noise:
                split = replace(split, depth_noise=self.camera_noise[camera])
            result = split_by_depth(result, depth, self.cfg.semantic_labels, split, camera_matrix, self.radii)
        return self._trimmed(result)

    def _exclusive(self, result: dict[str, Any]) -> dict[str, Any]:
        """``result`` with the configured overlaps resolved, and without its ``mask_probs``: what
        comes after selects and cuts masks, and would leave them behind."""
        if self.overlaps is not None:
            result = resolve_overlaps(result, self.overlaps.labels(self.cfg.classes), self.overlaps.duplicate)
        return {key: value for key, value in result.items() if key != "mask_probs"}

    def _trimmed(self, result: dict[str, Any]) -> dict[str, Any]:
        """``result`` with the trim's classes trimmed and its cores given (after the trim, which
        may drop detections)."""
        if self.trim is None:
            return result
        classes, thin = self.cfg.classes, self.cfg.semantic_labels
        result = trim_by_semantic(result, self.trim.labels(classes), thin, self.trim.above)
        return semantic_cores(result, self.trim.core_labels(classes), thin, self.trim.above)

    def detect_in(
        self, frame: CameraFrame, region: tuple[int, int, int, int], scale: float
    ) -> list[Detection]:
        """Detections in ``region`` (x0, y0, x1, y1 pixels) of the frame's RGB, enlarged ``scale``
        times first (a part too small or too cluttered for the whole frame), with masks of the
        whole frame's size. Not cut by depth: it looks for end fittings, a box-branch class."""
        from tlt_vision.segmentation.inference import detect_rgb

        rgb = frame.get("rgb")
        if rgb is None:
            return []
        h, w = rgb.shape[:2]
        x0, y0, x1, y1 = max(0, region[0]), max(0, region[1]), min(w, region[2]), min(h, region[3])
        if x1 <= x0 or y1 <= y0:
            return []
        crop = rgb[y0:y1, x0:x1]
        size = (max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale)))
        result = detect_rgb(self.model, cv2.resize(crop, size, interpolation=cv2.INTER_LINEAR), None)

        def in_frame(crop_mask: np.ndarray) -> np.ndarray:
            small = cv2.resize(crop_mask.astype(np.uint8), (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
            mask = np.zeros(rgb.shape[:2], dtype=bool)
            mask[y0:y1, x0:x1] = small >= 0.5
            return mask

        return [
            replace(d, mask=in_frame(d.mask), core=None if d.core is None else in_frame(d.core))
            for d in detections_from_mask_rcnn(
                self._trimmed(self._exclusive(result)), self.cfg.classes, self.min_score
            )
        ]


__all__ = ["MASK_RCNN_KIND", "MaskRcnnSegmenter", "TwinLabels"]
