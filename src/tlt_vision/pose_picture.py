"""A camera frame as the vision node saw it: its detections' masks and each part's posed model.

Each detection's mask is tinted with its class's colour; each posed part's CAD model, sampled on
its surface and moved to the pose C-3PO gave it, is projected into the image as dots, green where
the pose is certified and red where it is not, so that a wrong or refused pose shows where it lies
against the part. ``bench/vision.py --picture`` draws its first frames so
(``models/vision/vision_poses.png``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tlt_vision.cad.models import CadModel
from tlt_vision.detections import Detection
from tlt_vision.inspection import Observation

CERTIFIED, REFUSED = (0.2, 0.9, 0.2), (0.95, 0.1, 0.1)
# The classes' tints, without the poses' green and red.
TINTS = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:cyan", "tab:pink", "tab:olive", "tab:gray")
SURFACE_POINTS = 300


@dataclass(frozen=True)
class PosedFrame:
    """One frame's picture: the RGB image (H, W, 3) uint8, the camera matrix (3x3), the
    detections and their observations in the same order, and a title."""

    title: str
    rgb: np.ndarray
    camera_matrix: np.ndarray
    detections: Sequence[Detection]
    observations: Sequence[Observation]


def projected(
    model: CadModel, rotation: np.ndarray, translation: np.ndarray, k: np.ndarray, count: int = SURFACE_POINTS
) -> np.ndarray:
    """Pixel coordinates (N, 2) of ``count`` surface points of ``model`` at the pose, those in
    front of the camera only."""
    surface = model.sample(count, np.random.default_rng(0))[0]
    points = surface @ np.asarray(rotation).T + np.asarray(translation)
    points = points[points[:, 2] > 1e-3]
    return np.stack(
        [k[0, 0] * points[:, 0] / points[:, 2] + k[0, 2], k[1, 1] * points[:, 1] / points[:, 2] + k[1, 2]],
        axis=1,
    )


def write_pose_picture(
    path: str | Path,
    frames: Sequence[PosedFrame],
    models: Mapping[str, CadModel],
    classes: Sequence[str],
    columns: int = 2,
) -> Path:
    """``frames`` drawn side by side into the PNG ``path``; ``models`` (class: the model it was
    posed with) and ``classes`` (the colours' order) as the frames' poses were made."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_rgb
    from matplotlib.lines import Line2D

    if not frames:
        raise ValueError("no frame to draw")
    cols = min(columns, len(frames))
    rows = -(-len(frames) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.4 * cols, 4.8 * rows + 0.4), squeeze=False)
    tints = {name: np.array(to_rgb(TINTS[i % len(TINTS)])) for i, name in enumerate(classes)}
    for ax in axes.flat:
        ax.axis("off")
    for ax, frame in zip(axes.flat, frames, strict=False):
        h, w = frame.rgb.shape[:2]
        shown = frame.rgb.astype(np.float32) / 255.0
        for det in frame.detections:
            shown[det.mask] = 0.5 * shown[det.mask] + 0.5 * tints[det.object_class]
        ax.imshow(shown)
        posed = certified = 0
        for obs in frame.observations:
            e = obs.estimate
            if e is None or obs.object_class not in models:
                continue
            posed += 1
            certified += e.certified
            uv = projected(models[obs.object_class], e.rotation, e.translation, frame.camera_matrix)
            ax.scatter(uv[:, 0], uv[:, 1], s=1.5, color=CERTIFIED if e.certified else REFUSED, linewidths=0)
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_title(f"{frame.title}: {posed} parts posed, {certified} certified", fontsize=9)
    handles = [Line2D([], [], marker="s", linestyle="", color=tints[name], label=name) for name in classes]
    handles += [
        Line2D([], [], marker="o", linestyle="", color=CERTIFIED, label="posed model, certified"),
        Line2D([], [], marker="o", linestyle="", color=REFUSED, label="posed model, not certified"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


__all__ = ["CERTIFIED", "REFUSED", "TINTS", "PosedFrame", "projected", "write_pose_picture"]
