from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from tlt_vision.pointcloud import (
    Detached,
    Intrinsics,
    detached_pieces,
    masked_point_cloud,
    pixels_in_image,
    project,
)

K = Intrinsics(fx=100.0, fy=200.0, cx=1.5, cy=1.0)


def test_hand_computed_back_projection():
    mask = np.zeros((3, 4), dtype=bool)
    mask[0, 3] = mask[2, 0] = True
    depth = np.full((3, 4), 2.0)
    rgb = np.zeros((3, 4, 3), dtype=np.uint8)
    rgb[0, 3] = (10, 20, 30)
    out = masked_point_cloud(mask, depth, K, rgb, min_points=2, erode=0)
    assert out.ok and out.mask_pixels == 2
    # (u=3, v=0): x = 1.5 * 2 / 100 = 0.03, y = -1 * 2 / 200 = -0.01; (u=0, v=2): -0.03, 0.01.
    assert out.points.tolist() == [pytest.approx([0.03, -0.01, 2.0]), pytest.approx([-0.03, 0.01, 2.0])]
    assert out.colours[0].tolist() == [10, 20, 30]
    assert project(out.points, K) == pytest.approx(np.array([[3.0, 0.0], [0.0, 2.0]]), abs=1e-5)


def test_only_points_ahead_landing_in_the_image_have_pixels():
    points = np.array(
        [
            [0.03, -0.01, 2.0],  # (u=3, v=0): in a 3x4 image
            [-0.03, 0.01, 2.0],  # (0, 2)
            [0.03, -0.01, -2.0],  # behind the camera, though it projects onto (0, 2)
            [0.05, 0.0, 2.0],  # (4, 1): one column past the right edge
            [0.0, -0.02, 2.0],  # (1.5, -1): above the top row
            [0.0, 0.0, 0.0],  # at the optical centre
        ]
    )
    uv, index = pixels_in_image(points, K, (3, 4))
    assert uv.tolist() == [[3, 0], [0, 2]]
    assert index.tolist() == [0, 1]
    uv, index = pixels_in_image(np.zeros((0, 3)), K, (3, 4))
    assert uv.shape == (0, 2) and index.shape == (0,)


def test_invalid_depth_pixels_dropped():
    mask = np.ones((4, 4), dtype=bool)
    depth = np.full((4, 4), 1.0)
    depth[0, 0], depth[0, 1], depth[0, 2] = 0.0, np.nan, np.inf
    out = masked_point_cloud(mask, depth, K, min_points=4, erode=0)
    assert out.ok and len(out.points) == 13
    assert np.isfinite(out.points).all()


@pytest.mark.parametrize(
    ("mask", "depth", "reason"),
    [
        (np.zeros((4, 4), bool), np.ones((4, 4)), "empty mask"),
        (np.ones((4, 4), bool), np.zeros((4, 4)), "no depth"),
        (np.ones((4, 4), bool), np.full((4, 4), np.nan), "no depth"),
        (np.ones((4, 4), bool), np.ones((4, 4)), "too few points: 16"),  # the image edge is not a silhouette
        (np.ones((4, 4), bool), np.ones((4, 5)), "does not match"),
        (np.ones((4, 4), bool), None, "no depth image"),
    ],
)
def test_bad_input_gives_a_reason_not_an_exception(mask, depth, reason):
    out = masked_point_cloud(mask, depth, K, min_points=32)
    assert not out.ok and reason in out.reason
    assert out.points.shape == (0, 3)


def test_border_pixels_with_mixed_depth_are_dropped():
    mask = np.zeros((7, 7), bool)
    mask[1:6, 1:6] = True  # 25 px, 9 of them off the border
    depth = np.full((7, 7), 1.0)
    depth[1, 3] = 3.0  # a flying pixel on the silhouette, depth of the background
    out = masked_point_cloud(mask, depth, K, min_points=9)
    assert out.ok and len(out.points) == 9 and np.allclose(out.points[:, 2], 1.0)
    thin = np.zeros((7, 7), bool)
    thin[3, :] = True
    out = masked_point_cloud(thin, np.ones((7, 7)), K, min_points=1)
    assert not out.ok and out.reason == "too few points: the mask of 7 px has no pixel off its border"


