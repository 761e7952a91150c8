"""refine_pose: polishes a nearly right pose, and moves a tube fitted from behind to its front."""

import numpy as np
import pytest
import torch

from tlt_vision.cad.models import build_models
from tlt_vision.cad.views import synthetic_view
from tlt_vision.ops.registration import rotation_angle
from tlt_vision.pose.corrector import chamfer_objective, refine_pose
from tlt_vision.pose.estimator import tilted_turns


def _turn_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def _tilt_x(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


def test_a_cross_frame_turned_a_degree_comes_back_to_its_corners():
    m = build_models(0.75, {"vertical": 0.75})["cross_frame"]
    rot, t = _tilt_x(50.0), np.array([0.0, 0.0, 0.9])
    obs = torch.tensor(
        synthetic_view(m, rot, t, 600, np.random.default_rng(0), noise=0.0005), dtype=torch.float32
    )
    start = torch.tensor(rot @ _turn_z(1.0), dtype=torch.float32)[None]
    t0 = torch.tensor(t + np.array([0.002, -0.002, 0.0]), dtype=torch.float32)[None]
    mask = torch.ones(1, len(obs), dtype=torch.bool)
    r, tt, obj = refine_pose(obs[None], mask, start, t0, m.surface, 30, (0.0, 0.03))
    corners = np.array([[x, y, 0.0] for x in (-0.375, 0.375) for y in (-0.375, 0.375)])
    want = corners @ rot.T + t
    before = corners @ start[0].double().numpy().T + t0[0].double().numpy()
    got = corners @ r[0].double().numpy().T + tt[0].double().numpy()
    assert np.abs(before - want).max() > 0.005  # the start is off by more than the tolerance
    assert np.linalg.norm(got - want, axis=1).max() < 0.001
    kp = torch.tensor(m.keypoints, dtype=torch.float32)
    posed = kp @ r[0].T + tt[0]
    again, _, _ = chamfer_objective(obs[None], mask, posed[None], m.surface, kp)
    assert torch.allclose(again, obj, rtol=1e-3, atol=1e-12)


def test_a_tube_fitted_from_behind_moves_to_the_front():
    m = build_models(0.75, {"vertical": 0.75})["strut_tube/vertical"]
    # The tube across the view (its axis along camera x), 0.85 m away.
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    t = np.array([0.0, 0.0, 0.85])
    obs = torch.tensor(
        synthetic_view(m, rot, t, 400, np.random.default_rng(1), noise=0.0003), dtype=torch.float32
    )
    r_tube = float(m.surface.seg_r.min())
    behind = torch.tensor(t - [0.0, 0.0, 2 * r_tube], dtype=torch.float32)[None]
    mask = torch.ones(1, len(obs), dtype=torch.bool)
    rot_t = torch.tensor(rot, dtype=torch.float32)[None]
    # Without the second start the refinement stays on the wrong side; with it, on the axis.
    _, stuck, _ = refine_pose(obs[None], mask, rot_t, behind, m.surface, 30, (0.0,))
    _, tt, _ = refine_pose(obs[None], mask, rot_t, behind, m.surface, 30, (0.0, 2 * r_tube))
    off = lambda p: np.hypot(*(p[0].double().numpy() - t)[1:])  # noqa: E731 (distance off the axis)
    assert off(tt) < 0.002, tt
    assert off(stuck) > 0.01, stuck


def test_each_element_is_refined_as_it_would_be_alone():
    """Levenberg-Marquardt per element: a part's refined pose does not depend on the others in the
    batch, however far off they are (a wild start 30 cm away), up to float rounding (a batch sums
    in another order)."""
    m = build_models(0.75, {"vertical": 0.75})["corner_joint"]
    rng = np.random.default_rng(4)
    rots = [_tilt_x(30.0) @ _turn_z(20.0), _tilt_x(-40.0), _turn_z(70.0)]
    ts = [np.array([0.1, 0.0, 0.8]), np.array([-0.1, 0.05, 0.9]), np.array([0.0, -0.1, 0.7])]
    clouds = [synthetic_view(m, r, t, 300, rng, noise=0.0005) for r, t in zip(rots, ts, strict=True)]
    obs = torch.tensor(np.stack(clouds), dtype=torch.float32)
    mask = torch.ones(obs.shape[:2], dtype=torch.bool)
    start = torch.tensor(np.stack([r @ _turn_z(2.0) for r in rots]), dtype=torch.float32)
    t0 = torch.tensor(np.stack(ts) + 0.003, dtype=torch.float32)
    t0[2] += 0.3
    r, t, obj = refine_pose(obs, mask, start, t0, m.surface, 10, (0.0,))
    for i in range(2):
        one = slice(i, i + 1)
        r1, t1, obj1 = refine_pose(obs[one], mask[one], start[one], t0[one], m.surface, 10)
        assert np.degrees(float(rotation_angle(r1[0], r[i]))) < 0.5
        assert float(torch.linalg.vector_norm(t1[0] - t[i])) < 5e-4
        assert float(obj1[0]) == pytest.approx(float(obj[i]), rel=1e-3)
        assert np.linalg.norm(t[i].numpy() - ts[i]) < 0.001  # at its pose
    assert float(obj[2]) > 100 * float(obj[:2].max())  # the wild start is no fit, and held up nothing


def test_an_end_fitting_fitted_end_on_turns_to_its_side_with_the_turned_starts():
    """Seen from its side, an end fitting (about as long as it is wide) fitted with its axis
    towards the camera stays there from its own start; the starts turned a quarter about the
    model's x and y axes reach the side-on fit. A start an element does not ``use`` is not tried."""
    m = build_models(0.75, {"vertical": 0.75})["end_fitting"]
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]) @ _turn_z(30.0)  # axis along x
    t = np.array([0.05, -0.02, 0.6])
    obs = torch.tensor(
        synthetic_view(m, rot, t, 300, np.random.default_rng(2), noise=0.0003), dtype=torch.float32
    )[None]
    mask = torch.ones(obs.shape[:2], dtype=torch.bool)
    end_on = torch.tensor(rot @ _tilt_x(90.0) @ _turn_z(40.0), dtype=torch.float32)[None]
    t0 = torch.tensor(t + np.array([0.0, 0.0, 0.01]), dtype=torch.float32)[None]
    turns = torch.tensor(
        np.stack([np.eye(3), _tilt_x(90.0), _tilt_x(90.0) @ _turn_z(90.0)]), dtype=torch.float32
    )[None]

    def axis_error_deg(r: torch.Tensor) -> float:
        return float(np.degrees(np.arccos(min(1.0, abs(r[0, :, 2].double().numpy() @ rot[:, 2])))))

    stuck, _, stuck_obj = refine_pose(obs, mask, end_on, t0, m.surface, 10, (0.0, 0.0, 0.0))
    assert axis_error_deg(stuck) > 45.0
    left_out = torch.tensor([[True, False, False]])
    same, _, _ = refine_pose(obs, mask, end_on, t0, m.surface, 10, (0.0, 0.0, 0.0), turns, left_out)
    assert axis_error_deg(same) == pytest.approx(axis_error_deg(stuck), abs=0.01)
    r, tt, obj = refine_pose(obs, mask, end_on, t0, m.surface, 10, (0.0, 0.0, 0.0), turns)
    assert axis_error_deg(r) < 2.0
    assert np.linalg.norm(tt[0].double().numpy() - t) < 0.001
    assert float(obj[0]) < float(stuck_obj[0]) / 10


