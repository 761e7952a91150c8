"""A small convolutional backbone (four stages, strides 4 to 32) and a feature pyramid (FPN)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def _norm(channels: int) -> nn.GroupNorm:
    # GroupNorm: batch statistics of 1-2 images per step would make BatchNorm useless.
    return nn.GroupNorm(min(8, channels), channels)


def _block(cin: int, cout: int, stride: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False),
        _norm(cout),
        nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False),
        _norm(cout),
        nn.ReLU(inplace=True),
    )


class Backbone(nn.Module):
    """Image (B, 3, H, W) -> [C2, C3, C4, C5] at strides 4, 8, 16, 32 (and the stem at 2)."""

    def __init__(self, channels: tuple[int, int, int, int]) -> None:
        super().__init__()
        c2, c3, c4, c5 = channels
        self.stem = nn.Sequential(
            nn.Conv2d(3, c2, 3, stride=2, padding=1, bias=False), _norm(c2), nn.ReLU(inplace=True)
        )
        self.stages = nn.ModuleList(
            [_block(c2, c2, 2), _block(c2, c3, 2), _block(c3, c4, 2), _block(c4, c5, 2)]
        )

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        return self.pyramid(x)[1]

    def pyramid(self, x: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        """The stem's stride-2 features and [C2..C5]."""
        stem = x = self.stem(x)
        out = []
        for stage in self.stages:
            x = stage(x)
            out.append(x)
        return stem, out


class FPN(nn.Module):
    """Top-down feature pyramid: [C2..C5] -> [P2..P5], all with ``channels`` channels."""

    def __init__(self, in_channels: tuple[int, ...], channels: int) -> None:
        super().__init__()
        self.lateral = nn.ModuleList([nn.Conv2d(c, channels, 1) for c in in_channels])
        self.output = nn.ModuleList([nn.Conv2d(channels, channels, 3, padding=1) for _ in in_channels])

    def forward(self, feats: list[torch.Tensor]) -> list[torch.Tensor]:
        x = self.lateral[-1](feats[-1])
        outs = [self.output[-1](x)]
        for i in range(len(feats) - 2, -1, -1):
            lat = self.lateral[i](feats[i])
            x = lat + F.interpolate(x, size=lat.shape[-2:], mode="nearest")
            outs.insert(0, self.output[i](x))
        return outs


__all__ = ["FPN", "Backbone"]
