import numpy as np
import pytest
import torch
from scipy.ndimage import label

from tlt_vision.depth_noise import DepthNoise
from tlt_vision.ops.boxes import boxes_from_masks
from tlt_vision.segmentation.bend_split import BendSplit, straight_pieces
from tlt_vision.segmentation.depth_split import DepthSplit, split_by_depth
from tlt_vision.segmentation.region_pixels import RegionPoints

# A frame side's radius (15 mm) at 2 m with fx 500 is 7.5 px wide; two radii are 7.5 px across.
K = np.array([[500.0, 0.0, 100.0], [0.0, 500.0, 80.0], [0.0, 0.0, 1.0]])
RADIUS = 0.015
SIDE = 3


def _sides(
    *rects: tuple[slice, slice], shape=(160, 200), z: float = 2.0
) -> tuple[list[np.ndarray], np.ndarray]:
    """Bars 8 px wide facing the camera at ``z``: each a side of a frame, in one depth image."""
    depth = np.full(shape, np.inf)
    bars = []
    for rows, cols in rects:
        bar = np.zeros(shape, dtype=bool)
        bar[rows, cols] = True
        depth[bar] = z
        bars.append(bar)
    return bars, depth


def _one_region(mask: np.ndarray) -> dict[str, torch.Tensor]:
    """The semantic head's detections of a frame with one frame-side region, ``mask``."""
    m = torch.from_numpy(mask)[None]
    return {
        "boxes": boxes_from_masks(m),
        "labels": torch.tensor([SIDE]),
        "scores": torch.tensor([0.9]),
        "masks": m,
    }


def _cut(mask: np.ndarray, depth: np.ndarray, split: BendSplit) -> list[np.ndarray]:
    return straight_pieces(mask, RegionPoints.of(mask, depth, K), RADIUS, split)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def _each_side_found(pieces: list[np.ndarray], bars: list[np.ndarray], iou: float = 0.9) -> None:
    assert len(pieces) == len(bars)
    for bar in bars:
        assert max(_iou(piece, bar) for piece in pieces) > iou


TOP = (np.s_[20:28], np.s_[20:180])
LEFT, RIGHT = (np.s_[28:140], np.s_[20:28]), (np.s_[28:140], np.s_[172:180])


def test_two_sides_meeting_at_a_corner_are_cut_apart_and_no_pixel_is_lost():
    bars, depth = _sides(TOP, LEFT)
    mask = bars[0] | bars[1]
    pieces = _cut(mask, depth, BendSplit())
    _each_side_found(pieces, bars)
    assert np.array_equal(np.logical_or.reduce(pieces), mask)
    assert sum(int(p.sum()) for p in pieces) == int(mask.sum())  # each pixel in one piece


def test_three_sides_of_a_frame_are_three_pieces():
    bars, depth = _sides(TOP, LEFT, RIGHT)
    _each_side_found(_cut(np.logical_or.reduce(bars), depth, BendSplit()), bars)


def test_a_straight_side_is_left_whole_even_when_tilted_away():
    """A side receding from 1.5 to 2.5 m across the image is still one line in space (its
    inverse depth, not its depth, changes evenly along its image)."""
    bars, depth = _sides(TOP)
    depth[TOP] = 1 / np.linspace(1 / 1.5, 1 / 2.5, 160)[None, :]
    pieces = _cut(bars[0], depth, BendSplit())
    assert len(pieces) == 1 and np.array_equal(pieces[0], bars[0])


def test_the_cut_is_the_same_every_time_and_pixels_without_depth_go_with_their_neighbours():
    bars, depth = _sides(TOP, LEFT)
    mask = bars[0] | bars[1]
    depth[22:26, 60:64] = np.nan  # on the top side, away from the corner
    depth[100:104, 22:26] = 0.0  # on the left side
    pieces = _cut(mask, depth, BendSplit())
    again = _cut(mask, depth, BendSplit())
    assert all(np.array_equal(a, b) for a, b in zip(pieces, again, strict=True))
    top = next(p for p in pieces if p[24, 100])
    left = next(p for p in pieces if p[120, 24])
    assert top[22:26, 60:64].all() and left[100:104, 22:26].all()


def test_a_mask_without_depth_is_returned_as_it_is():
    bars, depth = _sides(TOP, LEFT)
    mask = bars[0] | bars[1]
    pieces = _cut(mask, np.full(depth.shape, np.nan), BendSplit())
    assert len(pieces) == 1 and pieces[0] is mask


def test_the_node_segmenter_cuts_an_l_of_frame_sides_only_with_a_bend_tolerance_and_a_radius():
    bars, depth = _sides(TOP, LEFT)
    result = _one_region(bars[0] | bars[1])
    plain = DepthSplit(min_area=30, full_score_area=40)
    bent = DepthSplit(min_area=30, full_score_area=40, bend_tolerance=2.0)
    assert len(split_by_depth(result, depth, (SIDE,), plain, K, {SIDE: RADIUS})["masks"]) == 1
    assert len(split_by_depth(result, depth, (SIDE,), bent, K)["masks"]) == 1  # no radius: no cut
    out = split_by_depth(result, depth, (SIDE,), bent, K, {SIDE: RADIUS})
    _each_side_found(list(out["masks"].numpy()), bars)
    assert out["scores"].tolist() == pytest.approx([0.9, 0.9])


def test_two_parts_crossing_are_cut_into_places_each_connected_and_joined_again_along_their_lines():
    """A cross: the first line found takes the pixels where they cross, leaving the other in two
    places, each a piece of its own; the node's segmenter joins the two again (on one line)."""
    (across, up), depth = _sides((np.s_[40:48], np.s_[20:180]), (np.s_[0:140], np.s_[96:104]))
    mask = across | up
    pieces = _cut(mask, depth, BendSplit())
    assert len(pieces) == 3 and np.array_equal(np.logical_or.reduce(pieces), mask)
    assert all(label(p, structure=np.ones((3, 3)))[1] == 1 for p in pieces)
    bent = DepthSplit(min_area=30, bend_tolerance=2.0)
    out = split_by_depth(_one_region(mask), depth, (SIDE,), bent, K, {SIDE: RADIUS})
    # The band within two radii of the first line is the first's: 16 of the other's 140 rows.
    _each_side_found(list(out["masks"].numpy()), [across, up], iou=0.85)


def test_with_the_cameras_depth_noise_allowed_for_a_straight_side_stays_whole_and_an_l_is_still_cut():
    """2 % Gaussian noise on each pixel's depth (4 cm at 2 m, a stereo camera's at several metres):
    taken for exact, the straight side is cut apart; with ``depth_noise`` 0.02 it is not, and two
    sides meeting at a corner (1 m long each) still are."""
    bars, depth = _sides((np.s_[20:28], np.s_[20:280]), (np.s_[28:280], np.s_[20:28]), shape=(300, 300))
    noisy = depth * (1 + 0.02 * np.random.default_rng(3).standard_normal(depth.shape))
    assert len(_cut(bars[0], noisy, BendSplit())) > 1
    allowed = BendSplit(depth_noise=DepthNoise(fraction=0.02))
    assert len(_cut(bars[0], noisy, allowed)) == 1
    # With the allowance (11 cm here) the first line takes a wider band of the other side.
    _each_side_found(_cut(bars[0] | bars[1], noisy, allowed), bars, iou=0.8)
