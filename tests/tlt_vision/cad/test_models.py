from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import (
    KEYPOINTS_FILE,
    PARTS_FILE,
    build_models,
    load_keypoints,
    load_parts,
    models_for_mission,
    strut_layout,
)
from tlt_vision.cad.views import random_rotation, visible_points

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def models():
    return models_for_mission(load_mission(ROOT / "missions" / "one_bay.yaml"))


def test_models_of_every_class(models):
    assert sorted(models) == sorted(
        ["strut_tube/vertical", "strut_tube/diagonal", "end_fitting", "cross_frame", "corner_joint", "rivet"]
    )
    parts = load_parts()
    # Vertical 0.75 m: tube between 0.025 + 0.05 from each end -> half length 0.3 m.
    assert models["strut_tube/vertical"].dims["half_length"] == pytest.approx(0.3)
    assert models["strut_tube/vertical"].keypoints[0].tolist() == pytest.approx([0, 0, -0.3])
    assert models["cross_frame"].keypoints[0].tolist() == pytest.approx([-0.375, -0.375, 0.0])
    assert models["end_fitting"].dims["radius"] == parts["fitting_radius"]


def test_strut_layout_hand_computed():
    lay = strut_layout(0.75, {"corner_size": 0.05, "fitting_length": 0.05})
    assert lay == pytest.approx(
        {"tube_a": 0.075, "tube_b": 0.675, "fitting_a": 0.05, "fitting_b": 0.7, "tube_centre": 0.375}
    )


def test_parts_config_matches_the_twin():
    twin = ROOT / "config" / "twin" / "edu.yaml"
    twin_parts = yaml.safe_load(twin.read_text())["parts"]
    ours = load_parts()
    for key in ("tube_radius", "fitting_radius", "fitting_length", "corner_size", "rivet_radius"):
        assert ours[key] == pytest.approx(twin_parts[key]), key
    assert ours["cross_frame_tube_radius"] == pytest.approx(1.2 * twin_parts["tube_radius"])


def test_symmetries_found(models):
    assert len(models["strut_tube/vertical"].symmetries) == 2  # flip end for end
    assert len(models["cross_frame"].symmetries) == 8  # square: 4 turns x flip
    assert len(models["corner_joint"].symmetries) == 24  # cube
    for m in models.values():
        assert m.symmetries[0].tolist() == list(range(len(m.keypoint_names)))


def test_symmetry_rotations_map_the_surface_onto_itself(models):
    rng = np.random.default_rng(0)
    for m in models.values():
        pts = torch.tensor(m.sample(300, rng)[0])
        for rot in m.symmetry_rotations:
            moved = pts @ torch.tensor(rot).T
            assert float(m.surface(moved.float()).max()) < 1e-5, m.name


def test_samples_lie_on_the_surface(models):
    rng = np.random.default_rng(1)
    for m in models.values():
        pts, nrm = m.sample(500, rng)
        assert pts.shape == (500, 3)
        assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0)
        assert float(m.surface(torch.tensor(pts, dtype=torch.float32)).max()) < 1e-5, m.name


def test_surface_distance_hand_computed(models):
    tube = models["strut_tube/vertical"]  # capsule r 0.0125, axis z from -0.3 to 0.3
    pts = torch.tensor([[0.1, 0.0, 0.0], [0.0, 0.0, 0.4], [0.0, 0.0, 0.0]])
    assert tube.surface(pts).tolist() == pytest.approx([0.0875, 0.0875, 0.0125], abs=1e-6)
    cube = models["corner_joint"]  # half 0.025
    assert cube.surface(torch.tensor([[0.125, 0.0, 0.0]])).item() == pytest.approx(0.1, abs=1e-6)
    fitting = models["end_fitting"]  # cylinder r 0.02, z in [-0.025, 0.025]
    p = torch.tensor([[0.05, 0.0, 0.065]])  # 0.03 out radially, 0.04 beyond the face: 0.05
    assert fitting.surface(p).item() == pytest.approx(0.05, abs=1e-6)


