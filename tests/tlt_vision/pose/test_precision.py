"""The predicted precision of a pose fitted to a noisy cloud (tlt_vision.pose.precision)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from tlt_vision.cad.models import build_models
from tlt_vision.depth_noise import DepthNoise, draw_area
from tlt_vision.pose.errors import add_s
from tlt_vision.pose.precision import model_motion_matrix, points_per_draw, pose_precision

MODELS = build_models(0.75, {"vertical": 0.75})
# One filtered point's noise: 1 mm at 1 m, growing with the depth's square; independent from
# point to point (a window of 1, no correlation, points far apart in the image).
NOISE = DepthNoise(per_m2=0.001 * 5 / math.sqrt(math.pi / 2), window=1)
FX = 600.0


def _seen(model_name: str, rotation: np.ndarray, t: np.ndarray, n: int = 400) -> np.ndarray:
    """Surface points of the model facing a camera at the origin (camera frame)."""
    model = MODELS[model_name]
    points, normals = model.sample(4 * n, np.random.default_rng(3))
    p = points @ rotation.T + t
    facing = np.einsum("ij,ij->i", normals @ rotation.T, p) < 0
    return p[facing][:n]


def _fit(model_name: str, cloud: np.ndarray, rotation: np.ndarray, t: np.ndarray) -> tuple:
    """Least-squares point-to-surface fit (Gauss-Newton) from the given pose."""
    model = MODELS[model_name]
    r, t = rotation.copy(), t.copy()
    for _ in range(6):
        q = (cloud - t) @ r
        d, g = model.surface.signed_with_gradient(torch.as_tensor(q, dtype=torch.float64))
        d, g = d.numpy(), g.numpy()
        jac = np.concatenate([g, np.cross(q, g)], axis=1)
        step = np.linalg.lstsq(jac, -d, rcond=None)[0]
        # The step moves the part (in its own frame) by dt and turns it by dw.
        dt, dw = step[:3], step[3:]
        angle = np.linalg.norm(dw)
        if angle > 0:
            k = dw / angle
            kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            turn = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
        else:
            turn = np.eye(3)
        t = t - r @ dt
        r = r @ turn.T
    return r, t


def test_the_predicted_error_matches_the_spread_of_least_squares_fits():
    """Over 30 draws of the noise the fits' ADD-S errors spread as predicted (within a factor)."""
    model = MODELS["end_fitting"]
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, -0.8], [0.0, 0.8, 0.6]])
    t = np.array([0.02, -0.01, 0.8])
    clean = _seen("end_fitting", rot, t)
    rays = clean / np.linalg.norm(clean, axis=1, keepdims=True)
    rng = np.random.default_rng(0)
    sigma = NOISE.residual(clean[:, 2])
    errors = []
    for _ in range(30):
        noisy = clean + rays * (sigma * rng.standard_normal(len(clean)))[:, None]
        r, tt = _fit("end_fitting", noisy, rot, t)
        errors.append(add_s(model, r, tt, rot, t))
    predicted = pose_precision(model, model_motion_matrix(model), clean, rot, t, NOISE, FX)
    measured = float(np.sqrt(np.mean(np.square(errors))))
    assert predicted.variance_factor == pytest.approx(1.0, abs=0.05)
    assert 0.5 < measured / predicted.add_s < 1.5, (measured, predicted)


def test_a_part_further_away_is_placed_worse():
    model = MODELS["corner_joint"]
    motion = model_motion_matrix(model)
    rot = np.eye(3)
    near, far = np.array([0.0, 0.0, 0.5]), np.array([0.0, 0.0, 1.0])
    p_near = pose_precision(model, motion, _seen("corner_joint", rot, near), rot, near, NOISE, FX)
    p_far = pose_precision(model, motion, _seen("corner_joint", rot, far), rot, far, NOISE, FX)
    # The noise grows with the depth's square; the same number of points.
    assert p_far.add_s == pytest.approx(4 * p_near.add_s, rel=0.35)