def test_a_corner_joint_fitted_tilted_comes_back_from_the_tilted_starts():
    """A corner joint whose fit starts tilted 45 degrees: from that start alone the refinement
    stops in a fit that is centimetres off; one of the starts turned 30 degrees either way about
    each model axis (``tilted_turns``, node.yaml ``corrector.tilted_starts``) reaches the true fit."""
    m = build_models(0.75, {"vertical": 0.75})["corner_joint"]
    rot, t = _tilt_x(20.0) @ _turn_z(10.0), np.array([0.03, -0.02, 1.2])
    obs = torch.tensor(
        synthetic_view(m, rot, t, 150, np.random.default_rng(6), noise=0.0003), dtype=torch.float32
    )[None]
    mask = torch.ones(obs.shape[:2], dtype=torch.bool)
    start = torch.tensor(rot @ _tilt_x(45.0), dtype=torch.float32)[None]
    t0 = torch.tensor(t + np.array([0.003, 0.0, 0.004]), dtype=torch.float32)[None]
    turns = torch.tensor(np.stack([np.eye(3), *tilted_turns(30.0)]), dtype=torch.float32)[None]
    assert turns.shape[1] == 7
    offsets = (0.0,) * 7
    own_only = torch.tensor([[True] + [False] * 6])
    r_stuck, _, stuck = refine_pose(obs, mask, start, t0, m.surface, 10, offsets, turns, own_only)
    r, tt, fit = refine_pose(obs, mask, start, t0, m.surface, 10, offsets, turns)
    kp = np.asarray(m.keypoints)

    def off_mm(r: torch.Tensor) -> float:
        # The cube turns into itself by quarter turns: each posed keypoint against the nearest true one.
        got, want = kp @ r[0].double().numpy().T, kp @ rot.T
        return 1000 * max(np.linalg.norm(want - g, axis=1).min() for g in got)

    assert off_mm(r_stuck) > 10.0 and float(stuck[0]) > 10 * float(fit[0])
    assert off_mm(r) < 1.0
    assert np.linalg.norm(tt[0].double().numpy() - t) < 0.001


