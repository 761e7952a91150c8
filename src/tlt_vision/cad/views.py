"""Synthetic depth-camera views of a posed CAD model (for training and tests without a renderer).

A camera at the origin looks along +z (x right, y down, as OpenCV). A view keeps the surface points
that face the camera and are the nearest along their line of sight (a z-buffer on a grid of
viewing angles), then draws ``n`` of them, optionally with Gaussian depth noise: what a masked
depth image back-projects to.
"""

from __future__ import annotations

import numpy as np

from tlt_vision.cad.models import CadModel


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation drawn uniformly from SO(3)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def visible_points(
    model: CadModel,
    rot: np.ndarray,
    t: np.ndarray,
    rng: np.random.Generator,
    dense: int = 8192,
    angle_step: float = 0.002,
    depth_tolerance: float = 0.003,
) -> np.ndarray:
    """Points (m, 3) of the posed model seen from the origin, in the camera frame."""
    pts, nrm = model.sample(dense, rng)
    p = pts @ rot.T + t
    n = nrm @ rot.T
    facing = (n * p).sum(1) < 0
    p = p[facing & (p[:, 2] > 1e-3)]
    if len(p) == 0:
        return p
    u = np.floor(p[:, 0] / p[:, 2] / angle_step).astype(np.int64)
    v = np.floor(p[:, 1] / p[:, 2] / angle_step).astype(np.int64)
    # One bin per occupied (u, v) cell: a dense grid over the view's angular extent can be huge
    # (a point just ahead of the camera spans thousands of cells and asked for a 76 GiB array).
    _, key = np.unique(np.stack([u, v], axis=1), axis=0, return_inverse=True)
    key = key.reshape(-1)
    depth = np.linalg.norm(p, axis=1)
    nearest = np.full(int(key.max()) + 1, np.inf)
    np.minimum.at(nearest, key, depth)
    return p[depth <= nearest[key] + depth_tolerance]


def synthetic_view(
    model: CadModel,
    rot: np.ndarray,
    t: np.ndarray,
    n: int,
    rng: np.random.Generator,
    noise: float = 0.0,
    **kw: float,
) -> np.ndarray:
    """``n`` points (fewer if fewer are visible) of a noisy partial view of the posed model."""
    p = visible_points(model, rot, t, rng, **kw)
    if len(p) > n:
        p = p[rng.choice(len(p), n, replace=False)]
    if noise > 0:
        p = p + rng.normal(scale=noise, size=p.shape)
    return p


__all__ = ["random_rotation", "synthetic_view", "visible_points"]
