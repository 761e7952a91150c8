"""Anchor boxes for the RPN, one size per FPN level and several aspect ratios per location."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch


def base_anchors(size: float, ratios: Sequence[float]) -> torch.Tensor:
    """Anchors ``(A, 4)`` centred on the origin, each of area ``size**2``; ratio is height/width."""
    out = []
    for r in ratios:
        w = size / math.sqrt(r)
        h = size * math.sqrt(r)
        out.append([-w / 2, -h / 2, w / 2, h / 2])
    return torch.tensor(out, dtype=torch.float32)


def grid_anchors(
    feature_size: tuple[int, int], stride: int, size: float, ratios: Sequence[float]
) -> torch.Tensor:
    """All anchors of one level, ``(H * W * A, 4)``, ordered row, column, ratio.

    Anchors are centred on the centre of their feature cell, ``((x + 0.5) * stride,
    (y + 0.5) * stride)``, matching RoIAlign's ``aligned=True`` pixel model.
    """
    h, w = feature_size
    base = base_anchors(size, ratios)
    ys = (torch.arange(h, dtype=torch.float32) + 0.5) * stride
    xs = (torch.arange(w, dtype=torch.float32) + 0.5) * stride
    cy, cx = torch.meshgrid(ys, xs, indexing="ij")
    shifts = torch.stack([cx, cy, cx, cy], dim=-1).reshape(-1, 1, 4)
    return (shifts + base[None]).reshape(-1, 4)


def pyramid_anchors(
    feature_sizes: Sequence[tuple[int, int]],
    strides: Sequence[int],
    sizes: Sequence[float],
    ratios: Sequence[float],
) -> list[torch.Tensor]:
    """One anchor tensor per FPN level (see :func:`grid_anchors`)."""
    if not len(feature_sizes) == len(strides) == len(sizes):
        raise ValueError("feature_sizes, strides and sizes need one entry per level")
    return [
        grid_anchors(fs, st, sz, ratios) for fs, st, sz in zip(feature_sizes, strides, sizes, strict=True)
    ]


__all__ = ["base_anchors", "grid_anchors", "pyramid_anchors"]
