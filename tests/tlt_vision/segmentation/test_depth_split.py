import dataclasses

import numpy as np
import pytest
import torch

from tlt_vision.ops.boxes import boxes_from_masks
from tlt_vision.pointcloud import Intrinsics, back_project
from tlt_vision.segmentation.depth_split import (
    DepthSplit,
    depth_pieces,
    join_collinear,
    piece_score,
    split_by_depth,
    voted,
    width_ratio,
)
from tlt_vision.segmentation.semantic import SURE

SPLIT = DepthSplit(jump=0.02, jump_per_m=0.01, min_area=6, full_score_area=40)
TUBE, FITTING = 1, 2


def _result(masks: list[np.ndarray], labels: list[int], scores: list[float]) -> dict[str, torch.Tensor]:
    m = torch.from_numpy(np.stack(masks))
    return {
        "boxes": boxes_from_masks(m),
        "labels": torch.tensor(labels),
        "scores": torch.tensor(scores),
        "masks": m,
    }


def _tee() -> tuple[np.ndarray, np.ndarray]:
    """One region in the image: a level tube at 1.0 m with a tube 0.4 m behind it standing on it."""
    mask = np.zeros((30, 40), dtype=bool)
    depth = np.full(mask.shape, np.inf)
    mask[20:23, 2:38] = True
    depth[20:23, 2:38] = 1.0
    mask[2:20, 18:21] = True
    depth[2:20, 18:21] = 1.4
    return mask, depth


def test_a_region_of_two_parts_at_different_depths_is_cut_in_two():
    mask, depth = _tee()
    pieces = depth_pieces(mask, depth, SPLIT)
    assert sorted(int(p.sum()) for p in pieces) == [54, 108]
    front = next(p for p in pieces if p.sum() == 108)
    assert np.all(depth[front] == 1.0)


def test_a_part_receding_from_the_camera_stays_whole():
    """A tube seen obliquely: 25 mm deeper each pixel, under the 2 cm + 1 cm/m at 1-2 m."""
    mask = np.zeros((5, 50), dtype=bool)
    mask[1:4, 5:45] = True
    depth = np.tile(1.0 + 0.025 * np.arange(50), (5, 1))
    assert [int(p.sum()) for p in depth_pieces(mask, depth, SPLIT)] == [120]
    depth[:, 25:] += 0.1  # another part 10 cm further on
    assert sorted(int(p.sum()) for p in depth_pieces(mask, depth, SPLIT)) == [60, 60]


def test_depth_noise_of_a_stereo_camera_does_not_shatter_a_part():
    """1 % of the depth (a ZED's at a few metres), pixel by pixel: the tube at 2 m stays one
    piece, the tube behind it stays apart (a pixel at its end may come loose, and go)."""
    mask, depth = _tee()
    depth = depth * 2.0
    noisy = depth * (1 + 0.01 * np.random.default_rng(0).standard_normal(depth.shape))
    back, front = sorted(int(p.sum()) for p in depth_pieces(mask, noisy, SPLIT))
    assert front == 108 and 52 <= back <= 54


def test_pixels_without_depth_do_not_cut_a_part():
    mask, depth = _tee()
    depth[20:23, 10:12] = np.nan  # the sensor's hole across the front tube
    depth[21, 30] = 0.0
    assert sorted(int(p.sum()) for p in depth_pieces(mask, depth, SPLIT)) == [54, 108]


def test_holes_where_two_parts_meet_do_not_join_them():
    """A stereo camera has no depth along an edge: the holes where the tube behind meets the one in
    front take the depth of the nearer of them, so the region is still cut in two."""
    mask, depth = _tee()
    depth[18:21, 17:22] = np.nan
    pieces = depth_pieces(mask, depth, SPLIT)
    assert len(pieces) == 2 and sum(int(p.sum()) for p in pieces) == int(mask.sum())


def test_pieces_are_scored_by_area_and_small_ones_dropped_box_classes_untouched():
    mask, depth = _tee()
    speck = np.zeros_like(mask)
    speck[5:7, 30:32] = True  # 4 pixels: under min_area
    depth[5:7, 30:32] = 3.0
    small = np.zeros_like(mask)
    small[10:14, 30:35] = True  # 20 pixels: half the full-score area
    depth[10:14, 30:35] = 2.0
    fitting = np.zeros_like(mask)
    fitting[20:23, 38:40] = True
    result = _result([mask | speck, fitting, small], [TUBE, FITTING, TUBE], [0.8, 0.7, 0.6])
    out = split_by_depth(result, depth, (TUBE,), SPLIT)
    assert out["labels"].tolist() == [FITTING, TUBE, TUBE, TUBE]
    assert torch.equal(out["masks"][0], result["masks"][1]) and float(out["scores"][0]) == np.float32(0.7)
    areas = out["masks"].flatten(1).sum(1).tolist()
    assert areas == [6, 54, 108, 20]  # the pieces in raster order: the back tube first
    assert np.allclose(out["scores"].tolist(), [0.7, 0.8, 0.8, 0.6 * 20 / 40])
    assert torch.equal(out["boxes"], boxes_from_masks(out["masks"]).to(out["boxes"].dtype))


