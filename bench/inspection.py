"""Part inspection on freshly rendered held struts: defective parts caught, good parts rejected
(issue 8: goals >= 99 % caught, <= 2 % rejected).

A twin of the mission is built with a scenario that makes half its struts defective, the kinds
the twin produces in turn between good ones: end fitting a missing, end fitting b missing, a bent
tube (bends cycled through ``--bends``). Every strut is then presented ``--rounds`` times, as the
ARS presents it for InspectPart: an arm at its ``poses.inspection`` (ARS X and ARS Y in turn) with
its joints jittered, the strut seated in its grasp, slid along the grasp line and rolled about its
own axis by chance, before the lifter ZED facing that arm at the twin's run size. The frame is
segmented as the launch set's vision does (the twin's labels; ``--segmentation mask_rcnn`` for
the shipped model) and decided by the vision node's :class:`tlt_vision.part_inspection.PartInspector`.

Prints, per kind of part: presented, failed, rate; the wrong decisions with their reasons; and the
figures against the goals.

    .venv/bin/python bench/inspection.py [--mission two_bay] [--rounds 2] [--seed 1100]
        [--bends 3 5 8 12] [--joint-jitter-deg 0.29] [--slide-mm 10]
        [--segmentation twin|mask_rcnn] [--weights W] [--min-score S] [--second-look S]
        [--no-closer] [--no-self-filter] [--threads 2] [--depth-noise 0.005] [--json figures.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tlt_tools.vision_training.twin_renderer import ARMS, inspection_joints

from tlt_common.config_schema import load_yaml
from tlt_common.geometry.transforms import pose_matrix
from tlt_common.mission.schema import load_mission
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.depth_noise import with_noise
from tlt_vision.node_config import VisionConfig, load_config
from tlt_vision.part_inspection import LookCloser, PartInspector
from tlt_vision.segmentation_source import TwinLabels
from tlt_vision.self_filter import EeSelfFilter, drop_inside, off_own_ee, own_pixels

ROOT = Path(__file__).resolve().parents[1]
CAUGHT_GOAL = 0.99
REJECTED_GOAL = 0.02
# The lifter ZED that faces each arm's inspection pose (zed_1 looks away from ARS X at every angle).
CAMERAS = {"ars_x": "zed_2", "ars_y": "zed_1"}
RUN = load_yaml(ROOT / "config" / "twin" / "run.yaml")
RUN_SIZE = (RUN["cameras"]["zed"]["width"], RUN["cameras"]["zed"]["height"])


@dataclass(frozen=True)
class Jitter:
    """How far a presentation strays from the nominal one: each arm joint (normal, standard
    deviation in rad) and the strut along the grasp line (uniform, +- m); its roll about its axis
    is drawn over the whole turn."""

    joint_rad: float = 0.005
    slide_m: float = 0.01


@dataclass(frozen=True)
class Presented:
    """One strut presented once: its kind of defect ('good' for none) and the decision."""

    part: str
    arm: str
    defect: str
    passed: bool
    reasons: tuple[str, ...]


def defect_label(defect) -> str:
    if defect is None:
        return "good"
    if defect.kind == "bent_tube":
        return f"bent_tube {defect.bend_deg:g} deg"
    return f"{defect.kind} {defect.end}"


def struts(mission) -> list[tuple[str, str]]:
    """(part name, kind) of every strut of the mission's dispensers."""
    return [
        (f"{name}/{index}", d.part_kind)
        for name, d in mission.dispensers.items()
        if d.part_kind in ("vertical", "diagonal")
        for index in range(d.count)
    ]


