"""select_part: the part presented is the group of instances joined in 3-D with the most pixels of
its main class, not the biggest single instance (a bigger side of another frame behind it)."""

import numpy as np

from tlt_vision.detections import Detection
from tlt_vision.part_inspection import select_part
from tlt_vision.pointcloud import Intrinsics

K = Intrinsics(100.0, 100.0, 49.5, 49.5)


def _mask(rows: slice, cols: slice) -> np.ndarray:
    m = np.zeros((100, 100), dtype=bool)
    m[rows, cols] = True
    return m


def _frame(*instances: tuple[str, np.ndarray, float, str]) -> tuple[list[Detection], np.ndarray]:
    """Detections and a depth image from (class, mask, depth in m, object id) per instance."""
    depth = np.zeros((100, 100), dtype=np.float32)
    for _, mask, z, _ in instances:
        depth[mask] = z
    return [Detection(cls, mask, object_id=oid) for cls, mask, _, oid in instances], depth


def _scene():
    # The held frame, 0.6 m away: two sides meeting at a corner joint; another frame 1.5 m away,
    # one side bigger than either held side, fewer pixels in all.
    return _frame(
        ("cross_frame", _mask(slice(10, 20), slice(10, 40)), 0.6, "a/side_0"),
        ("cross_frame", _mask(slice(20, 50), slice(10, 20)), 0.6, "a/side_1"),
        ("corner_joint", _mask(slice(10, 20), slice(40, 45)), 0.6, "a/corner_1"),
        ("cross_frame", _mask(slice(60, 75), slice(10, 40)), 1.5, "b/side_0"),
    )


def _ids(picked):
    return sorted(d.object_id for d in picked)


def test_the_joined_part_with_most_main_pixels_is_picked_without_the_frame_behind():
    dets, depth = _scene()
    picked = select_part(
        dets, depth, K, ("cross_frame", "corner_joint"), "cross_frame", 2.0, (0.15, 2.0), 50, gap=0.03
    )
    assert _ids(picked) == ["a/corner_1", "a/side_0", "a/side_1"]


def test_without_a_gap_the_biggest_instance_anchors_and_reach_decides():
    dets, depth = _scene()
    picked = select_part(dets, depth, K, ("cross_frame", "corner_joint"), "cross_frame", 0.3, (0.15, 2.0), 50)
    assert _ids(picked) == ["b/side_0"]


def test_no_anchor_in_the_depth_range_means_the_part_is_not_in_view():
    dets, depth = _scene()
    assert select_part(dets, depth, K, ("cross_frame",), "cross_frame", 2.0, (0.15, 0.5), 50, gap=0.03) == []
    assert select_part(dets, None, K, ("cross_frame",), "cross_frame", 2.0, (0.15, 2.0), 50, gap=0.03) == []


def test_a_strut_is_its_tube_and_the_fittings_on_it_not_a_racked_fitting_within_reach():
    """A few pixels of a racked strut's fitting, 10 cm behind a held strut and well within its
    reach, once counted as a third fitting of the held one (it could not be measured, and good
    struts failed inspection)."""
    from pathlib import Path

    from tlt_common.mission.schema import load_mission
    from tlt_vision.node_config import load_config
    from tlt_vision.part_inspection import PartInspector

    mission = load_mission(Path(__file__).resolve().parents[2] / "missions" / "two_bay.yaml")
    inspector = PartInspector(load_config(), mission)
    dets, depth = _frame(
        ("strut_tube", _mask(slice(48, 52), slice(20, 80)), 0.6, "held/tube"),
        ("end_fitting", _mask(slice(47, 53), slice(14, 20)), 0.6, "held/fitting_a"),
        ("end_fitting", _mask(slice(47, 53), slice(80, 86)), 0.6, "held/fitting_b"),
        ("end_fitting", _mask(slice(60, 62), slice(50, 53)), 0.7, "racked/fitting_b"),  # 6 pixels
    )
    picked = inspector.select("vertical", dets, depth, K)
    assert _ids(picked) == ["held/fitting_a", "held/fitting_b", "held/tube"]


