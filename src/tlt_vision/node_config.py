"""The vision node's configuration: ``config/vision/node.yaml``, validated on load.

Reads the YAML file (with ``tlt_common.config_schema``) against :mod:`tlt_vision.node_config_schema`
(the schema and the checks across keys it cannot state) and gives :class:`VisionConfig`, whose
accessors build the pipeline's settings objects from it. Paths are resolved against the repository
root. Any problem raises :class:`~tlt_common.config_schema.ConfigError` naming the file, the key and
the reason; nothing is returned half-checked.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.config_schema import load_yaml, validate
from tlt_common.geometry.transforms import pose_matrix, rpy_matrix
from tlt_vision.depth_noise import DepthNoise
from tlt_vision.node_config_schema import MODEL_NAMES, SCHEMA, SEGMENTATION_SOURCES, check_across_keys
from tlt_vision.pointcloud import Detached
from tlt_vision.pose.axial_ends import AxialEnds
from tlt_vision.pose.axial_slide import AxialSlide
from tlt_vision.pose.free_space import FreeSpace
from tlt_vision.pose.parting import Parting
from tlt_vision.segmentation.depth_split import DepthSplit
from tlt_vision.segmentation.overlap import ExclusiveOverlaps
from tlt_vision.segmentation.semantic_trim import SemanticTrim

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_CONFIG = REPO_ROOT / "config" / "vision" / "node.yaml"


def pose_of(entry: dict[str, Any]) -> np.ndarray:
    """4x4 pose of a ``{position, rpy}`` entry (rpy as URDF: R = Rz(yaw) Ry(pitch) Rx(roll))."""
    return pose_matrix(entry["position"], rpy_matrix(entry["rpy"]))


def repo_path(path: str) -> Path:
    p = Path(path)
    return p if p.is_absolute() else REPO_ROOT / p


@dataclass(frozen=True)
class VisionConfig:
    """The validated file; ``raw`` holds every key with defaults filled in."""

    raw: dict[str, Any]
    source: str

    @property
    def cameras(self) -> list[str]:
        return [*self.raw["lifter_cameras"], *self.raw["ee_cameras"]]

    def resolve_camera(self, name: str) -> str | None:
        """The configured camera ``name`` means (directly or through an alias), or None."""
        name = self.raw["camera_aliases"].get(name, name)
        return name if name in self.cameras else None

    @property
    def depth_noise(self) -> DepthNoise:
        """The noise of the cameras ``depth_noise.cameras`` does not name."""
        raw = self.raw["depth_noise"]
        return DepthNoise(
            raw["fraction"], raw["window"], raw["max_allowance"], precision_sigmas=raw["precision_sigmas"]
        )

    def with_exact_depth(self) -> VisionConfig:
        """This configuration with every camera's depth taken as exact: for the twin's exact
        cameras (``tlt twin run --camera-model exact``), a diagnosis."""
        raw = copy.deepcopy(self.raw)
        raw["depth_noise"].update(fraction=0.0, cameras={})
        return VisionConfig(raw, self.source)

    def with_segmentation(self, source: str) -> VisionConfig:
        """This configuration with masks from ``source`` (``segmentation.source``), checked as a
        file's value would be (``mask_rcnn`` needs ``segmentation.weights``)."""
        raw = copy.deepcopy(self.raw)
        raw["segmentation"]["source"] = source
        check_across_keys(raw, f"{self.source} with --segmentation {source}")
        return VisionConfig(raw, self.source)

    def depth_noise_of(self, camera: str, fx: float | None = None) -> DepthNoise:
        """The noise of the configured ``camera``'s depth; given the frame's focal length ``fx``
        (pixels), with the share of it that neighbouring pixels' sharing leaves after the filter."""
        default = self.depth_noise
        own = self.raw["depth_noise"]["cameras"].get(camera)
        if own is None:
            return default
        if not isinstance(own, dict):
            return replace(default, fraction=own)
        noise = replace(
            default,
            **{k: float(own.get(k, 0.0)) for k in ("fraction", "per_m2", "correlation_px", "focal_px")},
        )
        return noise if fx is None else noise.for_frame(fx)

    @property
    def free_space(self) -> FreeSpace:
        return FreeSpace(**self.raw["free_space"])

    @property
    def axial_slide(self) -> AxialSlide | None:
        raw = self.raw["axial_slide"]
        return AxialSlide(**{**raw, "classes": tuple(raw["classes"])}) if raw["classes"] else None

    @property
    def axial_ends(self) -> AxialEnds | None:
        raw = self.raw["axial_ends"]
        if not raw["classes"]:
            return None
        return AxialEnds(**{**raw, "classes": tuple(raw["classes"]), "offsets_px": tuple(raw["offsets_px"])})

    @property
    def pipeline_options(self) -> dict[str, Any]:
        """The keyword arguments of :class:`tlt_vision.pipeline.PartPipeline` this file sets."""
        raw = self.raw
        return {
            "max_points": raw["max_points"],
            "keep_border_below": raw["keep_border_below"],
            "free_space": self.free_space,
            "detached": self.detached,
            "axial_slide": self.axial_slide,
            "axial_ends": self.axial_ends,
            "depth_noise": self.depth_noise,
            "parting": self.parting,
        }

    @property
    def mask_rcnn_inference(self) -> dict[str, Any]:
        """The Mask R-CNN's inference settings node.yaml sets (MaskRCNN.set_inference); the
        weights' own for those left out."""
        seg = self.raw["segmentation"]
        named = {
            "semantic_background_weight": seg["semantic_background_weight"],
            "rpn_post_nms_top_n_test": seg["proposals"],
            "semantic_vote": seg["semantic_vote"],
        }
        return {key: value for key, value in named.items() if value is not None}

    @property
    def score_floor(self) -> float:
        """The lowest score a segmenter keeps: ``second_look_score`` when set, else ``min_score``."""
        seg = self.raw["segmentation"]
        return seg["min_score"] if seg["second_look_score"] is None else seg["second_look_score"]

    @property
    def parting(self) -> Parting:
        """Which refused clouds are posed again on the larger of two pieces (none when its classes
        are empty), and when a second pose is taken (that of a mask's core too)."""
        raw = self.raw["parting"]
        return Parting(**{**raw, "classes": tuple(raw["classes"])})

    @property
    def detached(self) -> Detached:
        """Which pieces of a part's cloud are dropped before its pose."""
        raw = self.raw["detached"]
        return Detached(
            **{
                **raw,
                "largest_only": tuple(raw["largest_only"]),
                "links": tuple(sorted(raw["links"].items())),
            }
        )

    @property
    def depth_split(self) -> DepthSplit | None:
        """How Mask R-CNN's thin-part regions are cut where the depth jumps; None: not cut."""
        raw = self.raw["segmentation"]["depth_split"]
        if not raw:
            return None
        band = raw["width_band"]
        return DepthSplit(
            **{
                **raw,
                "width_band": tuple(band) if band else None,
                "depth_noise": self.depth_noise,
                "vote": self.raw["segmentation"]["semantic_vote"],
            }
        )

    @property
    def semantic_trim(self) -> SemanticTrim | None:
        """Which box-branch masks lose the pixels the semantic head holds to be a thin part."""
        raw = self.raw["segmentation"]["semantic_trim"]
        return SemanticTrim(tuple(raw["classes"]), raw["above"], tuple(raw["cores"])) if raw else None

    @property
    def exclusive_overlaps(self) -> ExclusiveOverlaps | None:
        """Which box-branch classes' masks give the pixels they share to the more probable one."""
        raw = self.raw["segmentation"]["exclusive_overlaps"]
        return ExclusiveOverlaps(tuple(raw["classes"]), raw["duplicate"]) if raw else None

    def detector_path(self, model: str) -> Path:
        return repo_path(self.raw["detectors"][model])

    @property
    def mission_path(self) -> Path:
        return repo_path(self.raw["mission"])


def config_from_dict(data: Any, source: str = "<vision config>") -> VisionConfig:
    raw = validate(data, SCHEMA, source=source)
    check_across_keys(raw, source)
    return VisionConfig(raw, source)


def load_config(path: str | Path = DEFAULT_CONFIG, mission: str | Path | None = None) -> VisionConfig:
    """Load and check ``path``; ``mission`` replaces the file's mission. Raises ConfigError."""
    cfg = config_from_dict(load_yaml(path), str(path))
    if mission is not None:
        cfg.raw["mission"] = str(mission)
    return cfg


__all__ = [
    "DEFAULT_CONFIG",
    "MODEL_NAMES",
    "SEGMENTATION_SOURCES",
    "VisionConfig",
    "config_from_dict",
    "load_config",
    "pose_of",
    "repo_path",
]
