"""The point-cloud filter benchmark: its filters and measures on made-up clouds, and one image of the
twin through the camera models measured end to end."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import models_for_mission


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("cloud_filters")


def test_the_plane_step_moves_noisy_points_along_their_rays_towards_their_plane(bench):
    rng = np.random.default_rng(0)
    u, v = np.meshgrid(np.linspace(-0.1, 0.1, 30), np.linspace(-0.1, 0.1, 30))
    flat = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1)  # a wall 1 m ahead
    noisy = flat * (1 + 0.003 * rng.standard_normal(len(flat)))[:, None]  # moved along each ray
    smoothed = bench.plane_smoothed(noisy)
    assert np.abs(smoothed[:, 2] - 1).std() < 0.4 * np.abs(noisy[:, 2] - 1).std()
    rays = noisy / np.linalg.norm(noisy, axis=1, keepdims=True)
    after = smoothed / np.linalg.norm(smoothed, axis=1, keepdims=True)
    assert np.allclose(rays, after, atol=1e-9)  # each point stays on its pixel's ray


def test_points_are_thinned_evenly_and_spacing_is_the_nearest_neighbours(bench):
    points = np.arange(30.0).reshape(10, 3)
    assert np.array_equal(bench.evenly(points, 4), points[[0, 3, 6, 9]])
    assert bench.evenly(points, 20) is points and bench.evenly(points, None) is points
    line = np.stack([np.arange(10) * 0.002, np.zeros(10), np.ones(10)], 1)
    assert bench.spacing(line) == pytest.approx(0.002)


def test_distances_are_to_the_true_surface_at_its_pose(bench):
    model = models_for_mission(load_mission(bench.ROOT / "missions/one_bay.yaml"))["corner_joint"]
    surface, normals = model.sample(200, np.random.default_rng(1))
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    pose[:3, 3] = [0.1, -0.05, 0.8]
    seen = surface @ pose[:3, :3].T + pose[:3, 3]
    assert bench.surface_distances(model, seen, pose).max() < 1e-5
    off = (surface + 0.004 * normals) @ pose[:3, :3].T + pose[:3, 3]  # 4 mm out along the normals
    assert np.median(bench.surface_distances(model, off, pose)) == pytest.approx(0.004, abs=3e-4)


def rows(out: str, table: str) -> dict[tuple[str, str], list[str]]:
    """The rows of the clouds table by (way, camera)."""
    lines = out.split(table, 1)[1].split("\n\n", 1)[0].splitlines()
    return {(f[0], f[1]): f[2:] for f in (line.split() for line in lines[2:]) if len(f) == 10}


def test_one_image_measured_end_to_end(bench, capsys):
    assert bench.main(["--count", "1", "--seed", "930"]) == 0
    out = capsys.readouterr().out
    table = rows(out, "clouds against the true surface")
    ways = {way for way, _ in table}
    assert {"exact", "raw", "median", "median9", "plane"} <= ways
    assert ({"o3d", "median+o3d"} <= ways) == (bench.open3d_or_none() is not None)
    if bench.open3d_or_none() is None:
        assert "open3d is not installed" in out
    (camera,) = {cam for _, cam in table}  # one image, one camera
    rms = {way: float(table[way, camera][2]) for way in ways}
    assert rms["exact"] < rms["raw"]  # the camera's noise is measured
    assert float(table["median", camera][3]) == 1.0  # ratios are to the pipeline's own filter
    allowed = {way: float(table[way, camera][5]) for way in ways}
    assert allowed["exact"] == 0.0 and allowed["median"] > 0.0
    poses = out.split("poses by the node's pipeline", 1)[1]
    assert f"  median      {camera:5s} views" in poses
    exact = re.search(rf"  exact       {camera:5s} views +(\d+): certified +([\d.]+) %", poses)
    assert int(exact[1]) >= 1 and float(exact[2]) >= 50.0  # the exact depth's poses are certified
