"""Train the plain-torch Mask R-CNN on rendered image sets, and evaluate its mask AP50.

Train (``--train`` one or more sets, read as one, and optionally ``--val``, in the format of
:mod:`tlt_tools.vision_training.dataset`)::

    python -m tlt_tools.vision_training.mask_rcnn --train DIR [DIR ...] [--val DIR] \\
        --out build/vision/mask_rcnn.pt \\
        [--epochs 20] [--batch 4] [--lr 1e-3] [--seed 0] [--threads 2] [--max-size 320] \\
        [--device cpu|cuda] [--workers N] [--ranks N] [--time-budget-min M] [--config key=value ...]
        [--resume CKPT] [--init WEIGHTS]

Every ``--log-every`` steps it prints the epoch, step, images per second, the five losses and the
time left; after each epoch the validation mask AP50 per class and mean. It keeps the weights of
the best epoch by validation AP (the last epoch without ``--val``) in ``--out`` with their manifest
(kind ``mask_rcnn``; settings: the model configuration and ``max_size``, the input size the
node then uses too; figures: epochs, images, losses, AP50 per class, seconds). Beside it:
``<stem>_checkpoint.pt`` after every epoch (``--resume`` continues from it), ``<stem>_curves.png``
(losses per step, smoothed; validation AP per epoch) and ``<stem>_samples.png`` (validation images
with the predicted masks, boxes, classes and scores). ``--init WEIGHTS`` starts from trained
weights (the tensors of the same name and shape; a part the model adds, such as a semantic head,
starts fresh), so that short runs on lent machines can build on each other.

Evaluate saved weights::

    python -m tlt_tools.vision_training.mask_rcnn --evaluate build/vision/mask_rcnn.pt --val DIR [--threads 2]

prints AP50 per class and mean and the mean inference time per image (as the node runs it:
:func:`tlt_vision.segmentation.inference.detect_rgb`, full-size image in, full-size masks out).

With ``--node-config config/vision/node.yaml`` the validation AP (in training, and so the best
epoch, and with ``--evaluate``) is that of the masks as the vision node makes them
(:meth:`tlt_vision.segmentation_source.MaskRcnnSegmenter.refine`: its inference settings, the
depth cut of thin parts, the trim and the exclusive overlaps), not the model's alone: the figure
the benchmark holds to its goal.

An input that cannot be used (not an image set, another class list, no images, unreadable or
mismatched checkpoint or weights) ends the command with exit status 2 and the path and reason on
stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from tlt_tools.vision_training.data_parallel import Ranks, run_ranks
from tlt_tools.vision_training.dataset import DatasetError, ImageSet, ImageSets
from tlt_vision.ops.boxes import boxes_from_masks
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.evaluate import MaskAP
from tlt_vision.segmentation.inference import (
    KIND,
    detect_rgb,
    load_mask_rcnn,
    resize_image,
    resize_masks,
    rgb_to_tensor,
    scaled_size,
    weights_settings,
)
from tlt_vision.segmentation.model import MaskRCNN, train_step
from tlt_vision.weights import WeightsError, read_manifest, save_weights

if TYPE_CHECKING:
    from tlt_vision.segmentation_source import MaskRcnnSegmenter

VERSION = "1"
LOSSES = ("rpn_objectness", "rpn_box", "roi_cls", "roi_box", "roi_mask")
SEMANTIC = "semantic"  # the semantic head's loss, when the model has one
SHORT = {
    "rpn_objectness": "rpn_obj",
    "rpn_box": "rpn_box",
    "roi_cls": "cls",
    "roi_box": "box",
    "roi_mask": "mask",
    SEMANTIC: "sem",
}


class InputError(Exception):
    """An input the command cannot use; the message names the path and the reason (exit 2)."""


@dataclass(frozen=True)
class Augment:
    """Image augmentation for the twin's renders: the scenes have no preferred left and right,
    and exposure varies with lighting and camera; geometry otherwise stays as rendered."""

    flip: float = 0.5  # probability of a horizontal flip
    brightness: float = 0.1  # added, uniform in +-
    contrast: float = 0.2  # factor about the image mean, uniform in 1 +-
    # A real camera's sensor noise and optics, which the twin's renders lack: each image gets
    # Gaussian noise of a standard deviation uniform in 0..noise grey levels, and a Gaussian blur
    # of a sigma uniform in 0..blur pixels (at the size the model sees). 0: off.
    noise: float = 0.0
    blur: float = 0.0


# ---------------------------------------------------------------------------------------- data


def open_set(root: str | Path, classes: Sequence[str]) -> ImageSet:
    """The image set at ``root``, checked to use the model's ``classes`` and to hold images."""
    try:
        images = ImageSet(root)
    except DatasetError as exc:
        raise InputError(str(exc)) from exc
    if list(images.classes) != list(classes):
        raise InputError(
            f"{images.root / 'index.json'}: classes {images.classes} differ from the model's {list(classes)}"
        )
    if len(images) == 0:
        raise InputError(f"{images.root / 'index.json'}: the set has no images")
    return images


