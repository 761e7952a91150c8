"""estimate_together: a frame's parts of several kinds posed in one batch get the poses and
certificates they get in their own model's batch."""

import copy
import dataclasses
import math
from pathlib import Path

import numpy as np
import torch

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.views import random_rotation, synthetic_view
from tlt_vision.node_config import load_config
from tlt_vision.ops.registration import rotation_angle
from tlt_vision.part_inspection import load_estimators
from tlt_vision.pose.errors import add_s
from tlt_vision.pose.estimator import estimate_together, refined_together

ROOT = Path(__file__).resolve().parents[3]
KINDS = ("corner_joint", "end_fitting", "rivet", "strut_tube/vertical")


def test_parts_of_four_kinds_together_are_posed_as_alone():
    mission = ROOT / "missions" / "one_bay.yaml"
    config = load_config(ROOT / "config/vision/node.yaml", mission)
    estimators = load_estimators(config, load_mission(mission))
    # Each kind refines from its own starts: the end fitting's and the rivet's two turned ones too,
    # the corner joint's six tilted ones besides its own (a batch pads the others' and leaves the
    # padding out).
    assert [len(estimators[k].starts) for k in KINDS] == [7, 4, 4, 2]
    rng = np.random.default_rng(11)
    jobs = []
    for kind in KINDS:
        est = estimators[kind]
        truth = [(random_rotation(rng), np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 0.9]))
                 for _ in range(3)]  # fmt: skip
        clouds = [synthetic_view(est.model, r, t, 400, rng, noise=0.0003) for r, t in truth]
        clouds.append(np.zeros((3, 3)))  # too few points: failed with its reason, in its place
        jobs.append((est, clouds, None))
    together = estimate_together(jobs)
    for (est, clouds, _), poses in zip(jobs, together, strict=True):
        alone = est.estimate_batch(clouds)
        assert [p.model_name for p in poses] == [est.model.name] * len(clouds)
        assert poses[-1].certificate.reason.startswith("too few points")
        assert [p.certified for p in poses] == [p.certified for p in alone]
        assert sum(p.certified for p in poses) >= 2, [p.certificate.reason for p in poses]
        for a, b in zip(alone[:-1], poses[:-1], strict=True):
            assert np.linalg.norm(a.translation - b.translation) < 0.001
            if est.model.name == "corner_joint":  # the others turn freely about their axis
                turn = rotation_angle(torch.as_tensor(a.rotation), torch.as_tensor(b.rotation))
                assert np.degrees(float(turn)) < 1.0


def test_the_corrector_on_a_spread_of_each_cloud_poses_as_on_the_whole_of_it():
    # node.yaml `corrector.points`: the corrector fits evenly spaced points of a large cloud; the
    # refinement and the certificate still read every point.
    mission = ROOT / "missions" / "one_bay.yaml"
    config = load_config(ROOT / "config/vision/node.yaml", mission)
    assert config.raw["corrector"]["points"] == 256
    estimators = load_estimators(config, load_mission(mission))
    rng = np.random.default_rng(12)
    for kind in ("end_fitting", "strut_tube/vertical", "corner_joint"):
        est = estimators[kind]
        truth = [(random_rotation(rng), np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 0.9]))
                 for _ in range(3)]  # fmt: skip
        clouds = [synthetic_view(est.model, r, t, 1200, rng, noise=0.0003) for r, t in truth]
        spread = est.estimate_batch(clouds)
        all_points = copy.copy(est)
        all_points.corrector = dataclasses.replace(est.corrector, points=0)
        whole = all_points.estimate_batch(clouds)
        assert [p.num_points for p in spread] == [1200] * 3
        assert [p.certified for p in spread] == [p.certified for p in whole]
        assert sum(p.certified for p in spread) >= 2, [p.certificate.reason for p in spread]
        for (_, t), a, b in zip(truth, spread, whole, strict=True):
            if a.certified:  # within the goal's 3 mm, and as near the truth as the whole cloud's
                assert np.linalg.norm(a.translation - t) < 0.003
                assert np.linalg.norm(a.translation - t) < np.linalg.norm(b.translation - t) + 0.001


def _turn(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation of ``angle`` about ``axis`` (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross


def test_refined_together_fits_clouds_from_poses_a_few_millimetres_off():
    # pipeline.py: a refused corner joint's core is fitted from its whole mask's pose, which the
    # frame side the mask took in had pulled a few millimetres and a degree or two.
    mission = ROOT / "missions" / "one_bay.yaml"
    config = load_config(ROOT / "config/vision/node.yaml", mission)
    estimators = load_estimators(config, load_mission(mission))
    rng = np.random.default_rng(13)
    items, truth = [], []
    for kind in ("corner_joint", "corner_joint", "end_fitting"):
        est = estimators[kind]
        rot, t = random_rotation(rng), np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 0.9])
        cloud = synthetic_view(est.model, rot, t, 400, rng, noise=0.0003)
        off = np.array([0.004, -0.003, 0.002])
        turn = _turn(rng.normal(size=3), math.radians(2.0))
        items.append((est, cloud, turn @ rot, t + off))
        truth.append((rot, t))
    refined = refined_together(items)
    assert [e.model_name for e in refined] == ["corner_joint", "corner_joint", "end_fitting"]
    for (est, cloud, start_rot, start_t), e, (rot, t) in zip(items, refined, truth, strict=True):
        assert e.num_points == len(cloud)
        start = est.certify_at(cloud, start_rot, start_t)
        assert not start.certified and e.certified, (start.reason, e.certificate.reason)
        # Within the goal's 2 % of the part's size (ADD-S: a cube's turns are one pose).
        assert add_s(est.model, e.rotation, e.translation, rot, t) < 0.02 * est.model.diameter
    assert refined_together([]) == []
