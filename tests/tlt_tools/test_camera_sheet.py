"""The camera models' picture: one view as rendered, through the ZED's model and by the lunar sun."""

from __future__ import annotations

import cv2
from tlt_tools.camera_sheet import HEIGHT, WIDTH, main


def test_the_sheet_shows_three_views_over_their_depths(tmp_path):
    out = tmp_path / "cameras.png"
    assert main(["--out", str(out)]) == 0
    image = cv2.imread(str(out))
    assert image.shape == (HEIGHT, 3 * WIDTH // 2, 3)
    render, model, moon = (image[: HEIGHT // 2, k * WIDTH // 2 : (k + 1) * WIDTH // 2] for k in range(3))
    assert abs(render.astype(int) - model.astype(int)).mean() > 1.0, "the model changes the image"
    assert moon.mean() < 0.7 * render.mean(), "the lunar sun leaves most of the view dark"
    holes = (image[HEIGHT // 2 :, WIDTH // 2 : WIDTH].max(axis=2) == 0).mean()
    exact_holes = (image[HEIGHT // 2 :, : WIDTH // 2].max(axis=2) == 0).mean()
    assert holes > exact_holes + 0.01, "the model's depth has holes the render's has not"
