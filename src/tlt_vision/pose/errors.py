"""How far an estimated pose is from the true one, as the vision benchmarks count it.

A symmetric part has several true poses (a cube's 24, the square frame's 8, a tube end for end),
and the rotation of a tube, end fitting or rivet about its own axis (model z) is not observable,
so the rotation error is taken against the nearest symmetric image of the truth and, for those
axial classes, is the angle between the axes alone. ADD-S (the mean distance of the estimated
model's surface points to the true model's surface) is blind to symmetry by construction. A view
that shows too little of its part at the *true* pose (:func:`non_degenerate_at`) may not be
certified by any estimate, and is left out of the certified fraction.
"""

from __future__ import annotations

import numpy as np
import torch

from tlt_vision.cad.models import CadModel
from tlt_vision.pose.certificate import visible_groups

# Round parts whose spin about their own axis no camera can see (docs/vision.md).
AXIAL_CLASSES = frozenset({"strut_tube", "end_fitting", "rivet"})


def _angle(cos: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def rotation_error_deg(model: CadModel, rotation: np.ndarray, true_rotation: np.ndarray) -> float:
    """Degrees between ``rotation`` and the nearest symmetric image of ``true_rotation`` (for an
    axial class, between the model z axes they give)."""
    images = np.asarray(true_rotation) @ model.symmetry_rotations  # (P, 3, 3)
    rotation = np.asarray(rotation)
    if model.object_class in AXIAL_CLASSES:
        cos = images[:, :, 2] @ rotation[:, 2]
        # A symmetric tube's images already hold the reversed axis; a rivet's spin is all we drop.
        return float(_angle(cos).min())
    relative = np.einsum("pji,jk->pik", images, rotation)  # images^T @ rotation
    cos = (np.trace(relative, axis1=1, axis2=2) - 1.0) / 2.0
    return float(_angle(cos).min())


def add_s(
    model: CadModel,
    rotation: np.ndarray,
    translation: np.ndarray,
    true_rotation: np.ndarray,
    true_translation: np.ndarray,
    samples: int = 512,
) -> float:
    """Mean distance (m) from ``samples`` surface points of the model at the estimated pose to the
    model's surface at the true pose (exact surface distance: the dense limit of ADD-S)."""
    points, _ = model.sample(samples, np.random.default_rng(0))
    seen = points @ np.asarray(rotation).T + np.asarray(translation)
    in_true = (seen - np.asarray(true_translation)) @ np.asarray(true_rotation)
    with torch.no_grad():
        dist = model.surface(torch.as_tensor(in_true, dtype=torch.float32)[None])[0]
    return float(dist.abs().mean())


def non_degenerate_at(model: CadModel, points: np.ndarray, pose: np.ndarray) -> bool:
    """Whether ``points`` (N, 3, camera frame) show enough of ``model``'s keypoint groups with the
    part at ``pose`` (4x4, camera frame): the certificate's own rule, at the truth."""
    kp = np.asarray(model.keypoints) @ pose[:3, :3].T + pose[:3, 3]
    groups = visible_groups(
        torch.as_tensor(points, dtype=torch.float32),
        torch.as_tensor(kp, dtype=torch.float32),
        model.visibility,
    )
    return len(groups) >= model.visibility.groups_required


__all__ = ["AXIAL_CLASSES", "add_s", "non_degenerate_at", "rotation_error_deg"]
