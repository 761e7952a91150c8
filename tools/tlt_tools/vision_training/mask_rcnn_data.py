"""The Mask R-CNN trainer's inputs: the rendered image sets opened and checked, their samples
loaded at the model's size and augmented, the loader's helpers, and the torch device; an input that
cannot be used raises :class:`InputError`, naming the path and the reason."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tlt_tools.vision_training.dataset import DatasetError, ImageSet, ImageSets
from tlt_vision.ops.boxes import boxes_from_masks
from tlt_vision.segmentation.inference import resize_image, resize_masks, rgb_to_tensor, scaled_size


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


def as_list(batch: list[Any]) -> list[Any]:
    return batch


def silent(*_args: Any, **_kwargs: Any) -> None:
    """``print`` for the processes that are not the leader."""


def one_thread(_worker: int) -> None:
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
