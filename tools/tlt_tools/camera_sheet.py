"""A picture of what the twin's camera models do: one view as rendered, through the camera's model,
and by the lunar sun.

A lifter ZED sees a strut held 0.8 m before it (``Scene.place_in_view``). The sheet's top row
is colour (exact; through the ZED 2i's model; exact by the lunar light), its bottom row the depth
(exact; through the model, holes black; the difference, +-3 sigma at the strut's depth).

    python -m tlt_tools.camera_sheet --out docs/images/cameras.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mujoco
import numpy as np
from tlt_sim.model import names
from tlt_sim.model.camera_sensor import DEFAULT_CAMERAS, load_camera_sensors
from tlt_sim.model.lighting import apply_lighting, load_lighting
from tlt_sim.model.scene import Scene

WIDTH, HEIGHT = 640, 480


def _depth_colours(depth: np.ndarray, near: float, far: float) -> np.ndarray:
    """Depth as grey levels, near bright, no depth black."""
    grey = np.clip((far - depth) / (far - near), 0.0, 1.0) * 215 + 40
    grey[depth <= 0] = 0
    return np.repeat(grey[..., None], 3, axis=2).astype(np.uint8)


def _difference_colours(diff: np.ndarray, valid: np.ndarray, scale: float) -> np.ndarray:
    """Signed depth error as blue (nearer) to red (further), over ``scale`` m; no depth black."""
    t = np.clip(diff / scale, -1.0, 1.0)
    out = np.empty((*diff.shape, 3), dtype=np.float64)
    out[..., 0] = 128 + 127 * np.clip(t, 0, 1) - 128 * np.clip(-t, 0, 1)
    out[..., 2] = 128 + 127 * np.clip(-t, 0, 1) - 128 * np.clip(t, 0, 1)
    out[..., 1] = 128 - 128 * np.abs(t)
    out[~valid] = 0
    return out.astype(np.uint8)


def sheet(out: Path, cameras: Path = DEFAULT_CAMERAS, seed_frame: int = 0) -> Path:
    """Render the sheet to ``out`` (PNG); returns the path."""
    import cv2

    sensors = load_camera_sensors(cameras)
    camera = names.zed_camera(0)
    with Scene(out_dir=None) as scene:
        part = next(p for p in scene.info.parts.values() if p.kind == "vertical")
        scene.place_in_view(part.name, camera, 0.8)
        exact = scene.render(camera, WIDTH, HEIGHT)
        rng = sensors.frame_rng(camera, seed_frame)
        rgb, depth = sensors.for_camera(camera).apply(exact.rgb, exact.depth, exact.intrinsics.fx, rng)
    with Scene(out_dir=None) as moon:
        apply_lighting(moon.model, load_lighting(name="lunar"))
        mujoco.mj_forward(moon.model, moon.data)
        moon.place_in_view(part.name, camera, 0.8)
        lunar = moon.render(camera, WIDTH, HEIGHT, depth=False, segmentation=False)
    valid = exact.depth > 0
    near, far = 0.3, float(np.percentile(exact.depth[valid], 95))
    both = valid & (depth > 0)
    sigma = float(sensors.zed.depth.sigma(0.8))
    rows = [
        np.hstack([exact.rgb, rgb, lunar.rgb]),
        np.hstack(
            [
                _depth_colours(exact.depth, near, far),
                _depth_colours(depth, near, far),
                _difference_colours(depth - exact.depth, both, 3 * sigma),
            ]
        ),
    ]
    image = np.vstack(rows)
    labels = (
        "render",
        "ZED 2i model",
        "lunar sun",
        "depth",
        "through the model (holes black)",
        f"difference, +-{3 * sigma * 1000:.0f} mm",
    )
    for k, text in enumerate(labels):
        x, y = (k % 3) * WIDTH + 10, (k // 3) * HEIGHT + 28
        cv2.putText(image, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 0), 4, cv2.LINE_AA)
        cv2.putText(image, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2, cv2.LINE_AA)
    out.parent.mkdir(parents=True, exist_ok=True)
    small = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(out), cv2.cvtColor(small, cv2.COLOR_RGB2BGR))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="camera_sheet", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="PNG to write")
    p.add_argument("--cameras", type=Path, default=DEFAULT_CAMERAS, help="camera models (cameras.yaml)")
    args = p.parse_args(argv)
    print(sheet(args.out, args.cameras))
    return 0


if __name__ == "__main__":
    sys.exit(main())