def test_the_trim_leaves_out_a_neighbours_points_that_pull_the_fit_off():
    """An end fitting's cloud with a piece of the fitting beside it (8 % of the points, a mask that
    spilled over): the least-squares fit is pulled towards the neighbour; trimmed of the 10 % of
    points farthest from the model (node.yaml ``corrector.trim``) it stays at the part's pose, and
    an element's trim is its own (a batch of a trimmed and an untrimmed one)."""
    m = build_models(0.75, {"vertical": 0.75})["end_fitting"]
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]) @ _turn_z(30.0)
    t = np.array([0.05, -0.02, 0.6])
    rng = np.random.default_rng(3)
    own = synthetic_view(m, rot, t, 276, rng, noise=0.0003)
    nearby = t + np.array([0.0, float(m.diameter) * 0.6, 0.0])
    beside = synthetic_view(m, rot, nearby, 600, rng, noise=0.0003)
    spill = beside[beside[:, 1] < beside[:, 1].min() + 0.006][:24]  # its near edge
    assert len(spill) == 24
    obs = torch.tensor(np.concatenate([own, spill]), dtype=torch.float32)[None].repeat(2, 1, 1)
    mask = torch.ones(obs.shape[:2], dtype=torch.bool)
    start = torch.tensor(rot, dtype=torch.float32)[None].repeat(2, 1, 1)
    t0 = torch.tensor(t + np.array([0.001, 0.001, 0.001]), dtype=torch.float32)[None].repeat(2, 1)
    _, tt, _ = refine_pose(obs, mask, start, t0, m.surface, 10, (0.0,), trim=torch.tensor([0.0, 0.1]))
    pulled, kept = (float(np.linalg.norm(tt[i].double().numpy() - t)) for i in range(2))
    assert pulled > 0.001, pulled  # 1.5 mm
    assert kept < 0.0003, kept  # 0.1 mm
    _, alone, _ = refine_pose(obs[1:], mask[1:], start[1:], t0[1:], m.surface, 10, (0.0,), trim=0.1)
    assert float(torch.linalg.vector_norm(alone[0] - tt[1])) < 1e-4