def open_sets(roots: Sequence[str | Path], classes: Sequence[str]) -> ImageSets:
    """The sets at ``roots`` (each checked as :func:`open_set`) read as one."""
    return ImageSets([open_set(root, classes) for root in roots])


def load_sample(
    images: ImageSet | ImageSets, i: int, max_size: int | None, min_area: int
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Image ``i`` as the model trains on it: float (3, h, w) at the model's size, and its target
    (masks resized with it, instances under ``min_area`` pixels dropped, boxes from the masks)."""
    s = images[i]
    path = images.path(i)
    if s.rgb.dtype != np.uint8 or s.rgb.ndim != 3 or s.rgb.shape[2] != 3:
        raise InputError(f"{path}: rgb is {s.rgb.dtype} {s.rgb.shape}, expected uint8 (H, W, 3)")
    h, w = s.rgb.shape[:2]
    if s.masks.shape[1:] != (h, w):
        raise InputError(f"{path}: masks have shape {s.masks.shape}, the image is {h}x{w}")
    labels = torch.as_tensor(s.labels, dtype=torch.long)
    if len(labels) and (labels.min() < 1 or labels.max() > len(images.classes)):
        raise InputError(f"{path}: labels outside 1..{len(images.classes)}: {sorted(set(s.labels.tolist()))}")
    size = scaled_size(h, w, max_size)
    image = resize_image(rgb_to_tensor(s.rgb), size)[0]
    masks = resize_masks(torch.as_tensor(s.masks, dtype=torch.bool), size)
    # Counted in numpy: torch's sum of a bool (N, H*W) is slow enough to be most of the loader's
    # time.
    keep = torch.from_numpy(np.count_nonzero(masks.flatten(1).numpy(), axis=1) >= min_area)
    masks, labels = masks[keep], labels[keep]
    return image, {"boxes": boxes_from_masks(masks), "labels": labels, "masks": masks}


def augment(
    image: torch.Tensor, target: dict[str, torch.Tensor], aug: Augment, rng: np.random.Generator
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """A horizontally flipped (masks and boxes with it), exposure-jittered, blurred and noisy copy.
    Only what ``aug`` turns on draws from ``rng``, so a recipe's images do not change when an
    option is added."""
    target = dict(target)
    if rng.random() < aug.flip:
        w = image.shape[-1]
        image = image.flip(-1)
        target["masks"] = target["masks"].flip(-1)
        b = target["boxes"]
        target["boxes"] = torch.stack([w - b[:, 2], b[:, 1], w - b[:, 0], b[:, 3]], dim=1)
    c = 1.0 + rng.uniform(-aug.contrast, aug.contrast)
    b = rng.uniform(-aug.brightness, aug.brightness)
    mean = image.mean()
    image = (image - mean) * c + mean + b
    if aug.blur > 0.0:
        image = gaussian_blur(image, rng.uniform(0.0, aug.blur))
    if aug.noise > 0.0:
        sigma = rng.uniform(0.0, aug.noise) / 255.0
        noise = rng.standard_normal(image.shape, dtype=np.float32)
        image = image + torch.from_numpy(noise).to(image.dtype) * sigma
    return image.clamp(0.0, 1.0), target


def gaussian_blur(image: torch.Tensor, sigma: float) -> torch.Tensor:
    """``image`` (C, H, W) blurred by a Gaussian of ``sigma`` pixels, the borders mirrored; under
    0.3 px the kernel is a single tap and the image is returned as is."""
    radius = int(np.ceil(3.0 * sigma))
    if sigma < 0.3 or radius < 1:
        return image
    x = torch.arange(-radius, radius + 1, dtype=image.dtype)
    kernel = torch.exp(-0.5 * (x / sigma) ** 2)
    kernel = kernel / kernel.sum()
    c = image.shape[0]
    out = torch.nn.functional.pad(image[None], (radius, radius, radius, radius), mode="reflect")
    out = torch.nn.functional.conv2d(out, kernel.view(1, 1, 1, -1).expand(c, 1, 1, -1), groups=c)
    out = torch.nn.functional.conv2d(out, kernel.view(1, 1, -1, 1).expand(c, 1, -1, 1), groups=c)
    return out[0]


class TrainingImages(torch.utils.data.Dataset):
    """The training set as the model sees it: image ``i`` loaded and augmented by a generator
    seeded by (seed, epoch, i), so an epoch's images are the same whatever the number of loader
    workers, and a resumed run sees what it would have."""

    def __init__(
        self, images: ImageSet | ImageSets, max_size: int | None, min_area: int, aug: Augment, seed: int
    ) -> None:
        self.images, self.max_size, self.min_area, self.aug, self.seed = images, max_size, min_area, aug, seed
        self.epoch = 0  # set before each epoch's loader is made (workers copy it then)

    def __len__(self) -> int:
        return len(self.images)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        rng = np.random.default_rng([self.seed, self.epoch, i])
        return augment(*load_sample(self.images, i, self.max_size, self.min_area), self.aug, rng)


def _as_list(batch: list[Any]) -> list[Any]:
    return batch


def _silent(*_args: Any, **_kwargs: Any) -> None:
    """``print`` for the processes that are not the leader."""


def _one_thread(_worker: int) -> None:
    torch.set_num_threads(1)  # the workers share the machine with the training process


def resolve_device(name: str) -> torch.device:
    """``--device`` as a torch device; InputError when torch cannot use it here."""
    try:
        device = torch.device(name)
    except RuntimeError as exc:
        raise InputError(f"--device {name}: {exc}") from exc
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"--device {name}: this torch ({torch.__version__}) sees no CUDA device")
    if device.type not in ("cpu", "cuda"):
        raise InputError(f"--device {name}: only cpu and cuda are supported")
    return device


# ---------------------------------------------------------------------------------- evaluation


def node_segmenter(path: str | Path, model: MaskRCNN, max_size: int | None) -> MaskRcnnSegmenter:
    """The vision node's segmentation (configured by the node.yaml at ``path``) around ``model``,
    whose own inference settings stay in force but while :func:`evaluate` uses the node's."""
    from tlt_vision.node_config import load_config
    from tlt_vision.segmentation_source import MaskRcnnSegmenter

    own = model.inference_settings()
    try:
        segmenter = MaskRcnnSegmenter.from_config(load_config(path), model=model, max_size=max_size)
    except (OSError, ValueError) as exc:
        raise InputError(f"--node-config {path}: {exc}") from exc
    model.set_inference(**own)
    return segmenter


def evaluate(
    model: MaskRCNN,
    images: ImageSet,
    max_size: int | None,
    limit: int | None = None,
    node: MaskRcnnSegmenter | None = None,
) -> dict[str, Any]:
    """Mask AP50 of ``model`` on the set at full resolution: ``map``, ``per_class`` {name: AP}
    (classes with ground truth), ``seconds_per_image`` (segmentation, not scoring), ``images``; with
    ``node`` (:func:`node_segmenter` around ``model``), of the masks as the node makes them."""
    n = len(images) if limit is None else min(limit, len(images))
    acc = MaskAP(len(images.classes))
    seconds = 0.0
    own = model.inference_settings()
    if node is not None:
        model.set_inference(**node.inference)
    try:
        for i in range(n):
            s = images[i]
            t0 = time.perf_counter()
            pred = detect_rgb(model, s.rgb, max_size)
            if node is not None:
                pred = node.refine(pred, s.depth, s.intrinsics)
            seconds += time.perf_counter() - t0
            gt = {
                "masks": torch.as_tensor(s.masks, dtype=torch.bool),
                "labels": torch.as_tensor(s.labels, dtype=torch.long),
            }
            acc.add(pred, gt)
    finally:
        model.set_inference(**own)
    result = acc.result()
    per_class = {images.classes[label - 1]: ap for label, ap in result["per_class"].items()}
    return {
        "map": result["map"],
        "per_class": per_class,
        "seconds_per_image": seconds / max(n, 1),
        "images": n,
    }


def format_ap(result: dict[str, Any], classes: Sequence[str]) -> str:
    parts = [f"{c} {result['per_class'][c]:.3f}" if c in result["per_class"] else f"{c} -" for c in classes]
    return f"mask AP50 {result['map']:.3f} ({', '.join(parts)})"


# ------------------------------------------------------------------------------------- figures


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


# ------------------------------------------------------------------------------------ training


def output_paths(out: Path) -> dict[str, Path]:
    stem = out.with_suffix("")
    return {
        "checkpoint": Path(f"{stem}_checkpoint.pt"),
        "curves": Path(f"{stem}_curves.png"),
        "samples": Path(f"{stem}_samples.png"),
    }


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``key=value`` pairs (values as JSON: ``fpn_channels=32``, ``backbone_channels=[8,8,16,16]``)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--config {item!r}: expected key=value")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def build_config(overrides: dict[str, Any]) -> MaskRCNNConfig:
    try:
        return MaskRCNNConfig.from_dict({**MaskRCNNConfig().to_dict(), **overrides})
    except (TypeError, ValueError) as exc:
        raise InputError(f"--config: {exc}") from exc


def learning_rate(step: int, total: int, base: float) -> float:
    """Linear warm-up over the first 5 % of steps (at most 200) from base/10, then cosine to base/20:
    a from-scratch detector's first steps have wild RPN gradients."""
    warm = max(1, min(200, total // 20))
    if step < warm:
        return base * (0.1 + 0.9 * step / warm)
    t = (step - warm) / max(1, total - warm)
    return base * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t)))


