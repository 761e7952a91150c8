"""A round part's ends in the depth image (tlt_vision.pose.axial_ends), on a depth image ray-cast
from cylinders: an end fitting on its thinner tube below, its corner joint (wider, nearer) above,
a wall behind. The fitting posed where it is shows its tube-side end; posed along its axis, as a
mask that stops short of the fitting leaves it, it shows none, and the slide to an end finds its
place again."""

from __future__ import annotations

import numpy as np
import pytest

from tlt_vision.pointcloud import Intrinsics
from tlt_vision.pose.axial_ends import PosedCylinder, end_face_seen, ends_seen, slide_to_an_end

K = Intrinsics(300.0, 300.0, 160.0, 120.0)
W, H = 320, 240
Z0 = 0.25  # m, the axis's distance from the camera
RADIUS, HALF = 0.02, 0.025  # the end fitting
# The fitting's axis runs along the camera's y (down the image); its model z is the camera's y.
ALONG_Y = np.column_stack([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _render() -> np.ndarray:
    """z-depth of: the joint (r 30 mm, y -80..-25 mm), the fitting (r 20 mm, y -25..25 mm), the
    tube (r 12.5 mm, y 25..300 mm), all about the axis x = 0, z = Z0; a wall at 1 m."""
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    dx, dy = (u - K.cx) / K.fx, (v - K.cy) / K.fy
    depth = np.full((H, W), 1.0)
    for radius, y0, y1 in ((0.03, -0.08, -0.025), (RADIUS, -HALF, HALF), (0.0125, HALF, 0.3)):
        a = dx**2 + 1.0
        disc = Z0**2 - a * (Z0**2 - radius**2)
        t = (Z0 - np.sqrt(np.clip(disc, 0.0, None))) / a
        hit = (disc > 0) & (t * dy >= y0) & (t * dy <= y1) & (t < depth)
        depth[hit] = t[hit]
    return depth


def _fitting(rotation: np.ndarray, along_y: float) -> PosedCylinder:
    """The fitting posed ``along_y`` (m) down the image from where it is."""
    return PosedCylinder(rotation, np.array([0.0, along_y, Z0]), RADIUS, HALF)


@pytest.fixture(scope="module")
def depth() -> np.ndarray:
    return _render()


def test_the_fitting_where_it_is_shows_the_end_on_its_tube_and_not_the_one_in_its_joint(depth):
    assert ends_seen(_fitting(ALONG_Y, 0.0), depth, K) == ("b",)


@pytest.mark.parametrize("slide", [-0.015, 0.015])
def test_a_fitting_posed_along_its_axis_shows_no_end_and_the_slide_finds_its_place(depth, slide):
    posed = _fitting(ALONG_Y, slide)
    assert ends_seen(posed, depth, K) == ()
    back = slide_to_an_end(posed, depth, K)
    assert back is not None and abs(slide + back) <= 0.001, back


def test_nothing_behind_the_end_but_the_same_surface_is_no_end():
    flat = np.full((H, W), Z0 - RADIUS)  # a wall where the fitting's near side is: no end anywhere
    assert ends_seen(_fitting(ALONG_Y, 0.0), flat, K) == ()
    assert slide_to_an_end(_fitting(ALONG_Y, 0.0), flat, K) is None


def test_seen_end_on_the_check_does_not_apply(depth):
    facing = np.eye(3)  # the model's z along the line of sight
    assert ends_seen(_fitting(facing, 0.0), depth, K) is None


def test_seen_end_on_the_cloud_must_hold_an_end_face():
    rng = np.random.default_rng(0)
    angle = rng.uniform(0.0, 2 * np.pi, 400)
    side = np.column_stack([RADIUS * np.cos(angle), RADIUS * np.sin(angle), rng.uniform(-HALF, HALF, 400)])
    r = RADIUS * np.sqrt(rng.uniform(0.0, 1.0, 100))
    face = np.column_stack([r * np.cos(angle[:100]), r * np.sin(angle[:100]), np.full(100, -HALF)])
    at = np.array([0.0, 0.0, Z0])
    assert end_face_seen(_fitting(np.eye(3), 0.0), np.vstack([side, face]) + at, 0.002)
    assert not end_face_seen(_fitting(np.eye(3), 0.0), side[np.abs(side[:, 2]) < 0.015] + at, 0.002)
