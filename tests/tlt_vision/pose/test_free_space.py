"""The free-space check: hand-made depth images first, then rivets seen end-on in the twin."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tlt_vision.pointcloud import Intrinsics
from tlt_vision.pose.certificate import Certificate
from tlt_vision.pose.estimator import PoseEstimate
from tlt_vision.pose.free_space import FreeSpace, checked, free_space_fraction, nearest_depth

K = Intrinsics(fx=100.0, fy=100.0, cx=50.0, cy=50.0)  # a 100 x 100 image
MARGIN = 0.005


def _at_pixels(pixels, z):
    """Camera-frame points that project onto ``pixels`` [(u, v)] at depth ``z``."""
    return np.array([[(u - K.cx) * z / K.fx, (v - K.cy) * z / K.fy, z] for u, v in pixels])


def test_nearest_depth_is_the_smallest_valid_depth_in_the_window():
    depth = np.full((7, 7), 2.0, dtype=np.float32)
    depth[3, 3] = 1.0
    depth[0, 0] = 0.0  # no return
    depth[6, 6] = np.nan
    near = nearest_depth(depth, 3)
    assert near[2, 2] == 1.0 and near[4, 4] == 1.0 and near[3, 5] == 2.0
    assert near[0, 1] == 2.0  # the hole beside it does not count as near
    assert np.isinf(nearest_depth(np.zeros((3, 3)), 3)).all()
    assert np.isinf(nearest_depth(depth, 1)[0, 0])


def test_points_in_front_of_the_seen_surface_count_and_hidden_ones_do_not():
    near = nearest_depth(np.full((100, 100), 1.0), 5)
    pixels = [(10, 10), (50, 50), (80, 20), (30, 70)]
    assert free_space_fraction(near, K, _at_pixels(pixels, 0.9), MARGIN) == 1.0
    assert free_space_fraction(near, K, _at_pixels(pixels, 1.0), MARGIN) == 0.0
    assert free_space_fraction(near, K, _at_pixels(pixels, 1.0 - MARGIN / 2), MARGIN) == 0.0
    assert free_space_fraction(near, K, _at_pixels(pixels, 1.3), MARGIN) == 0.0  # behind: hidden
    mixed = np.vstack([_at_pixels(pixels[:3], 0.9), _at_pixels(pixels[3:], 1.2)])
    assert free_space_fraction(near, K, mixed, MARGIN) == pytest.approx(0.75)


def test_points_off_the_image_or_onto_no_depth_are_not_counted():
    depth = np.full((100, 100), 1.0)
    depth[:, :50] = 0.0  # no return on the left half
    near = nearest_depth(depth, 1)
    inside = _at_pixels([(70, 50)], 0.9)
    unseen = _at_pixels([(20, 50), (150, 50), (-5, 10)], 0.9)  # no depth, right of, left of the image
    behind_camera = np.array([[0.0, 0.0, -1.0]])
    assert free_space_fraction(near, K, np.vstack([inside, unseen, behind_camera]), MARGIN) == 1.0
    assert free_space_fraction(near, K, unseen, MARGIN) == 0.0


def test_a_point_on_the_silhouette_is_compared_with_the_part_not_the_background_beside_it():
    depth = np.full((100, 100), 1.0)
    depth[40:60, 40:60] = 0.5  # the part
    rim = _at_pixels([(61, 50), (50, 38)], 0.5)  # rounding puts them a pixel or two outside
    assert free_space_fraction(nearest_depth(depth, 5), K, rim, MARGIN) == 0.0
    assert free_space_fraction(nearest_depth(depth, 1), K, rim, MARGIN) == 1.0


def _estimate(certified: bool, translation) -> PoseEstimate:
    cert = Certificate(certified, 0.001, 0.003, 1, 1, ("body",), "" if certified else "degenerate view")
    t = np.asarray(translation, float)
    return PoseEstimate("rivet", "rivet", np.eye(3), t, np.zeros((2, 3)), cert, 50, 0.0)


def test_checked_takes_the_certificate_only_from_a_pose_standing_in_free_space():
    near = nearest_depth(np.full((100, 100), 1.0), 5)
    surface = np.array([[0.0, 0.0, -0.01], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]])
    check = FreeSpace(margin=MARGIN, max_fraction=0.25)
    on_surface = _estimate(True, [0.0, 0.0, 1.01])  # its front point on the seen surface, rest behind
    assert checked(on_surface, near, K, surface, check) is on_surface
    floating = _estimate(True, [0.0, 0.0, 0.8])
    out = checked(floating, near, K, surface, check)
    assert not out.certified
    assert "where the camera saw past it: 100% of its surface" in out.certificate.reason
    assert replace(out, certificate=floating.certificate) == floating  # the pose itself unchanged
    already = _estimate(False, [0.0, 0.0, 0.8])
    assert checked(already, near, K, surface, check) is already


# -- rivets seen end-on in the twin ----------------------------------------------------------------
twin_renderer = pytest.importorskip("tlt_tools.vision_training.twin_renderer")
ROOT = Path(__file__).resolve().parents[3]


def test_rivets_seen_end_on_in_their_feeder_are_not_certified_lying_across_their_heads():
    """Two defences, each tested: without the corrector's turned starts for rivets (node.yaml
    ``corrector.turned_starts``) some end-on rivet is fitted lying across its head, which the
    free-space check refuses; with them (the node's configuration) it is fitted right."""
    from tlt_common.mission.schema import load_mission
    from tlt_vision.detections import Detection
    from tlt_vision.node_config import load_config
    from tlt_vision.part_inspection import load_estimators
    from tlt_vision.pipeline import PartPipeline
    from tlt_vision.pose.errors import rotation_error_deg

    config = load_config(ROOT / "config" / "vision" / "node.yaml")
    mission = load_mission(ROOT / "missions" / "one_bay.yaml")
    assert "rivet" in config.raw["corrector"]["turned_starts"]
    turned = load_estimators(config, mission)["rivet"]
    config.raw["corrector"]["turned_starts"] = ["end_fitting"]
    plain = load_estimators(config, mission)["rivet"]
    opts = {"max_points": config.raw["max_points"], "keep_border_below": config.raw["keep_border_below"]}
    pipelines = {
        "checked": PartPipeline({"rivet": plain}, free_space=config.free_space, **opts),
        "unchecked": PartPipeline({"rivet": plain}, free_space=None, **opts),
        "node": PartPipeline({"rivet": turned}, free_space=config.free_space, **opts),
    }
    settings = twin_renderer.RenderSettings(seed=11, scenes={"feeder": 1.0}, defective_fraction=0.0)
    renderer = twin_renderer.TwinRenderer(settings)
    errors: dict[str, list[tuple[int, bool, float]]] = {k: [] for k in pipelines}
    rivet = twin_renderer.CLASSES.index("rivet") + 1
    try:
        for i in (2, 6):  # feeder views with rivets seen end-on beside others seen obliquely
            s, _ = renderer.sample(i)
            k = Intrinsics.from_matrix(s.intrinsics)
            dets = [Detection("rivet", s.masks[j]) for j in np.flatnonzero(s.labels == rivet)]
            truth = [s.poses[j] for j in np.flatnonzero(s.labels == rivet)]
            for name, pipe in pipelines.items():
                for true, obs in zip(truth, pipe.observe(dets, s.depth, k), strict=True):
                    if obs.estimate is not None:
                        e = obs.estimate
                        err = rotation_error_deg(plain.model, e.rotation, true[:3, :3])
                        errors[name].append((i, e.certified, err))
    finally:
        renderer.close()
    wrong = {name: sum(c and err > 10.0 for _, c, err in rows) for name, rows in errors.items()}
    certified = {name: sum(c for _, c, _ in rows) for name, rows in errors.items()}
    # Without either defence some end-on rivet is certified lying across its head: the case at issue.
    assert wrong["unchecked"] > 0, errors["unchecked"]
    assert wrong["checked"] == 0, errors["checked"]
    # Only the wrong ones lost their certificates.
    assert certified["checked"] == certified["unchecked"] - wrong["unchecked"], errors
    # The turned starts fit them right: certified, and none wrong.
    assert wrong["node"] == 0, errors["node"]
    assert certified["node"] > certified["checked"], errors