def test_a_mask_anywhere_in_the_frame_loses_its_silhouette_but_not_the_frame_edge():
    """Only the mask's box is looked at: its points are the same wherever it lies, its silhouette
    eroded, the frame's edge not (a part running out of the picture keeps its pixels there)."""
    depth = np.full((40, 50), 2.0)
    inside = np.zeros((40, 50), bool)
    inside[10:15, 20:28] = True  # 5 x 8 px, 3 x 6 off its silhouette
    corner = np.zeros((40, 50), bool)
    corner[35:, 44:] = True  # 5 x 6 px in the frame's corner, 4 x 5 off its silhouette
    for mask, rows, cols in ((inside, range(11, 14), range(21, 27)), (corner, range(36, 40), range(45, 50))):
        out = masked_point_cloud(mask, depth, K, min_points=1)
        pixels = {(round(u), round(v)) for u, v in project(out.points, K).tolist()}
        assert pixels == {(u, v) for v in rows for u in cols}


def test_max_points_and_matrix_intrinsics():
    k = Intrinsics.from_matrix(np.array([[100.0, 0, 1.5], [0, 200.0, 1.0], [0, 0, 1]]))
    assert k == K
    out = masked_point_cloud(np.ones((10, 10), bool), np.ones((10, 10)), k, min_points=5, max_points=20)
    assert len(out.points) == 20


