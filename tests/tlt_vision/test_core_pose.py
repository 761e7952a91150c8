"""A refused detection posed again on its mask's core: a corner joint whose mask took in the frame
side it joins is certified on the pixels the segmentation is surest of, and only within its mask."""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from tlt_vision.detections import Detection, detection_of
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pose.errors import add_s

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_pipeline import K, _render, _rz  # the z-buffered splatting of test_pipeline


@pytest.fixture(scope="module")
def joined():
    """The node's corner-joint estimator and pipeline options, a joint with a frame-side tube
    running from its face: the depth, the joint's true pose, its own mask and a mask that also
    takes in the tube's first centimetres beside it."""
    from tlt_common.mission.schema import load_mission
    from tlt_vision.node_config import load_config
    from tlt_vision.part_inspection import load_estimators

    config = load_config()
    estimators = load_estimators(config, load_mission(config.mission_path))
    joint, tube = estimators["corner_joint"], estimators["strut_tube/vertical"].model
    c, s = math.cos(0.5), math.sin(0.5)
    rot = _rz(0.6) @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    centre = np.array([0.0, 0.0, 0.5])
    half = joint.model.diameter / (2 * math.sqrt(3))  # the cube's half size
    # The tube along the joint's x axis, its end at the joint's face.
    along = rot[:, 0]
    tube_rot = rot @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # model z to x
    length = float(np.ptp(tube.sample(2000, np.random.default_rng(0))[0][:, 2]))
    tube_centre = centre + along * (half + length / 2)
    depth, ids = _render([(joint.model, rot, centre), (tube, tube_rot, tube_centre)])
    own = ids == 0
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rot, centre
    # The tube's pixels within a few of the joint's: what a learned mask takes in.
    import cv2

    near = cv2.dilate(own.astype(np.uint8), np.ones((41, 41), np.uint8)).astype(bool)
    return joint, config.pipeline_options, depth, pose, own, own | (near & (ids == 1))


def _posed(joined, detection, **options):
    estimator, defaults, depth, *_ = joined
    pipeline = PartPipeline({"corner_joint": estimator}, **{**defaults, **options})
    return pipeline.observe([detection], depth, K)[0].estimate


def _right(joined, e) -> bool:
    model, pose = joined[0].model, joined[3]
    return add_s(model, e.rotation, e.translation, pose[:3, :3], pose[:3, 3]) < 0.02 * model.diameter


def test_a_joint_whose_mask_took_in_its_frame_side_is_certified_on_its_core(joined):
    *_, own, spanning = joined
    assert spanning.sum() > 1.1 * own.sum()
    whole = _posed(joined, Detection("corner_joint", spanning))
    assert not whole.certified and "not observably correct" in whole.certificate.reason
    again = _posed(joined, Detection("corner_joint", spanning, core=own))
    assert again.certified, again.certificate.reason
    assert _right(joined, again)


def test_a_certified_pose_is_not_posed_again_and_a_core_pose_out_of_its_mask_is_not_taken(joined):
    *_, options, _, _, own, spanning = joined
    alone = _posed(joined, Detection("corner_joint", own))
    assert alone.certified and _right(joined, alone)
    # A certified pose stays the whole mask's, whatever the core (a sliver of it here).
    sliver = own & (np.arange(own.shape[1])[None, :] < np.percentile(np.nonzero(own)[1], 20))
    kept = _posed(joined, Detection("corner_joint", own, core=sliver))
    assert np.array_equal(kept.rotation, alone.rotation)
    assert np.array_equal(kept.translation, alone.translation)
    strict = replace(options["parting"], in_mask=1.01)  # no pose lies wholly in an ungrown mask
    assert not _posed(joined, Detection("corner_joint", spanning, core=own), parting=strict).certified
    assert not _posed(joined, Detection("corner_joint", spanning, core=own), parting=None).certified


def test_a_mask_rcnn_detection_carries_its_core_only_where_it_is_smaller_than_its_mask():
    masks = torch.zeros((3, 4, 4), dtype=torch.bool)
    masks[:, 1:3, 1:3] = True
    cores = masks.clone()
    cores[0, 1, 1] = False  # trimmed
    cores[2] = False  # trimmed away: nothing to pose
    result = {
        "labels": torch.tensor([4, 4, 2]),
        "scores": torch.tensor([0.9, 0.8, 0.7]),
        "masks": masks,
        "core_masks": cores,
    }
    classes = ("strut_tube", "end_fitting", "cross_frame", "corner_joint", "rivet")
    first, same, emptied = (detection_of(result, classes, k) for k in range(3))
    assert first.object_class == "corner_joint" and first.score == pytest.approx(0.9)
    assert first.core is not None and first.core.sum() == 3 and first.mask.sum() == 4
    assert same.core is None and emptied.core is None and emptied.object_class == "end_fitting"
    without = {k: v for k, v in result.items() if k != "core_masks"}
    assert detection_of(without, classes, 0).core is None