def test_without_a_fitting_depth_image_nothing_is_cut():
    mask, depth = _tee()
    result = _result([mask], [TUBE], [0.9])
    assert split_by_depth(result, None, (TUBE,), SPLIT) is result
    assert split_by_depth(result, depth[:, :20], (TUBE,), SPLIT) is result
    assert split_by_depth(result, depth, (FITTING,), SPLIT) is result


def test_with_the_heads_probabilities_each_piece_is_scored_by_its_own_pixels():
    """Each piece its pixels' mean probability times the share of them the head is sure of."""
    mask, depth = _tee()
    probs = torch.zeros((3, *mask.shape))
    probs[TUBE][20:23] = 0.9  # the front tube's row: the head is sure of it
    probs[TUBE][:11] = 0.7  # the tube behind: half of it as sure
    probs[TUBE][11:20] = 0.3  # and half doubted (a region read with the background weighted down)
    result = {**_result([mask], [TUBE], [0.7]), "semantic_probs": probs}
    out = split_by_depth(result, depth, (TUBE,), SPLIT)
    assert out["masks"].flatten(1).sum(1).tolist() == [54, 108]
    assert np.allclose(out["scores"].tolist(), [0.5 * 0.5, 0.9])
    assert out["semantic_probs"] is probs


def test_a_piece_is_scored_by_its_mean_probability_times_its_share_the_head_is_sure_of():
    assert piece_score(np.array([0.9, 0.9])) == pytest.approx(0.9)
    assert piece_score(np.array([0.9, 0.3, 0.3, SURE])) == pytest.approx(0.5 * 0.25)
    assert piece_score(np.array([0.4, 0.2])) == 0.0


def test_a_voted_piece_is_of_its_likelier_class_scored_as_a_thin_part_times_its_share():
    piece = np.array([True, True, True, False])
    tube = np.array([0.5, 0.5, 0.2, 0.9])
    frame = np.array([0.4, 0.4, 0.7, 0.0])
    chosen, score = voted([tube, frame], piece)
    assert chosen == 1  # frame side 1.5 against tube 1.2, the fourth pixel not the piece's
    assert score == pytest.approx(0.9 * (1.5 / 2.7))
    assert voted([tube, frame], np.array([True, False, False, False])) == (0, pytest.approx(0.9 * 0.5 / 0.9))


def test_with_the_vote_each_depth_piece_takes_the_class_most_probable_over_it():
    """One region of the tee labelled tube: the front bar mostly frame side to the head, the one
    behind mostly tube; with the vote each piece is of its own likelier class, scored from the
    two classes' probabilities together; without it the front bar, nowhere a sure tube, is lost."""
    mask, depth = _tee()
    frame = 3
    probs = torch.zeros((4, *mask.shape))
    probs[TUBE][20:23], probs[frame][20:23] = 0.3, 0.6
    probs[TUBE][:20], probs[frame][:20] = 0.7, 0.2
    result = {**_result([mask], [TUBE], [0.5]), "semantic_probs": probs}
    plain = split_by_depth(result, depth, (TUBE, frame), SPLIT)
    assert plain["labels"].tolist() == [TUBE] and plain["masks"].sum().item() == 54
    out = split_by_depth(result, depth, (TUBE, frame), dataclasses.replace(SPLIT, vote=True))
    assert out["masks"].flatten(1).sum(1).tolist() == [54, 108]
    assert out["labels"].tolist() == [TUBE, frame]
    assert np.allclose(out["scores"].tolist(), [0.9 * 0.7 / 0.9, 0.9 * 0.6 / 0.9])


K = np.array([[500.0, 0.0, 20.0], [0.0, 500.0, 15.0], [0.0, 0.0, 1.0]])


def _bar(rows: slice, cols: slice, z: float, depth: np.ndarray) -> np.ndarray:
    mask = np.zeros(depth.shape, dtype=bool)
    mask[rows, cols] = True
    depth[rows, cols] = z
    return mask