def test_a_tube_turned_about_its_axis_or_slid_along_it_leaves_the_precision_finite():
    """A tube's turn about its axis moves no surface point and its place along the axis is the
    outline's: neither makes the depth's precision infinite."""
    model = MODELS["strut_tube/vertical"]
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # axis across the view
    t = np.array([0.0, 0.0, 0.9])
    cloud = _seen("strut_tube/vertical", rot, t)
    cloud = cloud[np.abs(cloud[:, 0]) < 0.2]  # neither end seen
    p = pose_precision(model, model_motion_matrix(model), cloud, rot, t, NOISE, FX)
    assert math.isfinite(p.add_s) and p.add_s < 0.002


def test_residuals_wider_than_the_noise_widen_the_prediction():
    model = MODELS["end_fitting"]
    motion = model_motion_matrix(model)
    rot, t = np.eye(3), np.array([0.0, 0.0, 0.6])
    clean = _seen("end_fitting", rot, t)
    rays = clean / np.linalg.norm(clean, axis=1, keepdims=True)
    rng = np.random.default_rng(1)
    sigma = NOISE.residual(clean[:, 2])
    as_said = clean + rays * (sigma * rng.standard_normal(len(clean)))[:, None]
    wider = clean + rays * (4 * sigma * rng.standard_normal(len(clean)))[:, None]
    p_said = pose_precision(model, motion, as_said, rot, t, NOISE, FX)
    p_wider = pose_precision(model, motion, wider, rot, t, NOISE, FX)
    assert p_said.variance_factor < 1.5 and p_wider.variance_factor > 8
    assert p_wider.add_s > 2.5 * p_said.add_s


def test_points_sharing_a_draw_of_the_noise_count_as_fewer():
    """Points a pixel apart under a 5-pixel median share its draws; points far apart do not; the
    camera's own correlation shares them over more pixels."""
    noise = DepthNoise(per_m2=0.002, window=5, frame_fx=FX)
    grid = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    dense = np.column_stack([grid / FX, np.ones(len(grid))])
    sparse = np.column_stack([10 * grid / FX, np.ones(len(grid))])
    # A 5 x 5 median's output is shared over about 20 pixels (a box of 25 would be 25).
    assert 15.0 < points_per_draw(dense, FX, noise) < 25.0
    assert points_per_draw(sparse, FX, noise) == 1.0
    shared = DepthNoise(per_m2=0.002, window=5, correlation_px=2.0, focal_px=FX, frame_fx=FX)
    assert points_per_draw(dense, FX, shared) > 2.5 * points_per_draw(dense, FX, noise)


def test_the_pixels_per_draw_are_measured_on_the_noise_itself():
    """A block's mean of the filtered noise varies as one pixel's over the block's draws."""
    from scipy import ndimage

    from tlt_common.pixel_noise import correlated_field

    area = draw_area(2.0, 5)
    rng = np.random.default_rng(7)
    means, variances = [], []
    for _ in range(150):
        field = ndimage.median_filter(correlated_field(rng.standard_normal((80, 80)), 2.0), 5)[10:-10, 10:-10]
        means.append(field[10:50, 10:50].mean())
        variances.append(field.var())
    assert np.var(means) == pytest.approx(np.mean(variances) * area / 1600, rel=0.35)


def test_a_fittings_turn_is_placed_worse_than_its_position_and_worse_further_away():
    """The turn the depth leaves a fitting's axis: degrees at half a metre from a stereo camera
    whose points each keep a millimetre of noise, where its place is known to a fraction of one."""
    model = MODELS["end_fitting"]
    motion = model_motion_matrix(model)
    rot = np.eye(3)
    near, far = np.array([0.0, 0.0, 0.4]), np.array([0.0, 0.0, 0.8])
    p_near = pose_precision(model, motion, _seen("end_fitting", rot, near), rot, near, NOISE, FX)
    p_far = pose_precision(model, motion, _seen("end_fitting", rot, far), rot, far, NOISE, FX)
    assert 0.0 < p_near.rotation < p_far.rotation
    # A turn of theta moves the 50 mm fitting's ends by 25 mm * theta: more than its mean ADD-S.
    assert 0.025 * p_far.rotation > p_far.add_s