def test_surface_gradient_hand_computed(models):
    # The corrector's and the refinement's closed-form gradient: the unit direction away from the
    # nearest surface point, outside and inside each kind of primitive.
    tube, cube, fitting = models["strut_tube/vertical"], models["corner_joint"], models["end_fitting"]
    cases = [
        (tube, [0.1, 0.0, 0.0], 0.0875, [1.0, 0.0, 0.0]),  # beside the axis
        (
            tube,
            [0.0, 0.03, 0.4],
            np.hypot(0.03, 0.1) - 0.0125,
            [0.0, 0.03 / np.hypot(0.03, 0.1), 0.1 / np.hypot(0.03, 0.1)],
        ),  # past an end
        (cube, [0.125, 0.0, 0.0], 0.1, [1.0, 0.0, 0.0]),  # beyond a face
        (cube, [0.035, -0.035, 0.0], 0.01 * np.sqrt(2), [0.5**0.5, -(0.5**0.5), 0.0]),  # an edge
        (cube, [0.0, 0.0, -0.02], -0.005, [0.0, 0.0, -1.0]),  # inside, nearest the -z face
        (fitting, [0.05, 0.0, 0.065], 0.05, [0.6, 0.0, 0.8]),  # outside the rim
        (fitting, [0.0, 0.015, 0.0], -0.005, [0.0, 1.0, 0.0]),  # inside, nearest the side
        (fitting, [0.001, 0.0, -0.022], -0.003, [0.0, 0.0, -1.0]),  # inside, nearest the -z face
    ]
    for model, point, value, grad in cases:
        sdf, g = model.surface.signed_with_gradient(torch.tensor([point]))
        assert sdf.item() == pytest.approx(value, abs=1e-6), (model.name, point)
        assert g[0].tolist() == pytest.approx(grad, abs=1e-5), (model.name, point)
    # On the axis there is no radial direction: the distance is still exact, the gradient finite.
    for model, value in ((tube, -0.0125), (fitting, -0.02)):
        sdf, g = model.surface.signed_with_gradient(torch.zeros(1, 3))
        assert sdf.item() == pytest.approx(value, abs=1e-6) and bool(torch.isfinite(g).all())


def test_surface_gradient_is_the_signed_distances_gradient(models):
    from tlt_vision.cad.surface import SurfaceDistance

    names = ["corner_joint", "cross_frame", "end_fitting", "rivet", "strut_tube/vertical"]
    points = torch.tensor(np.random.default_rng(4).normal(0.0, 0.2, (len(names), 500, 3))).float()
    for surface in [models[n].surface for n in names] + [
        SurfaceDistance.stacked([models[n].surface for n in names])
    ]:
        q = points.clone().requires_grad_(True)
        (expected,) = torch.autograd.grad(surface.signed(q).sum(), q)
        sdf, grad = surface.signed_with_gradient(points)
        assert torch.allclose(sdf, surface.signed(points), atol=1e-7)
        assert torch.allclose(grad, expected, atol=1e-5)
        assert torch.allclose(torch.linalg.vector_norm(grad, dim=-1), torch.ones(sdf.shape), atol=1e-4)


def test_a_stacked_surface_measures_each_element_against_its_own_model(models):
    """Several models in one batch (a frame's parts posed together): a model with fewer segments or
    no box is padded with primitives that are never the nearest."""
    from tlt_vision.cad.surface import SurfaceDistance

    names = ["corner_joint", "cross_frame", "end_fitting", "rivet", "strut_tube/vertical"]
    stacked = SurfaceDistance.stacked([models[n].surface for n in names])
    points = torch.tensor(np.random.default_rng(3).normal(0.0, 0.3, (len(names), 200, 3))).float()
    alone = torch.stack([models[n].surface.signed(points[i]) for i, n in enumerate(names)])
    assert torch.equal(stacked.signed(points), alone)


def test_visible_points_face_the_camera(models):
    cube = models["corner_joint"]
    pts = visible_points(cube, np.eye(3), np.array([0.0, 0.0, 0.5]), np.random.default_rng(0))
    # Looking straight at the -z face: every visible point is on it.
    assert np.allclose(pts[:, 2], 0.5 - 0.025, atol=1e-9)
    r = random_rotation(np.random.default_rng(3))
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)


def test_bad_configs_name_the_key(tmp_path):
    data = yaml.safe_load(KEYPOINTS_FILE.read_text())
    data["classes"]["rivet"]["groups"]["body"] = ["end_a", "nope"]
    bad = tmp_path / "kp.yaml"
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"classes\.rivet\.groups\.body"):
        load_keypoints(bad)
    parts = yaml.safe_load(PARTS_FILE.read_text())
    parts["tube_radius"] = -1.0
    bad.write_text(yaml.safe_dump(parts))
    with pytest.raises(ConfigError, match="tube_radius"):
        load_parts(bad)


def test_strut_too_short_is_refused():
    with pytest.raises(ValueError, match="too short"):
        build_models(0.75, {"vertical": 0.1})