def test_pieces_of_one_straight_part_are_joined_and_others_not():
    """A tube at 1 m crossed by something in front (6 px, 12 mm, of it hidden) is two pieces on
    one line: joined. A tube beside it 2 cm away, and one on the same line of sight 0.5 m further,
    are other parts."""
    depth = np.full((30, 40), np.inf)
    left, right = _bar(np.s_[10:13], np.s_[2:15], 1.0, depth), _bar(np.s_[10:13], np.s_[21:37], 1.0, depth)
    beside = _bar(np.s_[20:23], np.s_[2:37], 1.0, depth)
    far = np.zeros_like(left)
    far[3:6, 2:37] = True
    depth[3:6, 2:37] = 1.5
    masks, scores, _ = join_collinear([left, right, beside, far], [0.8, 0.5, 0.9, 0.7], depth, K, SPLIT)
    assert len(masks) == 3
    assert np.array_equal(masks[0], left | right) and scores[0] == pytest.approx((0.8 * 39 + 0.5 * 48) / 87)
    assert np.array_equal(masks[1], beside) and np.array_equal(masks[2], far)
    result = _result([left, right, beside], [TUBE, TUBE, TUBE], [0.8, 0.5, 0.9])
    assert len(split_by_depth(result, depth, (TUBE,), SPLIT)["masks"]) == 3  # no camera matrix: no join
    assert len(split_by_depth(result, depth, (TUBE,), SPLIT, K)["masks"]) == 2


def _band_at(angle_deg: float, width_px: float, shape=(120, 160)) -> np.ndarray:
    """A straight band ``width_px`` wide, 100 px long, through the image's centre at ``angle_deg``."""
    ys, xs = np.mgrid[: shape[0], : shape[1]].astype(float)
    ys, xs = ys - shape[0] / 2, xs - shape[1] / 2
    a = np.radians(angle_deg)
    along, across = xs * np.cos(a) + ys * np.sin(a), -xs * np.sin(a) + ys * np.cos(a)
    return (np.abs(along) < 50) & (np.abs(across) < width_px / 2)


@pytest.mark.parametrize("angle", [0.0, 30.0, 90.0])
def test_a_tube_is_as_wide_in_the_image_as_its_radius_at_its_depth(angle):
    """12.5 mm radius at 1 m with fx 500: 12.5 px wide, whichever way it lies in the image."""
    k = np.array([[500.0, 0.0, 80.0], [0.0, 500.0, 60.0], [0.0, 0.0, 1.0]])
    depth = np.full((120, 160), 1.0)

    def ratio(width_px: float, z: np.ndarray) -> float | None:
        ys, xs = np.nonzero(_band_at(angle, width_px))
        return width_ratio(back_project(xs, ys, z[ys, xs], Intrinsics.from_matrix(k)), k, 0.0125)

    assert ratio(12.5, depth) == pytest.approx(1.0, abs=0.08)
    assert ratio(12.5, depth * 2) == pytest.approx(2.0, abs=0.16)  # as far, twice too wide
    assert ratio(40.0, depth) == pytest.approx(3.2, abs=0.3)
    assert width_ratio(np.ones((5, 3)), k, 0.0125) is None


def test_pieces_not_as_wide_as_their_part_are_scored_down():
    """One region of two tube pieces at 1 m: the one as wide as a tube (12 px) keeps its score, the
    one three times as wide (a panel of the machine) is scored width_penalty times lower. Without
    the parts' radii, or without a band, nothing is checked."""
    k = np.array([[500.0, 0.0, 80.0], [0.0, 500.0, 60.0], [0.0, 0.0, 1.0]])
    depth = np.full((120, 160), 1.0)
    tube, panel = np.zeros(depth.shape, dtype=bool), np.zeros(depth.shape, dtype=bool)
    tube[20:32, 10:110] = True
    panel[50:90, 30:130] = True
    split = DepthSplit(
        jump=0.02, jump_per_m=0.01, min_area=6, full_score_area=40, width_band=(0.6, 1.3), width_penalty=0.3
    )
    result = _result([tube | panel], [TUBE], [0.8])

    def scores(*args):
        out = split_by_depth(result, depth, (TUBE,), *args)
        pairs = zip(out["scores"], out["masks"], strict=True)
        return sorted((round(float(s), 3), int(m.sum())) for s, m in pairs)

    assert scores(split, k, {TUBE: 0.0125}) == [(0.24, 4000), (0.8, 1200)]
    assert [s for s, _ in scores(split, k)] == [0.8, 0.8]
    assert [s for s, _ in scores(SPLIT, k, {TUBE: 0.0125})] == [0.8, 0.8]