def test_a_held_strut_not_the_struts_of_a_lifted_bay_joined_behind_it():
    """In a two-bay build ARS X held bay 2's first vertical before the lifter ZED, and bay 1's
    near vertical, riveted to its diagonal, was in view at the same distance: the two tubes
    joined showed more tube than the held strut, were inspected in its place and failed it as a
    "bent tube". A strut is one tube; a group of several is structure."""
    dets, depth = _frame(
        ("strut_tube", _mask(slice(48, 52), slice(30, 70)), 0.85, "held/tube"),  # 160 pixels
        ("end_fitting", _mask(slice(47, 53), slice(24, 30)), 0.85, "held/fitting_a"),
        ("end_fitting", _mask(slice(47, 53), slice(70, 76)), 0.85, "held/fitting_b"),
        # 120 + 105 pixels: the vertical's foot on the diagonal's end.
        ("strut_tube", _mask(slice(0, 40), slice(5, 8)), 0.9, "bay1/vertical/tube"),
        ("strut_tube", _mask(slice(40, 43), slice(5, 40)), 0.9, "bay1/diagonal/tube"),
    )
    args = (dets, depth, K, ("strut_tube", "end_fitting"), "strut_tube", 0.5, (0.15, 2.0), 20)
    assert _ids(select_part(*args, gap=0.03)) == ["bay1/diagonal/tube", "bay1/vertical/tube"], "the old rule"
    assert _ids(select_part(*args, gap=0.03, anchors_per_part=1)) == [
        "held/fitting_a",
        "held/fitting_b",
        "held/tube",
    ]
    # A structure alone in view is still what there is to inspect (and fails for what it is).
    alone = [d for d in dets if not d.object_id.startswith("held/")]
    assert _ids(select_part(alone, depth, K, *args[3:], gap=0.03, anchors_per_part=1)) == [
        "bay1/diagonal/tube",
        "bay1/vertical/tube",
    ]


def test_a_held_tube_in_two_pieces_is_one_tube_and_its_far_fitting_within_reach():
    """Mask R-CNN split a held diagonal's tube into two detections: they lie along one line, so
    the held strut is one tube (not structure passed over for the racked strut beside it), and
    reach is measured from the middle of both pieces, which takes in the fitting at the far end
    of the bigger piece."""
    dets, depth = _frame(
        ("strut_tube", _mask(slice(48, 52), slice(10, 55)), 0.6, "held/tube_0"),  # 180 pixels
        ("strut_tube", _mask(slice(48, 52), slice(55, 90)), 0.6, "held/tube_1"),  # 140 pixels
        ("end_fitting", _mask(slice(47, 53), slice(4, 10)), 0.6, "held/fitting_a"),
        ("end_fitting", _mask(slice(47, 53), slice(90, 96)), 0.6, "held/fitting_b"),
        ("strut_tube", _mask(slice(10, 12), slice(20, 80)), 1.0, "racked/tube"),  # 120 pixels
    )
    args = (dets, depth, K, ("strut_tube", "end_fitting"), "strut_tube", 0.35, (0.15, 2.0), 20)
    assert _ids(select_part(*args, gap=0.03, anchors_per_part=1)) == [
        "held/fitting_a",
        "held/fitting_b",
        "held/tube_0",
        "held/tube_1",
    ]


def _slanted(row: int, cols: range, degrees: float, half_width: int = 2) -> np.ndarray:
    """A tube's mask rising ``degrees`` from ``row`` over ``cols``."""
    m = np.zeros((100, 100), dtype=bool)
    for c in cols:
        r = round(row - (c - cols.start) * np.tan(np.radians(degrees)))
        m[r - half_width : r + half_width, c] = True
    return m


def test_a_bent_tube_split_at_its_bend_is_one_tube():
    """Mask R-CNN can split a bent held tube at its bend, the two pieces off one straight line
    (a held diagonal bent 12 degrees: its ends 4 cm off the line through both pieces): they meet
    end to end at a few degrees, one bent tube, so the held strut is still the part inspected (and
    fails as bent), not passed over as two tubes for a racked strut."""
    held = (
        ("strut_tube", _mask(slice(58, 62), slice(5, 50)), 0.85, "held/tube_0"),  # 180 pixels
        ("strut_tube", _slanted(60, range(50, 95), 12.0), 0.85, "held/tube_1"),
        ("end_fitting", _mask(slice(57, 63), slice(0, 5)), 0.85, "held/fitting_a"),
    )
    racked = ("strut_tube", _mask(slice(90, 92), slice(20, 80)), 1.0, "racked/tube")  # 120 pixels
    dets, depth = _frame(*held, racked)
    args = (dets, depth, K, ("strut_tube", "end_fitting"), "strut_tube", 0.55, (0.15, 2.0), 20)
    assert _ids(select_part(*args, gap=0.03, anchors_per_part=1)) == [
        "held/fitting_a",
        "held/tube_0",
        "held/tube_1",
    ]
