"""A segmented instance (:class:`Detection`: its class, mask, score and the part of the mask the
segmentation is surest of), read from Mask R-CNN's output, and what is done to a frame's list of
them before any pose: one class's instances joined into one, and the instances kept that lie near
where a check looks."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from tlt_vision.pointcloud import PinholeIntrinsics, masked_point_cloud


@dataclass(frozen=True)
class Detection:
    object_class: str
    mask: np.ndarray  # (H, W) bool
    score: float = 1.0
    object_id: str = ""
    # The part of ``mask`` the segmentation is surest of, whose pose stands in for the whole
    # mask's when that is refused; None: no such part, or the whole mask.
    core: np.ndarray | None = None


def detection_of(result: Mapping[str, torch.Tensor], classes: Sequence[str], k: int) -> Detection:
    """The ``k``-th detection of one image's Mask R-CNN output (labels are 1-based indices into
    ``classes``), with its core where ``core_masks`` gives one smaller than its mask."""
    mask = result["masks"][k].numpy().astype(bool)
    core = None
    if "core_masks" in result:
        core = result["core_masks"][k].numpy().astype(bool)
        if not core.any() or np.array_equal(core, mask):
            core = None
    return Detection(classes[int(result["labels"][k]) - 1], mask, float(result["scores"][k]), core=core)


def detections_from_mask_rcnn(
    result: Mapping[str, torch.Tensor], classes: Sequence[str], min_score: float = 0.5
) -> list[Detection]:
    """Detections of one image's Mask R-CNN output scoring at least ``min_score``."""
    return [
        detection_of(result, classes, k)
        for k, score in enumerate(result["scores"].tolist())
        if score >= min_score
    ]


def merge_instances(detections: Sequence[Detection], classes: Sequence[str]) -> list[Detection]:
    """Detections with every instance of each class in ``classes`` joined into one."""
    out = [d for d in detections if d.object_class not in classes]
    for cls in classes:
        parts = [d for d in detections if d.object_class == cls]
        if parts:
            mask = np.logical_or.reduce([d.mask for d in parts])
            out.append(
                Detection(cls, mask, min(d.score for d in parts), "+".join(d.object_id for d in parts))
            )
    return out


def detections_near(
    detections: Sequence[Detection],
    depth: np.ndarray | None,
    intrinsics: PinholeIntrinsics,
    camera_pose: np.ndarray,
    places: np.ndarray,
    radius: float,
) -> list[Detection]:
    """The detections whose seen surface has its median point (in the frame ``camera_pose`` maps
    the camera into) within ``radius`` of one of ``places`` (n, 3).

    A pose costs seconds of corrector work, a point cloud's median microseconds: a check that
    counts only pieces near where they should be (within a gate) estimates those alone. The
    median of a piece's visible surface lies within half the piece's size of its centre, so with
    ``radius`` = gate + that no piece the check could count is dropped. A detection with no valid
    depth is kept, for the pipeline to give its reason."""
    places = np.asarray(places, dtype=float).reshape(-1, 3)
    kept = []
    for d in detections:
        cloud = masked_point_cloud(d.mask, depth, intrinsics, min_points=1, erode=0)
        if cloud.points.shape[0] == 0:
            kept.append(d)
            continue
        centre = camera_pose[:3, :3] @ np.median(cloud.points, axis=0) + camera_pose[:3, 3]
        if places.size and np.linalg.norm(places - centre, axis=1).min() <= radius:
            kept.append(d)
    return kept


__all__ = ["Detection", "detection_of", "detections_from_mask_rcnn", "detections_near", "merge_instances"]
