"""How well a noisy cloud places a pose: the ADD-S error a least-squares fit to it should make.

A stereo camera's depth moves each point along its ray by more than a certificate threshold held
to millimetres, but a pose fitted to hundreds of points averages that noise down: a 87 mm corner
joint 0.9 m from a ZED has 2.5 mm of noise left on each point and is still placed to about a
millimetre. Whether a pose can be trusted to 2 % of the part's size is therefore a question about
the fit, not about one point, and this module answers it the way a surveyor would: from the
linearised least-squares problem at the fitted pose.

Each observed point ``p_i`` constrains the pose along its model's surface normal ``n_i``: a small
motion of the part (translation ``dt``, rotation ``dw`` about the part's origin) changes its
distance to the surface by ``J_i . (dt, dw)``, ``J_i = (n_i, q_i x n_i)`` with ``q_i`` the point in
the part's frame. The fit solves ``sum J_i J_i^T x = ...`` (``H``); each point's noise
along its normal has variance ``v_i = (s_i (n_i . r_i))^2``, ``s_i`` the depth noise left on the
point along its ray ``r_i``. The fit's covariance is the sandwich ``H^-1 (k sum v_i J_i J_i^T)
H^-1``, where ``k`` counts how many points share one draw of the noise (neighbouring pixels err
together over the filter's window and the camera's own correlation), and is scaled up where the
fit's residuals are wider than the noise explains (the a posteriori variance factor: a wrong
model or a bad mask). The ADD-S error of a small motion is, for each model point ``x_j`` with
normal ``m_j``, its displacement along ``m_j``: ``a_j . (dt, dw)``, ``a_j = (m_j, x_j x m_j)``; its
expected square over the part is ``tr(M C)``, ``M`` the mean of ``a_j a_j^T``.

Motions that move no surface point off the surface (a tube turned about its axis) leave ``M``
empty in that direction; the fit is undetermined there and it does not matter: those directions
are taken out before inverting. So are the directions the cloud's normals hardly constrain (a
tube's place along its axis): the part's outline in the image places it there, which the depth's
noise does not move, and the certificate's keypoint groups and the axial checks judge it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree

from tlt_vision.cad.models import CadModel
from tlt_vision.depth_noise import DepthNoise

# Directions of ``M`` under this share of its largest eigenvalue move no surface point: symmetries.
SYMMETRY_EPS = 1e-7
# Directions of ``H`` under this share of its largest eigenvalue are placed by the part's outline
# in the image, not by its depth: a tube's place along its axis, where its surface's normals do not
# turn. The depth's noise does not move an outline, and the certificate's keypoint groups and the
# axial checks judge it (:mod:`tlt_vision.pose.axial_ends`).
OUTLINE_EPS = 1e-4


@dataclass(frozen=True)
class Precision:
    """The predicted ADD-S error (RMS, m) of a pose fitted to a cloud, and what went into it."""

    add_s: float  # m, RMS; inf where the cloud leaves a direction the part's surface shows free
    points_per_draw: float  # k: points sharing one draw of the noise
    variance_factor: float  # >= 1: the residuals' spread over the noise's
    # rad, 1 sigma: the largest turn the depth leaves the fit (about any axis a turn about which
    # moves the part's surface; a fitting's tilt, not its spin about its own axis)
    rotation: float = 0.0


def model_motion_matrix(model: CadModel, samples: int = 512) -> np.ndarray:
    """``M`` (6x6, part frame): the mean of ``a a^T`` over a surface sample, ``a = (m, x x m)``."""
    points, normals = model.sample(samples, np.random.default_rng(0))
    a = np.concatenate([normals, np.cross(points, normals)], axis=1)
    return a.T @ a / len(a)


def points_per_draw(points: np.ndarray, fx: float, noise: DepthNoise) -> float:
    """How many of ``points`` (camera frame) share one draw of the filtered depth noise: the
    noise's pixels per draw (:attr:`DepthNoise.pixels_per_draw`) over the pixels per point, from the
    points' median spacing in a frame of focal length ``fx``. Unknown focal length: a point a
    pixel."""
    area = noise.pixels_per_draw
    if len(points) < 2 or fx <= 0.0:
        return area
    z = np.maximum(points[:, 2], 1e-6)
    pixels = fx * points[:, :2] / z[:, None]
    spacing, _ = cKDTree(pixels).query(pixels, k=2)
    step = max(float(np.median(spacing[:, 1])), 1e-6)
    return max(1.0, area / (step * step))


def pose_precision(
    model: CadModel,
    motion: np.ndarray,
    points: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    noise: DepthNoise,
    fx: float,
) -> Precision:
    """The predicted ADD-S error of the pose ``rotation, translation`` (camera frame) fitted to
    ``points`` (N, 3, camera frame, the filtered cloud), given the depth's ``noise`` in a frame of
    focal length ``fx`` (pixels) and the part's ``motion`` matrix (:func:`model_motion_matrix`)."""
    p = np.asarray(points, dtype=np.float64)
    r = np.asarray(rotation, dtype=np.float64)
    t = np.asarray(translation, dtype=np.float64)
    if len(p) < 6:
        return Precision(math.inf, 1.0, 1.0)
    q = (p - t) @ r  # the points in the part's frame
    signed, gradient = model.surface.signed_with_gradient(torch.as_tensor(q, dtype=torch.float32))
    normals = gradient.double().numpy()
    residuals = signed.double().numpy()
    rays = (p / np.linalg.norm(p, axis=1, keepdims=True)) @ r
    sigma = noise.residual(p[:, 2])
    along = sigma * np.abs(np.einsum("ij,ij->i", normals, rays))
    variance = np.maximum(along * along, 1e-12)
    # The residuals' spread against the noise's: a fit whose points lie further from the model than
    # the noise puts them is less sure than the noise alone says.
    spread = float(np.mean(residuals * residuals) / np.mean(variance))
    factor = max(1.0, spread)
    k = points_per_draw(p, fx, noise)
    jac = np.concatenate([normals, np.cross(q, normals)], axis=1)
    h = jac.T @ jac
    b = k * factor * (jac * variance[:, None]).T @ jac
    # Take out the directions no surface point moves along: symmetries of the part.
    m_values, m_vectors = np.linalg.eigh(motion)
    keep = m_vectors[:, m_values > SYMMETRY_EPS * m_values.max()]
    h_values, h_vectors = np.linalg.eigh(keep.T @ h @ keep)
    depth_placed = h_values > OUTLINE_EPS * max(float(h_values.max()), 1e-30)
    basis = keep @ h_vectors[:, depth_placed]
    h_inv = np.diag(1.0 / h_values[depth_placed])
    covariance = h_inv @ (basis.T @ b @ basis) @ h_inv
    add_s = math.sqrt(max(float(np.trace(basis.T @ motion @ basis @ covariance)), 0.0))
    turn = (basis @ covariance @ basis.T)[3:, 3:]
    rotation = math.sqrt(max(float(np.linalg.eigvalsh(turn).max()), 0.0))
    return Precision(add_s, k, factor, rotation)


__all__ = ["Precision", "model_motion_matrix", "points_per_draw", "pose_precision"]
