"""Render a picture of the twin to PNG (``tlt twin render``).

Builds the scene for a machine description, mission and scenario, optionally stages the first
bay as built (every member in place and riveted), and writes one RGB frame from the free overview
camera of ``edu.yaml`` (or a named camera) to a PNG file. Exit status 0 on success, 2 when a file
is refused (the message names file, key and reason) or the model does not compile.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import mujoco

from tlt_common.config_schema import ConfigError
from tlt_sim.model.config import DEFAULT_EDU, REPO_ROOT
from tlt_sim.model.scene import ModelCompileError, Scene

DEFAULT_OUTPUT = REPO_ROOT / "docs" / "images" / "edu.png"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tlt twin render", description=__doc__.splitlines()[0])
    p.add_argument("--edu", type=Path, default=DEFAULT_EDU, help="machine description (config/twin/edu.yaml)")
    p.add_argument("--mission", type=Path, help="mission file (default: the one edu.yaml names)")
    p.add_argument("--scenario", type=Path, help="scenario file of faults")
    p.add_argument("--output", "-o", type=Path, default=DEFAULT_OUTPUT, help="PNG to write")
    p.add_argument(
        "--bays", type=int, choices=(0, 1), default=1, help="stage the first bay as built (1) or not"
    )
    p.add_argument("--camera", help="a named camera (zed_1, ars_x/d405_a, ...) instead of the overview")
    p.add_argument("--width", type=int, help="image width (default from edu.yaml render.width)")
    p.add_argument("--height", type=int, help="image height (default from edu.yaml render.height)")
    p.add_argument("--azimuth", type=float, help="overview camera azimuth, degrees")
    p.add_argument("--elevation", type=float, help="overview camera elevation, degrees")
    p.add_argument("--distance", type=float, help="overview camera distance, m")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        scene = Scene(args.edu, args.mission, args.scenario)
    except (ConfigError, ModelCompileError) as exc:
        print(f"tlt twin render: {exc}", file=sys.stderr)
        return 2
    with scene:
        if args.bays:
            scene.stage_bay(1)
        scene.advance(0.05)
        view = scene.edu["render"]
        width, height = args.width or view["width"], args.height or view["height"]
        limit = (scene.model.vis.global_.offwidth, scene.model.vis.global_.offheight)
        if width > limit[0] or height > limit[1]:
            print(f"tlt twin render: at most {limit[0]}x{limit[1]} pixels", file=sys.stderr)
            return 2
        if args.camera:
            if mujoco.mj_name2id(scene.model, mujoco.mjtObj.mjOBJ_CAMERA, args.camera) < 0:
                print(f"tlt twin render: no camera named {args.camera!r}", file=sys.stderr)
                return 2
            camera = args.camera
        else:
            camera = overview_camera(scene, args.distance, args.azimuth, args.elevation)
        ok = write_png(scene, camera, args.output, width, height)
    if not ok:
        print(f"tlt twin render: cannot write {args.output}", file=sys.stderr)
        return 2
    print(args.output)
    return 0


def overview_camera(
    scene: Scene, distance: float | None = None, azimuth: float | None = None, elevation: float | None = None
) -> mujoco.MjvCamera:
    """The free overview camera of ``edu.yaml`` (``render``), with any of its settings replaced."""
    view = scene.edu["render"]
    camera = mujoco.MjvCamera()
    camera.lookat[:] = view["lookat"]
    camera.distance = distance or view["distance"]
    camera.azimuth = view["azimuth"] if azimuth is None else azimuth
    camera.elevation = view["elevation"] if elevation is None else elevation
    return camera


def write_png(
    scene: Scene,
    camera: mujoco.MjvCamera | str,
    path: Path,
    width: int | None = None,
    height: int | None = None,
) -> bool:
    """Render ``scene`` as it stands from ``camera`` to ``path``; False when it cannot be written."""
    view = scene.edu["render"]
    frame = scene.render(
        camera, width or view["width"], height or view["height"], depth=False, segmentation=False
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    return bool(cv2.imwrite(str(path), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)))


if __name__ == "__main__":
    sys.exit(main())
