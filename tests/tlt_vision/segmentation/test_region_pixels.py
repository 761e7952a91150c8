import numpy as np

from tlt_vision.pointcloud import Intrinsics, back_project
from tlt_vision.segmentation.region_pixels import RegionPoints, neighbour_pairs

K = np.array([[500.0, 0.0, 100.0], [0.0, 500.0, 80.0], [0.0, 0.0, 1.0]])


def _pairs(mask: np.ndarray) -> set[frozenset[tuple[int, int]]]:
    ys, xs = np.nonzero(mask)
    found = []
    for first, y2, x2 in neighbour_pairs(ys, xs, mask.shape):
        member = mask[y2, x2]
        found += [
            frozenset({(int(ys[a]), int(xs[a])), (int(b), int(c))})
            for a, b, c in zip(first[member], y2[member], x2[member], strict=True)
        ]
    assert len(found) == len(set(found))  # no pair twice
    return set(found)


def test_every_pair_of_8_neighbours_once_and_none_across_the_image_edge():
    block = np.zeros((4, 5), dtype=bool)
    block[2:4, 3:5] = True  # a 2x2 block in the bottom-right corner: 6 pairs of neighbours
    assert len(_pairs(block)) == 6
    column = np.zeros((3, 3), dtype=bool)
    column[:, 0] = True  # the left edge: its pixels' lower-left neighbours lie outside
    assert _pairs(column) == {frozenset({(0, 0), (1, 0)}), frozenset({(1, 0), (2, 0)})}


def test_region_points_skip_pixels_without_depth_and_keep_the_crops_place_in_the_image():
    mask = np.zeros((3, 4), dtype=bool)
    mask[1, :] = True
    depth = np.full(mask.shape, 2.0)
    depth[1, 2] = np.nan
    seen = RegionPoints.of(mask, depth, K, top=10, left=20)
    assert seen.points.shape == (3, 3)
    assert seen.index[1, 2] == -1 and seen.index[0, 0] == -1
    columns, rows = np.array([20, 21, 23]), np.full(3, 11)
    expected = back_project(columns, rows, np.full(3, 2.0), Intrinsics.from_matrix(K))
    np.testing.assert_allclose(seen.points, expected)
    piece = np.zeros(mask.shape, dtype=bool)
    piece[1, 2:] = True  # one pixel without depth, one with
    np.testing.assert_allclose(seen.of_pixels(piece), expected[2:])