def epochs_within(budget_s: float, elapsed_s: float, epochs_run: int, epochs_done: int, epochs: int) -> int:
    """How many epochs (at most ``epochs``, at least those done) a run may have so it ends within
    ``budget_s``, at the mean duration of the ``epochs_run`` this run has trained and evaluated."""
    per_epoch = elapsed_s / max(epochs_run, 1)
    more = math.floor(max(budget_s - elapsed_s, 0.0) / per_epoch) if per_epoch > 0 else epochs
    return max(epochs_done, min(epochs, epochs_done + more))


def epochs_at_pace(budget_s: float, seconds_per_epoch: float, epochs_done: int, epochs: int) -> int:
    """How many epochs (at most ``epochs``, at least one more than ``epochs_done``, those before this
    run) fit in ``budget_s`` at ``seconds_per_epoch``, judged early in the run's first epoch."""
    fit = math.floor(budget_s / seconds_per_epoch) if seconds_per_epoch > 0 else epochs
    return max(epochs_done + 1, min(epochs, epochs_done + fit))


def pace_probe_step(steps_per_epoch: int) -> int:
    """The step of a run's first epoch after which ``--time-budget-min`` first judges the epochs
    that fit (0: none, a one-step epoch): 5 % of the epoch, or 20 steps if more, so that an epoch
    longer than the budget decays the learning rate over itself instead of holding it at its peak."""
    return max(steps_per_epoch // 20, min(20, steps_per_epoch - 1))


def _budget_line(minutes: float, fit: int, epochs: int, how: str = "") -> str:
    return (
        f"time budget {minutes:g} min: {fit} epochs fit, not {epochs}{how}; "
        "the learning rate decays over those"
    )


def _duration(seconds: float) -> str:
    seconds = round(seconds)
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else f"{m}m{s:02d}s"


def _save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    tmp.replace(path)  # a run killed while writing keeps its previous checkpoint


def validated_as(args: argparse.Namespace) -> str | None:
    """Which masks a run's validation scores (the manifest's and each epoch's ``val_as``); None
    without ``--val``."""
    if not args.val:
        return None
    return f"as the node segments ({args.node_config})" if args.node_config else "the model alone"


def _load_checkpoint(
    path: Path, settings: dict[str, Any], classes: Sequence[str], val_as: str | None
) -> dict[str, Any]:
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError as exc:
        raise InputError(f"{path}: checkpoint not found") from exc
    except Exception as exc:  # torch raises several types for a corrupt file
        raise InputError(f"{path}: unreadable checkpoint: {exc}") from exc
    if not isinstance(ckpt, dict) or ckpt.get("kind") != f"{KIND}_checkpoint":
        raise InputError(f"{path}: not a Mask R-CNN training checkpoint")
    if ckpt["classes"] != list(classes):
        raise InputError(f"{path}: checkpoint classes {ckpt['classes']} differ from {list(classes)}")
    if ckpt["settings"] != settings:
        diff = sorted(
            k
            for k in set(settings["model"]) | set(ckpt["settings"]["model"])
            if settings["model"].get(k) != ckpt["settings"]["model"].get(k)
        )
        if ckpt["settings"].get("max_size") != settings.get("max_size"):
            diff.append("max_size")
        raise InputError(
            f"{path}: checkpoint was trained with other settings ({', '.join(diff)}); "
            "resume with the same --config and --max-size"
        )
    validated = [h.get("val_as", "the model alone") for h in ckpt["history"] if h.get("val_map") is not None]
    if val_as is not None and validated and validated[-1] != val_as:
        raise InputError(
            f"{path}: its epochs were validated {validated[-1]}, this run's would be "
            f"{val_as} (the best epoch would be chosen by two measures); resume with the "
            "same --node-config"
        )
    return ckpt


def init_from(model: MaskRCNN, path: Path, classes: Sequence[str]) -> list[str]:
    """Copy into ``model`` the tensors of Mask R-CNN weights ``path`` that it has by the same name and
    shape; returns the names it has that the file does not give (left as initialised). InputError
    for weights of another kind or class list, or that give less than half the model's parameters."""
    try:
        manifest = read_manifest(path)
    except WeightsError as exc:
        raise InputError(str(exc)) from exc
    if manifest["kind"] != KIND or manifest["classes"] != list(classes):
        raise InputError(
            f"{path}: --init needs {KIND} weights for classes {list(classes)}, not "
            f"{manifest['kind']} weights for {manifest['classes']}"
        )
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for a corrupt file
        raise InputError(f"{path}: unreadable weights: {exc}") from exc
    own = model.state_dict()
    given = {k: v for k, v in state.items() if k in own and own[k].shape == v.shape}
    params = dict(model.named_parameters())
    total = sum(v.numel() for v in params.values())
    share = sum(v.numel() for k, v in params.items() if k in given) / max(total, 1)
    if share < 0.5:  # a model of another size: a few biases would match, nothing learned would carry
        raise InputError(f"{path}: gives only {share:.0%} of the model's parameters (another --config?)")
    model.load_state_dict(given, strict=False)
    return sorted(set(own) - set(given))


@dataclass(frozen=True)
class Inputs:
    """What a training run reads, opened and checked."""

    cfg: MaskRCNNConfig
    settings: dict[str, Any]
    train_set: ImageSets
    val_set: ImageSet | None
    device: torch.device
    out: Path


def open_inputs(args: argparse.Namespace) -> Inputs:
    """The run's inputs; InputError for the first that cannot be used (``--init`` and ``--resume``
    are read, and refused, where the run loads them)."""
    cfg = build_config(parse_overrides(args.config))
    settings = weights_settings(cfg, args.max_size)
    train_set = open_sets(args.train, cfg.classes)
    device = resolve_device(args.device)
    val_set = open_set(args.val, cfg.classes) if args.val else None
    out = Path(args.out)
    if out.suffix != ".pt":
        raise InputError(f"{out}: --out must end in .pt")
    if len(train_set) < args.batch * args.ranks:
        raise InputError(
            f"{', '.join(map(str, train_set.roots))}: {len(train_set)} images, fewer than "
            f"--batch {args.batch} times --ranks {args.ranks}"
        )
    if args.node_config:
        node_segmenter(args.node_config, MaskRCNN(cfg), args.max_size)  # refused here, not after an epoch
    return Inputs(cfg, settings, train_set, val_set, device, out)


def refuse_bad_inputs(args: argparse.Namespace) -> None:
    """Every InputError the run's inputs give, weights and checkpoint included, raised here: with
    ``--ranks`` the command calls this before it starts the processes, so that a bad input is
    refused once, with exit status 2, not by every process."""
    inputs = open_inputs(args)
    if args.init:
        init_from(MaskRCNN(inputs.cfg), Path(args.init), inputs.cfg.classes)
    if args.resume:
        _load_checkpoint(Path(args.resume), inputs.settings, inputs.cfg.classes, validated_as(args))


def train(args: argparse.Namespace, ranks: Ranks | None = None) -> int:
    """Train as ``args`` say; with ``ranks`` as one of several processes (``--ranks``), each on its
    share of every step's batch, the leader alone printing, validating and saving."""
    ranks = ranks or Ranks()
    say = print if ranks.leader else _silent
    inputs = open_inputs(args)
    cfg, settings, train_set, val_set, device, out = (
        inputs.cfg,
        inputs.settings,
        inputs.train_set,
        inputs.val_set,
        inputs.device,
        inputs.out,
    )
    paths = output_paths(out)
    if ranks.leader:
        out.parent.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    model = MaskRCNN(cfg)
    if args.init:
        fresh = init_from(model, Path(args.init), cfg.classes)
        say(
            f"initialised from {args.init}"
            + (f"; {len(fresh)} tensors fresh, from {fresh[0]}" if fresh else ""),
            flush=True,
        )
    model.to(device)
    node = None
    if args.node_config and ranks.leader:  # only the leader validates
        node = node_segmenter(args.node_config, model, args.max_size)
    val_as = validated_as(args)
    optimizer = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    aug = Augment(noise=args.sensor_noise, blur=args.blur)
    loss_keys = (*LOSSES, SEMANTIC) if cfg.semantic_classes else LOSSES
    steps_per_epoch = len(ranks.batches(range(len(train_set)), args.batch))
    epochs = args.epochs  # lowered by --time-budget-min once the run's pace is known
    total_steps = epochs * steps_per_epoch
    history: list[dict[str, Any]] = []
    step_losses: list[dict[str, float]] = []
    best_map, start_epoch, seconds_before = -1.0, 0, 0.0
    if args.resume:
        ckpt = _load_checkpoint(Path(args.resume), settings, cfg.classes, validated_as(args))
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        torch.set_rng_state(ckpt["torch_rng"])
        history, step_losses = ckpt["history"], ckpt["step_losses"]
        best_map, start_epoch, seconds_before = ckpt["best_map"], ckpt["epoch"], ckpt["seconds"]
        say(f"resuming {args.resume} after epoch {start_epoch}", flush=True)
        if start_epoch >= epochs:
            say(f"nothing to do: the checkpoint has {start_epoch} epochs, --epochs is {epochs}")
    ranks.same_as_leader(model)
    if ranks.size > 1:
        torch.manual_seed(args.seed + ranks.rank)  # each process samples its own anchors and RoIs
    say(
        f"train {', '.join(map(str, train_set.roots))} ({len(train_set)} images)"
        + (f", val {val_set.root} ({len(val_set)} images, {val_as})" if val_set else ", no validation set")
        + f"; {sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters; "
        f"{steps_per_epoch} steps per epoch; max size {args.max_size or 'full'}; {args.threads} threads; "
        f"device {device}; {args.workers} loader workers"
        + (
            f"; {ranks.size} processes sharing each step's {args.batch * ranks.size} images"
            if ranks.size > 1
            else ""
        ),
        flush=True,
    )
    data = TrainingImages(train_set, args.max_size, args.min_area, aug, args.seed)
    probe = pace_probe_step(steps_per_epoch) if args.time_budget_min is not None else 0
    t_start = time.perf_counter()
    steps_done = 0
    epoch = start_epoch
    while epoch < epochs:
        # The order depends only on (seed, epoch), the augmentation on (seed, epoch, image).
        order = np.random.default_rng([args.seed, epoch]).permutation(len(train_set)).tolist()
        data.epoch = epoch
        loader = torch.utils.data.DataLoader(
            data,
            batch_sampler=ranks.batches(order, args.batch),
            num_workers=args.workers,
            collate_fn=_as_list,
            worker_init_fn=_one_thread,
            prefetch_factor=4 if args.workers else None,
        )
        t_epoch = t_window = time.perf_counter()
        window_images = 0
        epoch_losses: list[dict[str, float]] = []
        for step, batch in enumerate(loader):
            sizes = {tuple(b[0].shape[-2:]) for b in batch}
            if len(sizes) > 1:
                raise InputError(
                    f"{', '.join(map(str, train_set.roots))}: images of different sizes "
                    f"{sorted(sizes)} in the training sets"
                )
            global_step = epoch * steps_per_epoch + step
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(global_step, total_steps, args.lr)
            images = torch.stack([b[0] for b in batch]).to(device)
            targets = [{k: v.to(device) for k, v in b[1].items()} for b in batch]
            losses = ranks.mean(
                train_step(
                    model, optimizer, images, targets, before_step=lambda: ranks.average_gradients(model)
                )
            )
            if not math.isfinite(losses["total"]):
                say(
                    f"error: loss is {losses['total']} at epoch {epoch + 1} step {step + 1}; "
                    "try a lower --lr",
                    file=sys.stderr,
                )
                return 1
            step_losses.append(losses)
            epoch_losses.append(losses)
            steps_done += 1
            if steps_done == probe:
                pace = (time.perf_counter() - t_start) / steps_done * steps_per_epoch
                # The leader's clock decides, so that every process trains the same epochs.
                budget_s = args.time_budget_min * 60.0
                fit = ranks.from_leader(epochs_at_pace(budget_s, pace, start_epoch, epochs))
                if fit < epochs:
                    how = f" (from the first {steps_done} steps)"
                    say(_budget_line(args.time_budget_min, fit, epochs, how), flush=True)
                    epochs, total_steps = fit, fit * steps_per_epoch
            window_images += len(batch) * ranks.size
            if (step + 1) % args.log_every == 0 or step + 1 == steps_per_epoch:
                now = time.perf_counter()
                rate = window_images / max(now - t_window, 1e-9)
                left = (now - t_start) / steps_done * (total_steps - global_step - 1)
                terms = " ".join(f"{SHORT[k]} {losses[k]:.3f}" for k in loss_keys)
                say(
                    f"epoch {epoch + 1}/{epochs} step {step + 1}/{steps_per_epoch} | "
                    f"{rate:.2f} img/s | {terms} total {losses['total']:.3f} | "
                    f"lr {optimizer.param_groups[0]['lr']:.1e} | ETA {_duration(left)}",
                    flush=True,
                )
                t_window, window_images = now, 0
        if not ranks.replicas_agree(model):
            say(f"error: the {ranks.size} processes' weights differ after epoch {epoch + 1}", file=sys.stderr)
            return 1
        record: dict[str, Any] = {
            "epoch": epoch + 1,
            "train_losses": {k: float(np.mean([s[k] for s in epoch_losses])) for k in (*loss_keys, "total")},
            "train_seconds": time.perf_counter() - t_epoch,
            "val_map": None,
            "val_ap50": {},
        }
        improved = True
        if val_set is not None and ranks.leader:
            result = evaluate(model, val_set, args.max_size, args.val_limit, node)
            record.update(
                val_map=result["map"],
                val_ap50=result["per_class"],
                val_as=val_as,
                val_seconds_per_image=result["seconds_per_image"],
            )
            improved = result["map"] > best_map
            say(
                f"epoch {epoch + 1}/{epochs} val {format_ap(result, cfg.classes)} | "
                f"{result['seconds_per_image'] * 1e3:.0f} ms/image | train loss "
                f"{record['train_losses']['total']:.3f}" + (" | best so far" if improved else ""),
                flush=True,
            )
        history.append(record)
        seconds = seconds_before + time.perf_counter() - t_start
        if improved and ranks.leader:
            best_map = record["val_map"] if record["val_map"] is not None else best_map
            figures = {
                "epochs": epoch + 1,
                "best_epoch": epoch + 1,
                "images": len(train_set),
                "val_images": len(val_set) if val_set else 0,
                "train": [str(root) for root in train_set.roots],
                "train_recipes": [images.recipe for images in train_set.sets],
                "val": str(val_set.root) if val_set else None,
                "val_as": val_as,
                "final_losses": record["train_losses"],
                "val_map": record["val_map"],
                "val_ap50": record["val_ap50"],
                "seconds": round(seconds, 1),
                "batch": args.batch,
                "processes": ranks.size,
                "lr": args.lr,
                "seed": args.seed,
                "min_area": args.min_area,
                "device": str(device),
                "augment": asdict(aug),
                "history": history,
            }
            save_weights(model, out, KIND, VERSION, cfg.classes, settings, {"figures": figures})
            say(f"saved {out} (epoch {epoch + 1})", flush=True)
        if ranks.leader:
            _save_checkpoint(
                paths["checkpoint"],
                {
                    "kind": f"{KIND}_checkpoint",
                    "classes": list(cfg.classes),
                    "settings": settings,
                    "epoch": epoch + 1,
                    "model": model.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "torch_rng": torch.get_rng_state(),
                    "history": history,
                    "step_losses": step_losses,
                    "best_map": best_map,
                    "seconds": seconds,
                },
            )
            plot_curves(paths["curves"], step_losses, history, cfg.classes)
        epoch += 1
        if args.time_budget_min is not None:
            # The leader's clock decides, so that every process trains the same epochs.
            fit = ranks.from_leader(
                epochs_within(
                    args.time_budget_min * 60.0,
                    time.perf_counter() - t_start,
                    epoch - start_epoch,
                    epoch,
                    epochs,
                )
            )
            if fit < epochs:
                say(_budget_line(args.time_budget_min, fit, epochs), flush=True)
                epochs, total_steps = fit, fit * steps_per_epoch
    if not ranks.leader:
        return 0
    if not out.is_file():
        raise InputError(f"{out}: no weights written (no epoch was trained)")
    best, _ = load_mask_rcnn(out, cfg.classes)  # the saved file, checked as the node will load it
    plot_samples(paths["samples"], best, val_set or train_set, args.max_size)
    plot_curves(paths["curves"], step_losses, history, cfg.classes)
    print(
        f"wrote {out}, {paths['checkpoint']}, {paths['curves']}, {paths['samples']} in "
        f"{_duration(time.perf_counter() - t_start)}",
        flush=True,
    )
    return 0


def evaluate_command(args: argparse.Namespace) -> int:
    torch.set_num_threads(args.threads)
    device = resolve_device(args.device)
    try:
        model, manifest = load_mask_rcnn(args.evaluate)
    except WeightsError as exc:
        raise InputError(str(exc)) from exc
    model.to(device)
    max_size = manifest["settings"].get("max_size")
    images = open_set(args.val, model.cfg.classes)
    node = node_segmenter(args.node_config, model, max_size) if args.node_config else None
    result = evaluate(model, images, max_size, args.val_limit, node)
    print(
        f"{args.evaluate} on {images.root} ({result['images']} images, max size {max_size or 'full'}, "
        f"{args.threads} threads, {device}), "
        + (f"as the node segments ({args.node_config})" if node is not None else "the model alone")
    )
    for c in model.cfg.classes:
        ap = result["per_class"].get(c)
        print(f"  {c:<14} AP50 {ap:.3f}" if ap is not None else f"  {c:<14} AP50 -  (no instances)")
    print(f"  mean           AP50 {result['map']:.3f}")
    print(f"  inference {result['seconds_per_image'] * 1e3:.0f} ms per image")
    return 0


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tlt_tools.vision_training.mask_rcnn", description=__doc__.split("\n")[0]
    )
    p.add_argument(
        "--train", nargs="+", help="training image sets (directories with index.json), read as one"
    )
    p.add_argument("--val", help="validation image set: AP50 after each epoch, best epoch kept")
    p.add_argument(
        "--out", default="build/vision/mask_rcnn.pt", help="weights file (.pt); manifest beside it"
    )
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--lr", type=float, default=1e-3, help="AdamW peak learning rate")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument(
        "--device", default="cpu", help="torch device to train and evaluate on (cpu, cuda, cuda:1)"
    )
    p.add_argument(
        "--workers",
        type=int,
        default=0,
        help="processes loading and augmenting training images (0: the training process); "
        "with --ranks, each training process's",
    )
    p.add_argument(
        "--ranks",
        type=int,
        default=1,
        help="training processes on the device, each on --batch images of every step, their "
        "gradients averaged (the step's batch is --batch times --ranks)",
    )
    p.add_argument(
        "--max-size",
        type=int,
        default=None,
        help="downscale images so the longest side is at most this (pixels); recorded in the "
        "manifest so inference uses the same size (default: full size)",
    )
    p.add_argument(
        "--min-area",
        type=int,
        default=4,
        help="drop training instances with fewer pixels than this at the model's size",
    )
    p.add_argument(
        "--sensor-noise",
        type=float,
        default=0.0,
        metavar="GREY_LEVELS",
        help="Gaussian colour noise of each training image, 1 sigma uniform in 0..this grey"
        " levels of 255, as a real camera's sensor adds (default 0: none)",
    )
    p.add_argument(
        "--blur",
        type=float,
        default=0.0,
        metavar="PIXELS",
        help="Gaussian blur of each training image, sigma uniform in 0..this pixels at the"
        " model's size, as real optics add (default 0: none)",
    )
    p.add_argument(
        "--config",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="MaskRCNNConfig field (JSON value), e.g. fpn_channels=32; repeatable",
    )
    p.add_argument(
        "--time-budget-min",
        type=float,
        default=None,
        help="train only the epochs that fit in this many minutes, judged from the epochs run "
        "(the learning rate's decay is fitted to them)",
    )
    p.add_argument("--log-every", type=int, default=10, help="steps between progress lines")
    p.add_argument("--val-limit", type=int, default=None, help="evaluate on the first N validation images")
    p.add_argument(
        "--node-config",
        metavar="NODE_YAML",
        help="validate the masks as the vision node configured by this file makes them "
        "(e.g. config/vision/node.yaml), not the model's alone",
    )
    p.add_argument("--resume", help="checkpoint (<out stem>_checkpoint.pt) to continue from")
    p.add_argument(
        "--init",
        metavar="WEIGHTS",
        help="start from these trained weights (tensors of the same name and shape)",
    )
    p.add_argument(
        "--evaluate", metavar="WEIGHTS", help="evaluate these weights on --val instead of training"
    )
    args = p.parse_args(argv)
    for name in ("epochs", "batch", "threads", "log_every", "ranks"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")
    if args.workers < 0:
        p.error("--workers must be at least 0")
    if args.time_budget_min is not None and args.time_budget_min <= 0:
        p.error("--time-budget-min must be positive")
    if not 0.0 <= args.sensor_noise <= 64.0:
        p.error(f"--sensor-noise {args.sensor_noise:g}: grey levels from 0 to 64")
    if not 0.0 <= args.blur <= 5.0:
        p.error(f"--blur {args.blur:g}: pixels from 0 to 5")
    if args.max_size is not None and args.max_size < 32:
        p.error("--max-size must be at least 32 pixels")
    if args.init and args.resume:
        p.error("--init and --resume exclude each other (a checkpoint holds the weights)")
    if args.evaluate and not args.val:
        p.error("--evaluate needs --val")
    if args.node_config and not args.val:
        p.error("--node-config needs --val")
    if not args.evaluate and not args.train:
        p.error("--train is required (or --evaluate WEIGHTS --val DIR)")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        if args.evaluate:
            return evaluate_command(args)
        if args.ranks > 1:
            refuse_bad_inputs(args)
        return run_ranks(train, args.ranks, args, refused=(InputError, DatasetError))
    except (InputError, DatasetError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
