"""Toy scenes of coloured shapes with exact masks, for tests and for checking a training loop.

Each scene has 1-3 objects drawn from the class list: a class is a colour and a shape (a long bar
for tubes, a short thick bar for fittings, a hollow square for frames, a square block for corners,
a small disc for rivets), on a noisy background. They are not the twin's renders (those come from
its camera pipeline); they exercise the model, losses and evaluation end to end in seconds.
"""

from __future__ import annotations

import numpy as np
import torch

COLOURS = np.array(
    [[0.78, 0.80, 0.83], [0.95, 0.55, 0.10], [0.55, 0.70, 0.85], [0.15, 0.35, 0.75], [0.90, 0.10, 0.10]]
)


def _shape_mask(label: int, h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    cx, cy = rng.uniform(0.25, 0.75) * w, rng.uniform(0.25, 0.75) * h
    s = min(h, w)
    if label in (1, 2):  # tube, fitting: rotated bars
        length, half_t = (0.6 * s, 0.04 * s) if label == 1 else (0.2 * s, 0.08 * s)
        a = rng.uniform(0, np.pi)
        u, v = np.cos(a), np.sin(a)
        along = (xx - cx) * u + (yy - cy) * v
        across = -(xx - cx) * v + (yy - cy) * u
        return (np.abs(along) <= length / 2) & (np.abs(across) <= half_t)
    if label == 3:  # frame: hollow square
        half = rng.uniform(0.18, 0.3) * s
        d = np.maximum(np.abs(xx - cx), np.abs(yy - cy))
        return (d <= half) & (d >= half - 0.05 * s)
    if label == 4:  # corner joint: block
        half = rng.uniform(0.07, 0.12) * s
        return (np.abs(xx - cx) <= half) & (np.abs(yy - cy) <= half)
    r = rng.uniform(0.04, 0.07) * s  # rivet: disc
    return (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r


def toy_scene(
    rng: np.random.Generator, size: tuple[int, int] = (64, 64), num_classes: int = 5
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """An image (3, H, W) in [0, 1] and its target (boxes, labels, masks), objects not overlapping."""
    h, w = size
    img = rng.uniform(0.0, 0.25, size=(h, w, 3))
    occupied = np.zeros((h, w), dtype=bool)
    masks, labels = [], []
    for _ in range(int(rng.integers(1, 4))):
        label = int(rng.integers(1, num_classes + 1))
        for _attempt in range(10):
            m = _shape_mask(label, h, w, rng)
            if m.sum() >= 4 and not (m & occupied).any():
                break
        else:
            continue
        occupied |= m
        img[m] = COLOURS[(label - 1) % len(COLOURS)] + rng.normal(scale=0.03, size=(int(m.sum()), 3))
        masks.append(m)
        labels.append(label)
    boxes = []
    for m in masks:
        ys, xs = np.nonzero(m)
        boxes.append([xs.min(), ys.min(), xs.max() + 1.0, ys.max() + 1.0])
    target = {
        "boxes": torch.tensor(np.array(boxes, dtype=np.float32).reshape(-1, 4)),
        "labels": torch.tensor(labels, dtype=torch.long),
        "masks": torch.tensor(np.array(masks, dtype=bool).reshape(-1, h, w)),
    }
    return torch.tensor(np.clip(img, 0, 1), dtype=torch.float32).permute(2, 0, 1), target


def toy_batch(
    rng: np.random.Generator, n: int, size: tuple[int, int] = (64, 64)
) -> tuple[torch.Tensor, list[dict[str, torch.Tensor]]]:
    scenes = [toy_scene(rng, size) for _ in range(n)]
    return torch.stack([s[0] for s in scenes]), [s[1] for s in scenes]


__all__ = ["COLOURS", "toy_batch", "toy_scene"]
