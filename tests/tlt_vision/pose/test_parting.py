"""A refused fitting posed again on the larger of two pieces of its cloud: the parting, the mask
check, and the pipeline on a mask that took in a racked neighbour."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from tlt_vision.detections import Detection
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.pose.errors import add_s
from tlt_vision.pose.parting import Parting, larger_piece, visible_share_in_mask

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_pipeline import K, _render, _rz  # the z-buffered splatting of test_pipeline


def _blob(n: int, centre, radius: float, rng) -> np.ndarray:
    return np.asarray(centre) + rng.uniform(-radius, radius, (n, 3))


def test_the_larger_of_two_pieces_is_kept_and_one_part_is_not_parted():
    rng = np.random.default_rng(0)
    two = np.vstack([_blob(300, (0.0, 0.0, 0.5), 0.01, rng), _blob(200, (0.04, 0.0, 0.5), 0.01, rng)])
    keep = larger_piece(two, min_share=0.2, min_separation=0.02)
    assert keep is not None and keep[:300].all() and not keep[300:].any()
    assert larger_piece(two, min_share=0.2, min_separation=0.05) is None  # centres 4 cm apart
    assert larger_piece(two[:330], min_share=0.2, min_separation=0.02) is None  # 30 of 330: a sliver
    one = _blob(500, (0.0, 0.0, 0.5), 0.02, rng)  # its halves' centres lie a radius apart
    assert larger_piece(one, min_share=0.2, min_separation=0.025) is None
    assert larger_piece(one[:1], min_share=0.2, min_separation=0.0) is None


def test_the_share_in_the_mask_counts_the_visible_surface_only():
    k = Intrinsics(100.0, 100.0, 50.0, 50.0)
    depth = np.full((100, 100), 1.0)
    mask = np.zeros((100, 100), bool)
    mask[:, :50] = True  # the left half of the image
    xs = np.linspace(-0.2, 0.2, 41)
    surface = np.stack([np.repeat(xs, 41), np.tile(xs, 41), np.full(41 * 41, 1.0)], axis=1)
    share = visible_share_in_mask(surface, mask, depth, k, margin_px=0, hidden_margin=0.01)
    assert share == pytest.approx(20 / 41, abs=0.01)  # u = 30..70 px; 30..49 in the mask
    # Behind what the camera saw on the right half: hidden there, the rest is in the mask.
    depth[:, 50:] = 0.5
    assert visible_share_in_mask(surface, mask, depth, k, 0, 0.01) == pytest.approx(1.0)
    depth[:, 50:] = np.nan  # no depth there: the image says nothing of those points
    assert visible_share_in_mask(surface, mask, depth, k, 0, 0.01) == pytest.approx(1.0)
    depth[:] = 1.0
    grown = visible_share_in_mask(surface, mask, depth, k, margin_px=5, hidden_margin=0.01)
    assert grown == pytest.approx(25 / 41, abs=0.01)  # the mask grown to u = 54
    assert visible_share_in_mask(surface, mask, np.full((100, 100), 0.5), k, 0, 0.01) == 0.0


@pytest.fixture(scope="module")
def racked():
    """The node's end-fitting estimator and pipeline options (no detached-piece filter, so a cloud
    reaches the pose whole), and two fittings side by side, 1.4 mm apart: the depth, the true pose
    of the first, its own mask, and a mask that holds it and the near half of its neighbour."""
    from tlt_common.mission.schema import load_mission
    from tlt_vision.node_config import load_config
    from tlt_vision.part_inspection import load_estimators

    config = load_config()
    estimator = load_estimators(config, load_mission(config.mission_path))["end_fitting"]
    c, s = math.cos(1.2), math.sin(1.2)
    rot = _rz(0.2) @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    mine, neighbour = np.array([-0.029, 0.0, 0.5]), np.array([0.029, 0.0, 0.5])
    depth, ids = _render([(estimator.model, rot, mine), (estimator.model, rot, neighbour)])
    theirs = ids == 1
    near_half = theirs & (np.arange(ids.shape[1])[None, :] <= np.median(np.nonzero(theirs)[1]))
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rot, mine
    options = {**config.pipeline_options, "detached": None}
    return estimator, options, depth, pose, ids == 0, (ids == 0) | near_half


def _posed(racked, mask, **options):
    estimator, defaults, depth, *_ = racked
    pipeline = PartPipeline({"end_fitting": estimator}, **{**defaults, **options})
    return pipeline.observe([Detection("end_fitting", mask)], depth, K)[0].estimate


def _right(racked, e) -> bool:
    model, pose = racked[0].model, racked[3]
    return add_s(model, e.rotation, e.translation, pose[:3, :3], pose[:3, 3]) < 0.02 * model.diameter


def test_a_fitting_whose_mask_took_in_half_its_racked_neighbour_is_posed_on_its_own_piece(racked):
    _, options, _, _, own, spanning = racked
    assert options["parting"] is not None and "end_fitting" in options["parting"].classes
    refused = _posed(racked, spanning, parting=None)  # the fit lies across the two
    assert not refused.certified and "not observably correct" in refused.certificate.reason
    parted = _posed(racked, spanning)
    assert parted.certified, parted.certificate.reason
    assert _right(racked, parted) and parted.num_points < refused.num_points
    # The fitting's own mask is certified at once; the parting has nothing to do.
    alone = _posed(racked, own)
    assert alone.certified and _right(racked, alone)
    assert alone.num_points == _posed(racked, own, parting=None).num_points


def test_the_parting_works_without_the_free_space_check(racked):
    parted = _posed(racked, racked[5], free_space=None)
    assert parted.certified and _right(racked, parted)


def test_a_piece_posed_out_of_its_mask_is_not_taken(racked):
    # The mask check alone refusing: no pose lies wholly within a mask no pixel grows.
    strict = Parting(classes=("end_fitting",), in_mask=1.01)
    assert not _posed(racked, racked[5], parting=strict).certified
