"""Render the vision training images from the MuJoCo twin: RGB-D, instance masks, classes, poses.

Run: ``python -m tlt_tools.vision_training.render_dataset --out DIR --count N [--seed S] [--width 640
--height 480] [--mission missions/one_bay.yaml] [--defective-fraction 0.2]``. It writes the image
set of :mod:`tlt_tools.vision_training.dataset` (``index.json``, ``NNNNN.npz``) and ``preview.png``, a
contact sheet of the first images with their masks outlined and named.

The scenes, cameras, appearance, defects, instances and poses are those of
:mod:`tlt_tools.vision_training.twin_renderer`; the contact sheet is
:mod:`tlt_tools.vision_training.contact_sheet`.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path

from tlt_common.config_schema import ConfigError
from tlt_tools.vision_training.contact_sheet import write_preview
from tlt_tools.vision_training.dataset import Sample, write_index, write_sample
from tlt_tools.vision_training.twin_renderer import (
    DEFAULT_MISSION,
    SCENES,
    RenderError,
    RenderSettings,
    TwinRenderer,
)
from tlt_vision.segmentation.config import CLASSES

PREVIEW = "preview.png"


def render_set(
    out: Path,
    count: int,
    settings: RenderSettings,
    progress_every: int = 1,
    index_every: int = 10,
    preview_count: int = 6,
) -> list[str]:
    """Render ``count`` images into ``out`` with progress on stderr; returns the files written."""
    renderer = TwinRenderer(settings)
    record = {**asdict(settings), "defective_parts": renderer.defects, "scene_kinds": {}}
    files: list[str] = []
    shown: list[Sample] = []
    start = time.monotonic()
    try:
        for i in range(count):
            sample, kind = renderer.sample(i)
            name = f"{i:05d}.npz"
            write_sample(out / name, sample)
            files.append(name)
            record["scene_kinds"][name] = kind
            if len(shown) < preview_count:
                shown.append(sample)
                if len(shown) == min(preview_count, count):
                    write_preview(out / PREVIEW, shown)
            done = i + 1
            if done % index_every == 0 or done == count:
                write_index(out, list(CLASSES), settings.width, settings.height, files, record)
            if done % progress_every == 0 or done == count:
                rate = done / max(time.monotonic() - start, 1e-9)
                eta = (count - done) / rate
                print(
                    f"render_dataset: {done}/{count} images, {len(sample.labels)} instances ({kind}), "
                    f"{rate:.2f} images/s, ETA {int(eta // 60)}m{int(eta % 60):02d}s",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        renderer.close()
    return files


def parse_scene_weights(items: list[str]) -> dict[str, float]:
    """``["held=0.2", "presented=0.5"]`` as weights; a ValueError names the item at fault."""
    weights: dict[str, float] = {}
    for item in items:
        kind, _, value = item.partition("=")
        if kind not in SCENES:
            raise ValueError(f"{item!r}: unknown scene kind {kind!r} (kinds: {', '.join(SCENES)})")
        try:
            weight = float(value)
        except ValueError:
            raise ValueError(f"{item!r}: the weight must be a number (KIND=WEIGHT)") from None
        if not weight >= 0:
            raise ValueError(f"{item!r}: a weight must not be negative")
        weights[kind] = weight
    if not sum(weights.values()) > 0:
        raise ValueError("no scene kind has a weight above 0")
    return weights


def _weights_text(weights: dict[str, float]) -> str:
    return " ".join(f"{k}={w:g}" for k, w in weights.items())


def _fail(message: str) -> int:
    print(f"render_dataset: error: {message}", file=sys.stderr, flush=True)
    return 2


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="render_dataset", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, type=Path, help="directory of the image set (made if missing)")
    p.add_argument("--count", required=True, type=int, help="number of images")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--mission", type=Path, default=DEFAULT_MISSION, help="mission of the tower and parts")
    p.add_argument("--defective-fraction", type=float, default=0.2, help="probability a strut is defective")
    p.add_argument(
        "--min-pixels",
        type=int,
        default=RenderSettings.min_pixels,
        help="instances with fewer visible pixels are dropped",
    )
    p.add_argument(
        "--antialias",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="multisampled RGB (as the detectors see); --no-antialias is cheaper",
    )
    p.add_argument("--progress-every", type=int, default=1, help="print progress every k images")
    p.add_argument(
        "--lighting",
        default="",
        help="light every image by this preset of config/twin/lighting.yaml (lunar) instead of random lights",
    )
    p.add_argument(
        "--cameras",
        type=Path,
        help="take the images through these camera models (config/twin/cameras.yaml); "
        "default: the exact render",
    )
    p.add_argument(
        "--scenes",
        nargs="+",
        metavar="KIND=WEIGHT",
        help=f"how often each scene kind is drawn (relative; kinds left out are not drawn): "
        f"{', '.join(SCENES)}; default {_weights_text(RenderSettings().scenes)}",
    )
    args = p.parse_args(argv)
    if args.count < 1:
        return _fail(f"--count must be at least 1, got {args.count}")
    if args.width < 16 or args.height < 16:
        return _fail(f"--width/--height must be at least 16 pixels, got {args.width}x{args.height}")
    if not 0.0 <= args.defective_fraction <= 1.0:
        return _fail(f"--defective-fraction must lie in [0, 1], got {args.defective_fraction}")
    if args.min_pixels < 1 or args.progress_every < 1:
        return _fail("--min-pixels and --progress-every must be at least 1")
    if not args.mission.is_file():
        return _fail(f"--mission {args.mission}: no such file")
    scenes = RenderSettings().scenes
    if args.scenes is not None:
        try:
            scenes = parse_scene_weights(args.scenes)
        except ValueError as exc:
            return _fail(f"--scenes: {exc}")
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        probe = args.out / ".write_test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        return _fail(f"--out {args.out}: cannot write there: {exc.strerror or exc}")
    settings = RenderSettings(
        width=args.width,
        height=args.height,
        seed=args.seed,
        mission=str(args.mission),
        defective_fraction=args.defective_fraction,
        min_pixels=args.min_pixels,
        antialias=args.antialias,
        scenes=scenes,
        cameras=str(args.cameras) if args.cameras else "",
        lighting=args.lighting,
    )
    try:
        render_set(args.out, args.count, settings, progress_every=args.progress_every)
    except ConfigError as exc:
        return _fail(str(exc))
    except RenderError as exc:
        return _fail(str(exc))
    print(f"render_dataset: wrote {args.count} images to {args.out}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