def test_a_large_masks_points_are_spread_evenly_over_it():
    """The subset C-3PO is given covers the whole mask as densely everywhere: no region left
    thin by chance, where the certificate's Chamfer percentile would read a hole in the part."""
    mask = np.zeros((60, 80), bool)
    mask[5:55, 10:70] = True  # 3000 pixels, one valid depth each
    out = masked_point_cloud(mask, np.ones(mask.shape), K, max_points=300, erode=0)
    rows = np.round(out.points[:, 1] * K.fy / out.points[:, 2] + K.cy).astype(int)
    per_band = np.bincount((rows - 5) // 5, minlength=10)  # ten bands of 300 pixels each
    assert per_band.min() >= 29 and per_band.max() <= 31, per_band
    cols = np.round(out.points[:, 0] * K.fx / out.points[:, 2] + K.cx).astype(int)
    assert np.ptp(cols) >= 55  # across the mask's width too, not a few columns
    again = masked_point_cloud(mask, np.ones(mask.shape), K, max_points=300, erode=0)
    np.testing.assert_array_equal(again.points, out.points)


def test_pixels_beyond_the_part_size_from_its_median_depth_are_dropped():
    """A learned mask straying past the part onto the floor behind it: with the part's size given,
    those pixels give no points; the part's own, whatever its depth across, all stay."""
    mask = np.ones((6, 6), dtype=bool)
    depth = np.linspace(1.00, 1.05, 36).reshape(6, 6)  # the part, 5 cm deep across
    depth[0, :3] = 2.5  # the floor, through the mask's stray pixels
    kept = masked_point_cloud(mask, depth, K, min_points=4, erode=0, extent=0.06)
    assert kept.ok and len(kept.points) == 33
    assert kept.points[:, 2].max() <= 1.05
    assert len(masked_point_cloud(mask, depth, K, min_points=4, erode=0).points) == 36


def test_small_pieces_nothing_joins_to_the_part_are_detached_and_large_ones_are_not():
    """A tube 1 m long sampled every centimetre, cut in two by a jaw 3 cm wide in front of it, and a
    few points of the floor 0.4 m behind its end: the floor goes, both pieces of the tube stay."""
    rod = np.column_stack([np.linspace(0.0, 1.0, 101), np.zeros(101), np.full(101, 1.0)])
    tube = rod[(rod[:, 0] < 0.1) | (rod[:, 0] > 0.13)]  # 11 points, then 87
    floor = np.array([[1.0, 0.0, 1.4], [1.005, 0.0, 1.4], [1.0, 0.005, 1.4]])
    cloud = np.vstack([tube, floor])
    out = detached_pieces(cloud, Detached(link=0.02, below=0.05))
    assert out.tolist() == [False] * len(tube) + [True] * 3
    # Linked by steps of 5 cm the floor joins the tube: nothing is detached.
    assert not detached_pieces(cloud, Detached(link=0.5, below=0.05)).any()
    # The biggest piece stays whatever its share: a cloud in many small pieces is not emptied.
    scattered = np.column_stack([np.arange(30) * 0.1, np.zeros(30), np.ones(30)])
    assert detached_pieces(scattered, Detached()).sum() == 29
    assert detached_pieces(np.zeros((0, 3)), Detached()).shape == (0,)
    # A chain of 1000 points 1 mm apart is one piece, however long.
    chain = np.column_stack([np.arange(1000) * 0.001, np.zeros(1000), np.ones(1000)])
    assert not detached_pieces(np.random.default_rng(0).permutation(chain), Detached()).any()


def test_a_compact_part_keeps_only_its_largest_piece_when_its_class_asks():
    """An end fitting's cloud with a neighbouring fitting 5 cm beside it, a third of the points (its
    mask took the neighbour in): only the largest piece stays for a class in ``largest_only``, both
    for any other class, since each piece holds more than ``below`` of the cloud."""
    rng = np.random.default_rng(3)
    fitting = rng.uniform([-0.02, -0.02, 1.0], [0.02, 0.02, 1.01], (200, 3))
    neighbour = fitting[:100] + np.array([0.09, 0.0, 0.0])  # 5 cm gap beside a 4 cm fitting
    cloud = np.vstack([neighbour, fitting])
    detached = Detached(link=0.02, below=0.05, largest_only=("end_fitting", "corner_joint"))
    assert detached_pieces(cloud, detached, "end_fitting").tolist() == [True] * 100 + [False] * 200
    assert not detached_pieces(cloud, detached, "strut_tube").any()
    assert not detached_pieces(cloud, detached).any()
    # One piece is the part whatever the class.
    assert not detached_pieces(fitting, detached, "corner_joint").any()


def test_a_class_with_a_link_of_its_own_parts_from_neighbours_nearer_than_the_common_link():
    """Two rivets of a feeder's tray side by side, 13 mm apart (25 mm pitch, 12 mm across), the
    neighbour a third of the cloud: a 2 cm link joins them, the rivets' own 1 cm parts them; every
    other class keeps the common link."""
    rng = np.random.default_rng(4)
    rivet = rng.uniform([-0.006, -0.012, 0.5], [0.006, 0.012, 0.505], (200, 3))
    neighbour = rivet[:100] + np.array([0.025, 0.0, 0.0])
    cloud = np.vstack([neighbour, rivet])
    common = Detached(link=0.02, below=0.05, largest_only=("rivet",))
    assert not detached_pieces(cloud, common, "rivet").any()
    own = Detached(link=0.02, below=0.05, largest_only=("rivet",), links=(("rivet", 0.01),))
    assert own.link_of("rivet") == 0.01 and own.link_of("end_fitting") == 0.02 and own.link_of(None) == 0.02
    assert detached_pieces(cloud, own, "rivet").tolist() == [True] * 100 + [False] * 200
    assert not detached_pieces(cloud, own, "end_fitting").any()


def test_a_rivet_whose_mask_took_in_its_neighbour_in_the_feeder_is_posed_from_its_own_points():
    """The twin's feeder: each rivet's mask grown onto the pixels of a neighbour within 4 px of it,
    as the model's masks do (a tenth to a third more pixels). With the node's configuration (rivets'
    own 1 cm link, their largest piece kept) every one is certified at its true pose; with the
    common 2 cm link the neighbour's points stay and pull the fit off."""
    twin_renderer = pytest.importorskip("tlt_tools.vision_training.twin_renderer")
    from tlt_common.mission.schema import load_mission
    from tlt_vision.detections import Detection
    from tlt_vision.node_config import load_config
    from tlt_vision.part_inspection import load_estimators
    from tlt_vision.pipeline import PartPipeline
    from tlt_vision.pose.errors import add_s

    root = Path(__file__).resolve().parents[2]
    config = load_config(root / "config" / "vision" / "node.yaml")
    estimator = load_estimators(config, load_mission(root / "missions" / "one_bay.yaml"))["rivet"]
    options = config.pipeline_options
    node = PartPipeline({"rivet": estimator}, **options)
    one_link = replace(options["detached"], links=())
    common = PartPipeline({"rivet": estimator}, **{**options, "detached": one_link})
    renderer = twin_renderer.TwinRenderer(
        twin_renderer.RenderSettings(seed=11, scenes={"feeder": 1.0}, defective_fraction=0.0)
    )
    rivet = twin_renderer.CLASSES.index("rivet") + 1
    results: dict[str, list[tuple[bool, float]]] = {"node": [], "common": []}
    try:
        for i in (2, 3):  # the tray seen close, rivets side by side in the image
            s, _ = renderer.sample(i)
            k = Intrinsics.from_matrix(s.intrinsics)
            rivets = np.flatnonzero(s.labels == rivet)
            for j in rivets:
                near = cv2.dilate(s.masks[j].astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
                for n in rivets[rivets != j]:
                    bleed = s.masks[n] & near
                    if bleed.sum() < 0.15 * s.masks[j].sum():
                        continue
                    mask, true = s.masks[j] | bleed, s.poses[j]
                    for name, pipeline in (("node", node), ("common", common)):
                        e = pipeline.observe([Detection("rivet", mask)], s.depth, k)[0].estimate
                        assert e is not None
                        err = add_s(estimator.model, e.rotation, e.translation, true[:3, :3], true[:3, 3])
                        results[name].append((e.certified, err / estimator.model.diameter))
    finally:
        renderer.close()
    assert len(results["node"]) >= 8, results
    assert all(certified and err < 0.02 for certified, err in results["node"]), results["node"]
    assert sum(not certified for certified, _ in results["common"]) > len(results["common"]) / 2, results


def test_smoothing_takes_each_points_noise_down_and_not_the_background_behind_the_mask():
    """A flat target at 1 m with 1 % noise, the background 2 m behind it: with ``smooth`` 5 each
    point's depth is the median of its part's pixels about it (about a quarter of the noise, as
    sqrt(pi / 2) / 5 says), and no point moves towards the background at the silhouette."""
    k = Intrinsics(fx=300.0, fy=300.0, cx=40.0, cy=30.0)
    depth = np.full((60, 80), 3.0, dtype=np.float32)
    mask = np.zeros((60, 80), dtype=bool)
    mask[15:45, 20:60] = True
    depth[mask] = 1.0
    rng = np.random.default_rng(0)
    depth = (depth * (1 + 0.01 * rng.standard_normal(depth.shape))).astype(np.float32)
    raw = masked_point_cloud(mask, depth, k, erode=0)
    smooth = masked_point_cloud(mask, depth, k, erode=0, smooth=5)
    assert raw.ok and smooth.ok and len(raw.points) == len(smooth.points) == mask.sum()
    assert np.std(raw.points[:, 2]) == pytest.approx(0.01, rel=0.1)
    inner = np.abs(smooth.points[:, 0]) < 0.05  # points whose window lies inside the target
    assert np.std(smooth.points[inner, 2]) == pytest.approx(0.01 * np.sqrt(np.pi / 2) / 5, rel=0.2)
    assert smooth.points[:, 2].max() < 1.02