def scenario(mission, bends: list[float]):
    """The mission's struts in turn: good, end fitting a missing, good, b missing, good, bent
    (half of them good, the bends cycled through ``bends``)."""
    from tlt_sim.model.scenario import Defect, Scenario

    defects = {}
    for n, (name, _) in enumerate(struts(mission)):
        turn = n % 6
        if turn in (1, 3):
            defects[name] = Defect("missing_end_fitting", "a" if turn == 1 else "b")
        elif turn == 5:
            defects[name] = Defect("bent_tube", bend_deg=bends[(n // 6) % len(bends)])
    return Scenario(name="inspection bench", description="struts defective in turn", defects=defects)


def present(scene, part, arm: str, joints: np.ndarray, rng: np.random.Generator, jitter: Jitter):
    """Seat ``part`` in ``arm``'s grasp at ``joints`` jittered, slid and rolled; render the ZED."""
    scene.pose_arm(arm, joints + rng.normal(0.0, jitter.joint_rad, joints.size))
    roll = rng.uniform(0.0, 2 * np.pi)
    scene.seat_in_grasp(part.name, arm, roll, rng.uniform(-jitter.slide_m, jitter.slide_m))
    return scene.render(CAMERAS[arm], *RUN_SIZE)


def without_own_ee(scene, frame, ee_filter: EeSelfFilter) -> np.ndarray:
    """The frame's depth with both arms' end effectors taken out, as the vision node does from the
    arms' joint states (here the twin's own poses of the flanges and its width and grasp joints)."""
    from tlt_sim.model import names

    camera = pose_matrix(frame.position, frame.rotation)
    placed = []
    for arm in ARMS:
        flange = pose_matrix(*scene.body_pose(names.ee_body(arm)))
        jaws = {side: scene.position(names.grasp_joint(arm, side)) for side in ("a", "b")}
        placed += ee_filter.place(camera, flange, scene.position(names.width_joint(arm)), jaws)
    return drop_inside(frame.depth, frame.intrinsics, placed, ee_filter.margin)[0]


@dataclass(frozen=True)
class Segmentation:
    """Detections of a rendered frame as the vision node makes them for InspectPart: the twin's
    labels, or Mask R-CNN down to the configuration's score floor, its thin parts cut and joined on
    the frame's depth (``segmentation.depth_split``: the node's frames carry their depth), with its
    closer look at a region of the frame (``segmentation.second_look_closer``)."""

    segmenter: Any = None  # MaskRcnnSegmenter; None for the twin's labels
    scale: float | None = None

    def __call__(self, frame, camera: str):
        if self.segmenter is None:
            return TwinLabels.detect_render(frame, camera)
        return self.segmenter.detect(self._frame(frame, camera))

    def closer(self, frame, camera: str) -> LookCloser | None:
        if self.segmenter is None or self.scale is None:
            return None
        whole = self._frame(frame, camera)
        return lambda region: self.segmenter.detect_in(whole, region, self.scale)

    @staticmethod
    def _frame(frame, camera: str) -> CameraFrame:
        k = frame.intrinsics
        images = {"rgb": frame.rgb, "depth": frame.depth}
        return CameraFrame(camera, 0.0, f"{camera}_optical", k, k.matrix, images)


def detector(kind: str, weights: str | None = None, config: VisionConfig | None = None) -> Segmentation:
    """The twin's labels, or Mask R-CNN (``weights``, by default the configured ones) as the
    ``config`` (by default config/vision/node.yaml) sets it up."""
    if kind == "twin":
        return Segmentation()
    from tlt_vision.segmentation_source import MaskRcnnSegmenter

    config = config or load_config()
    closer = config.raw["segmentation"]["second_look_closer"]
    segmenter = MaskRcnnSegmenter.from_config(config, weights)
    return Segmentation(segmenter, closer["scale"] if closer else None)


def run(args: argparse.Namespace) -> list[Presented]:
    from tlt_sim.model import names
    from tlt_sim.model.scene import Scene

    mission = load_mission(ROOT / "missions" / f"{args.mission}.yaml")
    scen = scenario(mission, args.bends)
    config = load_config()
    # The node is configured with its camera's noise (node.yaml depth_noise); so is the bench.
    config.raw["depth_noise"]["fraction"] = args.depth_noise
    seg = config.raw["segmentation"]
    if args.min_score is not None:
        seg["min_score"] = args.min_score
    if args.second_look is not None:
        seg["second_look_score"] = args.second_look or None
    if (seg["second_look_score"] or 0.0) > seg["min_score"]:  # a --min-score under it: no second look
        seg["second_look_score"] = None
    if not args.closer:
        seg["second_look_closer"] = None
    inspector = PartInspector(config, mission)
    ee_filter = EeSelfFilter.from_config(config.raw["ee_self_filter"])
    detect = detector(args.segmentation, args.weights, config)
    rng = np.random.default_rng(args.seed)
    # Its own draw, so that a strut is presented the same with noise and without.
    noise_rng = np.random.default_rng(args.seed + 1)
    jitter = Jitter(np.radians(args.joint_jitter_deg), args.slide_mm / 1000.0)
    arms = inspection_joints()
    results: list[Presented] = []
    with Scene(mission=mission, scenario=scen) as scene:
        for i in range(2):
            scene.set_joint_state(names.camera_mount(i), 0.0)  # outward, as the CRS holds them
        presented = struts(mission)
        total, done = len(presented) * args.rounds, 0
        started = time.monotonic()
        for round_ in range(args.rounds):
            for i, (name, kind) in enumerate(presented):
                arm = ARMS[(i + round_) % 2]  # each strut by the other arm next round
                part = scene.part(name)
                home = scene.body_pose(part.body)
                frame = present(scene, part, arm, arms[arm], rng, jitter)
                if args.depth_noise:
                    frame.depth = with_noise(frame.depth, args.depth_noise, noise_rng)
                depth = without_own_ee(scene, frame, ee_filter) if args.self_filter else frame.depth
                scene.place_part(name, *home)  # back in its rack, out of the next view
                camera = CAMERAS[arm]
                own = own_pixels(frame.depth, depth)
                report, _ = inspector.inspect(
                    f"bench/{kind}",
                    kind,
                    off_own_ee(detect(frame, camera), own, ee_filter.own_share),
                    depth,
                    frame.intrinsics,
                    frame.rgb,
                    detect.closer(frame, camera),
                )
                defect = defect_label(scen.defects.get(name))
                results.append(Presented(name, arm, defect, report.passed, tuple(report.reasons)))
                done += 1
                each = (time.monotonic() - started) / done
                print(
                    f"\r{done}/{total} presented ({each:.1f} s each, {(total - done) * each:.0f} s left)",
                    end="",
                    file=sys.stderr,
                    flush=True,
                )
        print(file=sys.stderr)
    return results


def report(results: list[Presented]) -> dict[str, float | int]:
    by_defect: dict[str, list[Presented]] = defaultdict(list)
    for r in results:
        by_defect[r.defect].append(r)
    print(f"{'part':28s} {'presented':>9s} {'failed':>7s} {'rate':>7s}")
    for defect in sorted(by_defect, key=lambda d: (d != "good", d)):
        rs = by_defect[defect]
        failed = sum(not r.passed for r in rs)
        print(f"{defect:28s} {len(rs):9d} {failed:7d} {failed / len(rs):7.1%}")
    wrong = [r for r in results if r.passed != (r.defect == "good")]
    if wrong:
        print("\nwrong decisions:")
        for r in wrong:
            verdict = "passed" if r.passed else "failed: " + "; ".join(r.reasons)
            print(f"  {r.part} ({r.defect}) by {r.arm}: {verdict}")
    good = by_defect.get("good", [])
    bad = [r for r in results if r.defect != "good"]
    rejected = sum(not r.passed for r in good) / max(1, len(good))
    caught = sum(not r.passed for r in bad) / max(1, len(bad))
    print(f"\ndefective parts caught: {caught:.1%} of {len(bad)} (goal >= {CAUGHT_GOAL:.0%})")
    print(f"good parts rejected:    {rejected:.1%} of {len(good)} (goal <= {REJECTED_GOAL:.0%})")
    return {"caught": caught, "rejected": rejected, "defective": len(bad), "good": len(good)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mission", default="two_bay", help="missions/NAME.yaml: its struts are presented")
    parser.add_argument("--rounds", type=int, default=2, help="times each strut is presented")
    parser.add_argument("--seed", type=int, default=1100)
    parser.add_argument(
        "--bends", type=float, nargs="+", default=[3.0, 5.0, 8.0, 12.0], help="bends of the bent tubes, deg"
    )
    nominal = Jitter()
    parser.add_argument(
        "--joint-jitter-deg", type=float, default=np.degrees(nominal.joint_rad), help="per joint, std dev"
    )
    parser.add_argument("--slide-mm", type=float, default=nominal.slide_m * 1000, help="along the grasp, +-")
    parser.add_argument("--segmentation", choices=("twin", "mask_rcnn"), default="twin")
    parser.add_argument("--weights", help="Mask R-CNN weights (default: config/vision/node.yaml's)")
    parser.add_argument("--min-score", type=float, help="Mask R-CNN's (default: config/vision/node.yaml's)")
    parser.add_argument(
        "--second-look", type=float, help="second_look_score, 0 for none (default: config/vision/node.yaml's)"
    )
    parser.add_argument(
        "--closer",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the second look's closer look at a region (Mask R-CNN), as configured",
    )
    parser.add_argument(
        "--self-filter",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="take the end effectors out of the depth first, as the vision node does",
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--depth-noise",
        type=float,
        default=0.0,
        help="Gaussian noise added to each pixel's depth, a fraction of it; the node is "
        "told so (node.yaml depth_noise)",
    )
    parser.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    if not 0.0 <= args.depth_noise <= 0.1:
        parser.error(f"--depth-noise {args.depth_noise}: a fraction of the depth from 0 to 0.1")
    torch.set_num_threads(args.threads)
    figures = report(run(args))
    if args.json:
        settings = {
            "seed": args.seed,
            "rounds": args.rounds,
            "mission": args.mission,
            "segmentation": args.segmentation,
            "weights": args.weights,
        }
        args.json.write_text(json.dumps({**settings, **figures}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
