"""Hyper-parameters of the Mask R-CNN (one frozen dataclass; the weights manifest records it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

CLASSES = ("strut_tube", "end_fitting", "cross_frame", "corner_joint", "rivet")


@dataclass(frozen=True)
class MaskRCNNConfig:
    """Sizes and thresholds. Label 0 is background; label i + 1 is ``classes[i]``."""

    classes: tuple[str, ...] = CLASSES
    backbone_channels: tuple[int, int, int, int] = (16, 32, 64, 96)  # C2..C5, strides 4..32
    fpn_channels: int = 48
    anchor_sizes: tuple[float, float, float, float] = (16.0, 32.0, 64.0, 128.0)  # one per level
    # Struts are long and thin in an image: wide ratios (height / width) as well as square.
    anchor_ratios: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 4.0)
    rpn_pre_nms_top_n: int = 600  # per level
    rpn_post_nms_top_n_train: int = 300
    rpn_post_nms_top_n_test: int = 100
    rpn_nms_threshold: float = 0.7
    rpn_fg_iou: float = 0.7
    rpn_bg_iou: float = 0.3
    rpn_batch_per_image: int = 128
    rpn_positive_fraction: float = 0.5
    roi_fg_iou: float = 0.5
    roi_batch_per_image: int = 96
    roi_positive_fraction: float = 0.25
    box_pool: int = 7
    mask_pool: int = 14
    representation: int = 256  # box head MLP width
    mask_convs: int = 2
    box_weights: tuple[float, float, float, float] = (10.0, 10.0, 5.0, 5.0)
    score_threshold: float = 0.05
    detection_nms: float = 0.5
    detections_per_image: int = 50
    min_box_size: float = 1.0
    pixel_mean: tuple[float, float, float] = (0.485, 0.456, 0.406)
    pixel_std: tuple[float, float, float] = (0.229, 0.224, 0.225)
    strides: tuple[int, int, int, int] = field(default=(4, 8, 16, 32))
    # Classes found as connected regions of a per-pixel class map (the semantic head, stride 2)
    # instead of by box and box-sized mask: a strut lying across the view is a line a few pixels
    # wide that few anchors overlap and a 28x28 mask over its box cannot draw. Empty: no head.
    semantic_classes: tuple[str, ...] = ()
    semantic_channels: int = 32
    semantic_fg_weight: float = 3.0  # cross-entropy weight of object pixels against background
    semantic_min_area: int = 12  # pixels at the model's input size; smaller regions are noise
    # Pixels between touching instances of a class that the head learns as background, so that
    # they are separate regions; 2 is one cell of its stride-2 map (a 1-pixel gap it cannot draw).
    semantic_gap: int = 2
    # A pixel is a thin part's where that part's probability beats this times the background's
    # (1: the most probable class). The head's doubt lies on a thin part's edges and narrow
    # stretches; below 1 fewer tubes break in two or vanish (models/vision/history.md). Applied
    # at inference only; the vision node sets it (node.yaml segmentation.semantic_background_weight).
    semantic_background_weight: float = 1.0
    # A region is one of any thin class's pixels, of the class with the most probability over it
    # (semantic.instances_from_semantic); False: one class's pixels. Applied at inference only.
    semantic_vote: bool = False

    def __post_init__(self) -> None:
        if not self.semantic_background_weight > 0:
            raise ValueError(f"semantic_background_weight {self.semantic_background_weight} is not positive")
        unknown = [c for c in self.semantic_classes if c not in self.classes]
        if unknown:
            raise ValueError(f"semantic_classes {unknown} are not among the classes {list(self.classes)}")

    @property
    def semantic_labels(self) -> tuple[int, ...]:
        """1-based labels of ``semantic_classes``."""
        return tuple(self.classes.index(c) + 1 for c in self.semantic_classes)

    @property
    def num_classes(self) -> int:
        """Classes including the background."""
        return len(self.classes) + 1

    def to_dict(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MaskRCNNConfig:
        known = {f for f in cls.__dataclass_fields__}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown Mask R-CNN settings: {', '.join(sorted(unknown))}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


__all__ = ["CLASSES", "MaskRCNNConfig"]
