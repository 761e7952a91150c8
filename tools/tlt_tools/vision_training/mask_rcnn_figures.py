"""The Mask R-CNN trainer's figures: the loss curves (smoothed, per step) with the validation AP per
epoch, and validation images with the predicted masks, boxes, classes and scores."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tlt_tools.vision_training.dataset import ImageSet, ImageSets
from tlt_vision.segmentation.inference import detect_rgb
from tlt_vision.segmentation.model import MaskRCNN

# The losses the trainer logs and the curves plot.
LOSSES = ("rpn_objectness", "rpn_box", "roi_cls", "roi_box", "roi_mask")
SEMANTIC = "semantic"  # the semantic head's loss, when the model has one


def _smooth(values: Sequence[float], window: int) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if window <= 1 or len(v) < 2:
        return v
    c = np.cumsum(np.insert(v, 0, 0.0))
    out = np.empty_like(v)
    for i in range(len(v)):  # trailing mean; short at the start
        lo = max(0, i + 1 - window)
        out[i] = (c[i + 1] - c[lo]) / (i + 1 - lo)
    return out


def plot_curves(
    path: Path,
    step_losses: Sequence[dict[str, float]],
    history: Sequence[dict[str, Any]],
    classes: Sequence[str],
) -> None:
    """Losses per step (trailing mean over ~2 % of the run) and validation AP50 per epoch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, (ax_loss, ax_ap) = plt.subplots(1, 2, figsize=(12, 4.5))
    window = max(1, len(step_losses) // 50)
    steps = np.arange(1, len(step_losses) + 1)
    for key in (*LOSSES, SEMANTIC, "total"):
        values = [s[key] for s in step_losses if key in s]
        if values:
            ax_loss.plot(steps, _smooth(values, window), label=key, lw=2.0 if key == "total" else 1.0)
    ax_loss.set_yscale("log")
    ax_loss.set_xlabel("step")
    ax_loss.set_ylabel(f"loss (mean of {window} steps)")
    ax_loss.legend(fontsize=8)
    ax_loss.grid(alpha=0.3)
    val = [h for h in history if h.get("val_map") is not None]
    if val:
        epochs = [h["epoch"] for h in val]
        ax_ap.plot(epochs, [h["val_map"] for h in val], "k-o", lw=2, label="mean")
        for c in classes:
            ys = [h["val_ap50"].get(c, np.nan) for h in val]
            if not all(np.isnan(ys)):
                ax_ap.plot(epochs, ys, "-", marker=".", lw=1, label=c)
        ax_ap.set_ylim(0, 1)
        ax_ap.legend(fontsize=8)
    else:
        ax_ap.text(0.5, 0.5, "no validation set", ha="center", va="center", transform=ax_ap.transAxes)
    ax_ap.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax_ap.set_xlabel("epoch")
    ax_ap.set_ylabel("validation mask AP50")
    ax_ap.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_samples(
    path: Path,
    model: MaskRCNN,
    images: ImageSet | ImageSets,
    max_size: int | None,
    count: int = 4,
    min_score: float = 0.5,
) -> None:
    """The first ``count`` images of the set with the detections scoring ``min_score`` or more."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    n = min(count, len(images))
    cols = min(2, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.4 * cols, 4.8 * rows), squeeze=False)
    colours = plt.get_cmap("tab10")
    for k, ax in enumerate(axes.flat):
        ax.axis("off")
        if k >= n:
            continue
        s = images[k]
        det = detect_rgb(model, s.rgb, max_size)
        shown = s.rgb.astype(np.float32) / 255.0
        keep = det["scores"] >= min_score
        for box, label, score, mask in zip(
            det["boxes"][keep], det["labels"][keep], det["scores"][keep], det["masks"][keep], strict=True
        ):
            colour = np.array(colours(int(label) - 1)[:3])
            m = mask.numpy()
            shown[m] = 0.5 * shown[m] + 0.5 * colour
            x1, y1, x2, y2 = box.tolist()
            ax.add_patch(Rectangle((x1, y1), x2 - x1, y2 - y1, fill=False, color=colour, lw=1.2))
            ax.text(
                x1,
                y1,
                f"{images.classes[int(label) - 1]} {float(score):.2f}",
                color="white",
                fontsize=7,
                va="bottom",
                bbox={"facecolor": colour, "alpha": 0.7, "pad": 1, "lw": 0},
            )
        ax.imshow(shown)
        ax.set_title(f"{images.path(k).name}: {int(keep.sum())} detections, {len(s.labels)} true", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
