"""An end fitting seen from its side, placed along its axis by its mask: hand-made images of a
fitting lying across the view, its far end hidden behind an occluder."""

from pathlib import Path

import numpy as np
import pytest

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import models_for_mission
from tlt_vision.pointcloud import Intrinsics, project
from tlt_vision.pose.axial_slide import AxialSlide, overhangs, slid_along_axis
from tlt_vision.pose.certificate import Certificate
from tlt_vision.pose.estimator import PoseEstimate

ROOT = Path(__file__).resolve().parents[3]
K = Intrinsics(fx=600.0, fy=600.0, cx=320.0, cy=240.0)
SHAPE = (480, 640)
BACKGROUND = 3.0  # m, seen wherever the fitting and the occluder are not
# The fitting lies across the view at 1 m, its axis (model z) along the camera's x.
ROTATION = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
TRUE = np.array([0.0, 0.0, 1.0])


def _along(x: float) -> np.ndarray:
    """TRUE moved ``x`` (m) along the fitting's axis."""
    return TRUE + np.array([x, 0.0, 0.0])


@pytest.fixture(scope="module")
def fitting():
    return models_for_mission(load_mission(ROOT / "missions" / "one_bay.yaml"))["end_fitting"]


def _view(fitting, hide_above_x: float | None, hide_below_x: float | None = None):
    """Mask, depth and observed cloud of the fitting at TRUE, with an occluder 0.2 m nearer than it
    over the image where the camera-frame x of the fitting is above ``hide_above_x`` (and below
    ``hide_below_x``)."""
    points, _ = fitting.sample(200_000, np.random.default_rng(1))
    cam = points @ ROTATION.T + TRUE
    uv = np.rint(project(cam, K)).astype(int)
    depth = np.full(SHAPE, BACKGROUND)
    np.minimum.at(depth, (uv[:, 1], uv[:, 0]), cam[:, 2])
    mask = depth < BACKGROUND
    u = np.arange(SHAPE[1])
    hidden = np.zeros(SHAPE[1], dtype=bool)
    if hide_above_x is not None:
        hidden |= u > K.cx + hide_above_x * K.fx
    if hide_below_x is not None:
        hidden |= u < K.cx + hide_below_x * K.fx
    depth[:, hidden] = 0.8
    mask[:, hidden] = False
    v, u = np.nonzero(mask)
    z = depth[v, u]
    observed = np.column_stack([(u - K.cx) * z / K.fx, (v - K.cy) * z / K.fy, z])
    return mask, depth, observed


def _estimate(translation) -> PoseEstimate:
    cert = Certificate(True, 0.0003, 0.0025, 1, 1, ("side_a",), "")
    return PoseEstimate(
        "end_fitting",
        "end_fitting",
        ROTATION,
        np.asarray(translation, float),
        np.zeros((3, 3)),
        cert,
        100,
        0.0,
    )


def test_a_fitting_slid_past_its_visible_end_is_put_back_and_one_in_place_stays(fitting):
    # The fitting's end at x = -25 mm stands against the background; from x = +5 mm on it is hidden.
    mask, depth, observed = _view(fitting, hide_above_x=0.005)
    surface = fitting.sample(512, np.random.default_rng(0))
    for off in (-0.012, -0.006):  # the band seen fits the model slid this far along x
        moved, by = slid_along_axis(_estimate(_along(off)), observed, mask, depth, K, surface, AxialSlide())
        assert moved.translation == pytest.approx(TRUE, abs=0.0015) and by == pytest.approx(-off, abs=0.0015)
        assert moved.keypoints[:, 0] == pytest.approx(np.full(3, by))  # the keypoints move with it
    kept, by = slid_along_axis(_estimate(TRUE), observed, mask, depth, K, surface, AxialSlide())
    assert by == 0.0 and kept.translation.tolist() == TRUE.tolist()


def test_a_fitting_hidden_at_both_ends_stays_where_the_fit_put_it(fitting):
    """Nothing in the image says where along its axis it is: no slide removes any overhang."""
    mask, depth, observed = _view(fitting, hide_above_x=0.005, hide_below_x=-0.015)
    surface = fitting.sample(512, np.random.default_rng(0))
    moved, by = slid_along_axis(_estimate(_along(-0.004)), observed, mask, depth, K, surface, AxialSlide())
    assert by == 0.0 and moved.translation.tolist() == _along(-0.004).tolist()


def test_overhang_counts_surface_facing_the_camera_outside_the_mask_and_not_hidden(fitting):
    mask, depth, _ = _view(fitting, hide_above_x=0.005)
    points, normals = fitting.sample(512, np.random.default_rng(0))
    posed, turned = points @ ROTATION.T + TRUE, normals @ ROTATION.T

    placings = np.stack([posed - TRUE + _along(shift) for shift in (0.0, -0.010, 0.010)])
    in_place, off_the_end, behind = overhangs(mask, depth, K, placings, turned, 0.003)
    # In place, only the hidden part is off the mask, and it is hidden; moved towards the visible end
    # the model stands against the background; moved the other way it goes behind the occluder.
    assert in_place <= 2
    assert off_the_end > 20
    assert behind <= 2


def test_the_pipeline_places_by_its_mask_a_fitting_posed_off_along_its_axis(fitting):
    """The shipped C-3PO on the band of a fitting whose far end is hidden (it fits the band 8 mm off
    along the axis): the pipeline with the slide puts it where the mask ends, certified there."""
    from tlt_vision.detections import Detection
    from tlt_vision.node_config import load_config
    from tlt_vision.part_inspection import load_estimators
    from tlt_vision.pipeline import PartPipeline

    mission = ROOT / "missions" / "one_bay.yaml"
    estimator = load_estimators(
        load_config(ROOT / "config/vision/node.yaml", mission), load_mission(mission)
    )["end_fitting"]
    mask, depth, _ = _view(fitting, hide_above_x=0.005)
    (seen,) = PartPipeline({"end_fitting": estimator}, axial_slide=AxialSlide()).observe(
        [Detection("end_fitting", mask)], depth, K
    )
    assert seen.estimate.certified, seen.estimate.certificate.reason
    assert seen.estimate.translation == pytest.approx(TRUE, abs=0.0015)
