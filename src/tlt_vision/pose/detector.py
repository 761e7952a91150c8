"""A small PointNet keypoint detector: a point cloud in, the model's K keypoints out (camera frame).

The cloud is centred on its (masked) mean and divided by ``scale`` (half the part's size) so one
network serves a part seen anywhere; a shared per-point MLP, max and mean pooling, and a regression
head give the keypoints in that normalised frame, which are then mapped back. Sized for the CPU:
with ``width=64`` it has about 0.2 M parameters.
"""

from __future__ import annotations

import torch
from torch import nn


class KeypointDetector(nn.Module):
    """PointNet regression of ``num_keypoints`` 3-D keypoints from a (B, N, 3) cloud."""

    def __init__(self, num_keypoints: int, scale: float, width: int = 64) -> None:
        super().__init__()
        if num_keypoints < 1 or scale <= 0 or width < 4:
            raise ValueError("need num_keypoints >= 1, scale > 0 and width >= 4")
        self.num_keypoints = num_keypoints
        self.width = width
        self.register_buffer("scale", torch.tensor(float(scale)))
        self.point_mlp = nn.Sequential(
            nn.Conv1d(3, width, 1),
            nn.ReLU(),
            nn.Conv1d(width, 2 * width, 1),
            nn.ReLU(),
            nn.Conv1d(2 * width, 4 * width, 1),
        )
        self.head = nn.Sequential(
            nn.Linear(8 * width, 4 * width),
            nn.ReLU(),
            nn.Linear(4 * width, 2 * width),
            nn.ReLU(),
            nn.Linear(2 * width, 3 * num_keypoints),
        )

    def forward(self, points: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Keypoints (B, K, 3) in the frame of ``points``; ``mask`` (B, N) marks real points."""
        b, n, _ = points.shape
        if mask is None:
            mask = torch.ones(b, n, dtype=torch.bool, device=points.device)
        m = mask.to(points.dtype)[..., None]
        count = m.sum(1).clamp(min=1.0)
        centre = (points * m).sum(1) / count
        x = ((points - centre[:, None]) / self.scale * m).transpose(1, 2)
        f = self.point_mlp(x)  # (B, 4w, N)
        neg = torch.finfo(f.dtype).min
        fmax = f.masked_fill(~mask[:, None, :], neg).max(dim=2).values
        fmean = (f * m.transpose(1, 2)).sum(2) / count
        out = self.head(torch.cat([fmax, fmean], dim=1)).view(b, self.num_keypoints, 3)
        return out * self.scale + centre[:, None]


def symmetric_keypoint_loss(
    predicted: torch.Tensor, target: torch.Tensor, symmetries: torch.Tensor
) -> torch.Tensor:
    """Mean squared keypoint error, taking the best of the model's symmetric relabellings.

    ``symmetries`` (P, K): a part with a symmetry looks the same after it, so its keypoint labels
    are only defined up to these permutations; the loss must not punish either choice.
    """
    # target[:, perm] for every perm: (B, P, K, 3)
    candidates = target[:, symmetries]
    err = (predicted[:, None] - candidates).pow(2).sum(-1).mean(-1)  # (B, P)
    return err.min(dim=1).values.mean()


__all__ = ["KeypointDetector", "symmetric_keypoint_loss"]
