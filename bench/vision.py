"""Vision benchmark on freshly rendered held-out scenes (issue 8, paper §V.E).

Renders ``--count`` images of the twin with a seed the training sets do not use (or reads
``--images DIR``), runs the shipped Mask R-CNN on each as the vision node does, then C-3PO on every
detected part, and prints against the issue's goals:

* mask AP50 per class and mean (goal >= 0.90) of the detections the node poses (the model's,
  with the thin parts' regions cut where the depth jumps, node.yaml ``segmentation.depth_split``,
  the end fittings' masks trimmed, ``segmentation.semantic_trim``, and those of end fittings and
  rivets made exclusive, ``segmentation.exclusive_overlaps``), and of the model's own on
  the RGB image alone (its semantic head's map read as the node reads it,
  ``segmentation.semantic_background_weight``);
* C-3PO on the parts both the model and the twin segment (a detection matched to a ground-truth
  instance of its class at mask IoU >= 0.5): the fraction certified (goal >= 95 %), of the certified
  the fraction with ADD-S under 2 % of the part's size (goal >= 95 %), their median rotation error
  (goal <= 2 deg) and translation error (goal <= 3 mm); then the same from the twin's own masks,
  which tells segmentation's share of the errors from the pose's; each also restricted to the views
  that are non-degenerate at the true pose (the certificate's keypoint-group rule applied to the
  observed points and the part's true pose), since no pose of a part seen from a degenerate view
  may be certified; and, on the model's masks, to the views in which the twin's own mask of the
  part shows enough of it (the same rule on that mask's cloud), which counts what segmentation
  loses as well: a mask short of a corner joint's vertex leaves a view the camera shows well
  degenerate to the pipeline;
* segmentation and pose of every detected part of a 640x480 frame, median and p95 over the frames
  (goal <= 500 ms on 2 CPU cores).

``--picture PATH`` draws the first frames (``--picture-frames``) as the node saw them: its masks,
and every posed part's model where C-3PO put it, green when certified and red when not
(tlt_vision.pose_picture).

The images are taken through the twin's camera models (``--camera-model realistic``, the
default: config/twin/cameras.yaml's depth noise, holes, image noise and exposure; docs/cameras.md),
and the pipeline is told each camera's noise as the node is (node.yaml ``depth_noise.cameras``);
``--camera-model exact`` renders them exact, for diagnosis. ``--depth-noise F`` adds Gaussian
noise of F times each pixel's depth (drawn the same for each image every run), to see what of the
figures holds on a real camera's depth, and tells the node's pipeline so (node.yaml
``depth_noise``), which then also reports the views within the noise's reach;
``--image-noise S`` adds S grey levels of Gaussian noise to the colours.

Cross frames are left out of the pose figures: the twin labels each side as an instance while the
pose model is the whole square, which the node assembles from the sides of the one part it
inspects. Tubes are posed with the model of their kind (vertical or diagonal, as the node knows
from the request; here from the twin's instance name); an unmatched tube detection with the
vertical one.

    .venv/bin/python bench/vision.py [--weights models/vision/mask_rcnn.pt] [--count 40]
        [--seed 900] [--images DIR] [--threads 2] [--camera-model realistic|exact]
        [--depth-noise 0.01] [--image-noise 3]
        [--picture vision_poses.png] [--picture-frames 4] [--json figures.json]

``--json PATH`` also writes the figures as JSON (``bench/vision_candidate.py`` reads them).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tlt_sim.model.camera_sensor import DEFAULT_CAMERAS
from tlt_sim.model.config import load_edu
from tlt_tools.vision_training.dataset import ImageSet, Sample, instance_model
from tlt_tools.vision_training.render_dataset import render_set
from tlt_tools.vision_training.twin_renderer import RenderSettings

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import CadModel
from tlt_vision.depth_noise import EXACT, DepthNoise, with_noise
from tlt_vision.detections import Detection, detection_of, detections_from_mask_rcnn
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import load_estimators
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.pose.errors import add_s, non_degenerate_at, rotation_error_deg
from tlt_vision.pose.precision import model_motion_matrix, pose_precision
from tlt_vision.pose_picture import PosedFrame, write_pose_picture
from tlt_vision.segmentation.evaluate import MaskAP, mask_iou
from tlt_vision.segmentation.inference import detect_rgb
from tlt_vision.segmentation_source import MaskRcnnSegmenter

ROOT = Path(__file__).resolve().parents[1]
POSED = ("strut_tube", "end_fitting", "corner_joint", "rivet")
ADD_S_FRACTION = 0.02


@dataclass
class PoseTally:
    """Pose figures of one segmentation source, per class."""

    estimated: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    certified: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    add_s_ok: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    rotation: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    translation: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    # Views that show enough of the part by the certificate's own rule at the *true* pose: the
    # share of these certified is the pose stage's figure on views that can be certified at all.
    whole: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    whole_certified: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    # The same rule on the cloud of the twin's own mask of the part: views in which the camera
    # shows enough of the part, whatever the detection took in or left out. On the model's masks
    # the share of these certified counts segmentation's losses too (a corner joint's mask short
    # of a vertex the twin's shows); and a tube's mask running on past its end, into the rack it
    # lies on, does not pass for its end seen. On the twin's masks it is ``whole`` again.
    shown: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    shown_certified: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    # Of those, the views whose depth's noise (node.yaml depth_noise) leaves their part certifiable
    # at all (src/tlt_vision/depth_noise.py): on exact depth, every one.
    reach: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    reach_certified: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    # Of the non-degenerate views not certified, why (the certificate's first reason) and whether
    # the pose was right all the same (ADD-S within the goal): a right pose refused points at the
    # certificate or the mask, a wrong one at the estimator.
    refused: dict[str, dict[tuple[str, bool], int]] = field(
        default_factory=lambda: defaultdict(lambda: defaultdict(int))
    )
    no_cloud: int = 0

    def total(self, table: dict[str, int]) -> int:
        return sum(table.values())


def pose_instances(
    pipelines, estimators, items, depth, intrinsics, tally: PoseTally, noise: DepthNoise = EXACT
) -> None:
    """Pose ``items`` [(Detection, model name, true 4x4 pose, the twin's mask of the part, or None
    where the detection's mask is the twin's)] on depth of the camera's ``noise`` and count them
    into ``tally``."""
    by_model: dict[str, list[tuple[Detection, np.ndarray, np.ndarray | None]]] = defaultdict(list)
    for det, name, true, truth_mask in items:
        by_model[name].append((det, true, truth_mask))
    for name, group in by_model.items():
        observations = pipelines[name].observe([d for d, _, _ in group], depth, intrinsics, depth_noise=noise)
        model = estimators[name].model
        for (det, true, truth_mask), obs in zip(group, observations, strict=True):
            if obs.estimate is None:
                tally.no_cloud += 1
                continue
            cls = model.object_class
            tally.estimated[cls] += 1
            e = obs.estimate
            points = pipelines[name].cloud(det, depth, intrinsics, depth_noise=noise).points
            whole = non_degenerate_at(model, points, true)
            tally.whole[cls] += whole
            shown = whole
            if truth_mask is not None:
                truth = dataclasses.replace(det, mask=truth_mask)
                truth_cloud = pipelines[name].cloud(truth, depth, intrinsics, depth_noise=noise)
                shown = truth_cloud.ok and non_degenerate_at(model, truth_cloud.points, true)
            tally.shown[cls] += shown
            reach = whole and within_reach(model, points, true, noise)
            tally.reach[cls] += reach
            right = add_s(model, e.rotation, e.translation, true[:3, :3], true[:3, 3]) < (
                ADD_S_FRACTION * model.diameter
            )
            if not e.certified:
                if reach:
                    tally.refused[cls][refusal_kind(e.certificate.reason), bool(right)] += 1
                continue
            tally.certified[cls] += 1
            tally.whole_certified[cls] += whole
            tally.shown_certified[cls] += shown
            tally.reach_certified[cls] += reach
            r_err = rotation_error_deg(model, e.rotation, true[:3, :3])
            tally.rotation[cls].append(r_err)
            tally.translation[cls].append(float(np.linalg.norm(e.translation - true[:3, 3])) * 1000)
            tally.add_s_ok[cls] += int(right)


# The certificate's reasons (src/tlt_vision/pose/certificate.py, free_space.py, pipeline.py), by
# the words they start with.
REFUSALS = (
    ("not observably correct", "Chamfer over threshold"),
    ("degenerate view", "degenerate at its pose"),
    ("posed model where the camera saw past it", "seen past"),
    ("depth too noisy", "depth too noisy"),
)


def within_reach(model: CadModel, points: np.ndarray, true: np.ndarray, noise: DepthNoise) -> bool:
    """Whether the depth's ``noise`` leaves a fit of ``points`` at the part's ``true`` pose
    certifiable: its predicted ADD-S error within the node's bound (:mod:`tlt_vision.pose.precision`)."""
    if noise.exact:
        return True
    motion = model_motion_matrix(model)
    precision = pose_precision(model, motion, points, true[:3, :3], true[:3, 3], noise, noise.frame_fx)
    return noise.precision_sigmas * precision.add_s <= noise.max_allowance * model.diameter


def refusal_kind(reason: str) -> str:
    for start, kind in REFUSALS:
        if reason.startswith(start):
            return kind
    return reason.split(":")[0] or "no reason given"


def pose_summary(tally: PoseTally) -> dict[str, Any]:
    """The figures :func:`report_poses` prints first, for ``--json``: parts posed and certified,
    views non-degenerate at the true pose and of them certified, the same of the views the twin's
    mask shows enough of (``views_shown``), certified within the ADD-S goal, median errors (None
    with nothing certified)."""
    rot = [v for c in tally.rotation.values() for v in c]
    trans = [v for c in tally.translation.values() for v in c]
    return {
        "posed": tally.total(tally.estimated),
        "certified": tally.total(tally.certified),
        "views": tally.total(tally.whole),
        "views_certified": tally.total(tally.whole_certified),
        "views_shown": tally.total(tally.shown),
        "views_shown_certified": tally.total(tally.shown_certified),
        "add_s_ok": tally.total(tally.add_s_ok),
        "median_rotation_deg": statistics.median(rot) if rot else None,
        "median_translation_mm": statistics.median(trans) if trans else None,
    }


def report_poses(title: str, tally: PoseTally, noise_bound: float) -> None:
    summary = pose_summary(tally)
    est, cert, ok = summary["posed"], summary["certified"], summary["add_s_ok"]
    print(f"{title}: {est} parts posed ({tally.no_cloud} without a usable cloud)")
    if not est:
        return
    print(f"  certified {cert}/{est} = {cert / est * 100:.1f} % (goal >= 95 %)")
    whole, whole_cert = summary["views"], summary["views_certified"]
    if whole:
        print(
            f"  of the {whole} views non-degenerate at the true pose (enough keypoint groups seen), "
            f"certified {whole_cert}/{whole} = {whole_cert / whole * 100:.1f} %"
        )
    shown, shown_cert = summary["views_shown"], summary["views_shown_certified"]
    if shown and (shown, shown_cert) != (whole, whole_cert):
        print(
            f"  of the {shown} views in which the twin's mask of the part shows enough of it "
            f"(segmentation's losses counted), certified {shown_cert}/{shown} = "
            f"{shown_cert / shown * 100:.1f} %"
        )
    reach, reach_cert = tally.total(tally.reach), tally.total(tally.reach_certified)
    if reach < whole:
        print(
            f"  of the {reach} of those the depth's noise leaves certifiable (a fit at the true pose "
            f"places the part to {noise_bound:.0%} of its size), certified "
            f"{reach_cert}/{reach} = {reach_cert / max(reach, 1) * 100:.1f} %"
        )
    if cert:
        print(
            f"  of the certified, ADD-S < 2 % of size: {ok}/{cert} = {ok / cert * 100:.1f} % (goal >= 95 %)"
        )
        print(
            f"  median rotation error {summary['median_rotation_deg']:.2f} deg (goal <= 2), "
            f"translation {summary['median_translation_mm']:.1f} mm (goal <= 3)"
        )
    for cls in POSED:
        n = tally.estimated.get(cls, 0)
        if not n:
            continue
        c = tally.certified.get(cls, 0)
        w = tally.whole.get(cls, 0)
        line = f"    {cls:13s} posed {n:4d}, certified {c / n * 100:5.1f} %"
        if w:
            line += f" ({tally.whole_certified.get(cls, 0) / w * 100:5.1f} % of {w} non-degenerate"
            r = tally.reach.get(cls, 0)
            if r < w:
                share = tally.reach_certified.get(cls, 0) / max(r, 1) * 100
                line += f", {share:5.1f} % of {r} in the noise's reach"
            line += ")"
        if c:
            line += (
                f", ADD-S ok {tally.add_s_ok.get(cls, 0) / c * 100:5.1f} %, rotation "
                f"{statistics.median(tally.rotation[cls]):5.2f} deg, translation "
                f"{statistics.median(tally.translation[cls]):5.1f} mm"
            )
        print(line)
    refused = [(cls, kinds) for cls, kinds in tally.refused.items() if kinds]
    if refused:
        print(
            "  not certified though non-degenerate at the true pose (and in the noise's reach), by the"
            " certificate's reason, [of them with a pose within the ADD-S goal]:"
        )
    for cls, kinds in sorted(refused):
        names = sorted({kind for kind, _ in kinds})
        text = ", ".join(
            f"{kind} {kinds[kind, True] + kinds[kind, False]} [{kinds[kind, True]}]" for kind in names
        )
        print(f"    {cls:13s} {text}")


def with_image_noise(sample: Sample, sigma: float, index: int) -> Sample:
    """``sample`` with Gaussian noise of ``sigma`` grey levels on each pixel's colours, the same
    each run."""
    noise = np.random.default_rng(2000 + index).normal(0.0, sigma, sample.rgb.shape)
    return dataclasses.replace(sample, rgb=np.clip(sample.rgb + noise, 0, 255).round().astype(np.uint8))


def with_depth_noise(sample: Sample, fraction: float, index: int) -> Sample:
    """``sample`` with Gaussian noise of ``fraction`` times each pixel's depth, the same each run."""
    noisy = with_noise(sample.depth, fraction, np.random.default_rng(1000 + index))
    return dataclasses.replace(sample, depth=noisy)


class CameraOptics:
    """Which of the node's cameras took an image, from its focal length: the renders use the lifter
    ZED's optics or the EE D405's (config/twin/edu.yaml cameras), whose noise differs."""

    def __init__(self) -> None:
        fovy = load_edu()[0]["cameras"]
        self.fovy = {"zed_1": fovy["zed_fovy_deg"], "ars_x/d405_a": fovy["d405_fovy_deg"]}

    def __call__(self, k: np.ndarray, height: int) -> str:
        fovy = math.degrees(2 * math.atan(height / 2 / float(k[1, 1])))
        return min(self.fovy, key=lambda camera: abs(self.fovy[camera] - fovy))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--weights", type=Path, default=ROOT / "models/vision/mask_rcnn.pt")
    p.add_argument("--images", type=Path, help="a rendered image set to use instead of rendering")
    p.add_argument("--count", type=int, default=40, help="images to render")
    p.add_argument("--seed", type=int, default=900, help="render seed (training sets use 0-9)")
    p.add_argument("--mission", type=Path, default=ROOT / "missions/one_bay.yaml")
    p.add_argument("--config", type=Path, default=ROOT / "config/vision/node.yaml")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument(
        "--camera-model",
        choices=("realistic", "exact"),
        default="realistic",
        help="the images through the twin's camera models (config/twin/cameras.yaml), the "
        "node told each camera's noise (node.yaml depth_noise.cameras); or exact",
    )
    p.add_argument(
        "--cameras",
        type=Path,
        default=DEFAULT_CAMERAS,
        help="the camera models the realistic images are taken through (cameras.yaml)",
    )
    p.add_argument(
        "--lighting",
        default="",
        help="light the images by this preset of config/twin/lighting.yaml (lunar: a low, "
        "hard sun) instead of the renderer's random lights",
    )
    p.add_argument(
        "--depth-noise",
        type=float,
        default=0.0,
        help="Gaussian noise added to each pixel's depth, a fraction of it (default none)",
    )
    p.add_argument(
        "--image-noise",
        type=float,
        default=0.0,
        help="Gaussian noise added to each pixel's colours, in grey levels of 255 (default none)",
    )
    p.add_argument("--picture", type=Path, help="draw the first frames' masks and posed models into this PNG")
    p.add_argument("--picture-frames", type=int, default=4, help="frames drawn (default 4)")
    p.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = p.parse_args()
    if args.picture_frames < 1:
        p.error(f"--picture-frames {args.picture_frames}: at least one")
    if not 0.0 <= args.image_noise <= 64:
        p.error(f"--image-noise {args.image_noise}: grey levels from 0 to 64")
    if not 0.0 <= args.depth_noise <= 0.1:
        p.error(f"--depth-noise {args.depth_noise}: a fraction of the depth from 0 to 0.1")
    torch.set_num_threads(args.threads)
    mission = load_mission(args.mission)
    config = load_config(args.config, args.mission)
    # The node is configured with its camera's noise (node.yaml depth_noise); so is the bench.
    if args.camera_model == "exact":
        config = config.with_exact_depth()
    config.raw["depth_noise"]["fraction"] = args.depth_noise
    camera_of = CameraOptics()
    segmenter = MaskRcnnSegmenter.from_config(config, args.weights)
    model, max_size = segmenter.model, segmenter.max_size
    classes = list(model.cfg.classes)
    estimators = load_estimators(config, mission)
    opts = {**config.pipeline_options, "merge": ()}
    pipelines = {
        name: PartPipeline({estimators[name].model.object_class: e}, **opts) for name, e in estimators.items()
    }
    # A frame's parts of every kind posed in one call, as the node does (tubes as verticals).
    frame_pipeline = PartPipeline({cls: estimators[instance_model(cls, "")] for cls in POSED}, **opts)
    min_score = config.raw["segmentation"]["min_score"]

    with tempfile.TemporaryDirectory(prefix="tlt_bench_vision_") as tmp:
        root = args.images
        if root is None:
            root = Path(tmp)
            print(f"rendering {args.count} held-out images (seed {args.seed}) ...", flush=True)
            cameras = str(args.cameras) if args.camera_model == "realistic" else ""
            settings = RenderSettings(
                seed=args.seed, mission=str(args.mission), cameras=cameras, lighting=args.lighting
            )
            render_set(root, args.count, settings, progress_every=10)
        images = ImageSet(root)
        if images.classes != classes:
            print(f"{root}: classes {images.classes} differ from the model's {classes}", file=sys.stderr)
            return 2
        ap, ap_rgb = MaskAP(len(classes)), MaskAP(len(classes))
        from_model, from_twin = PoseTally(), PoseTally()
        frame_s, seg_s, parts = [], [], []
        pictured: list[PosedFrame] = []
        for i in range(len(images)):
            s = images[i]
            if args.depth_noise:
                s = with_depth_noise(s, args.depth_noise, i)
            if args.image_noise:
                s = with_image_noise(s, args.image_noise, i)
            intrinsics = Intrinsics.from_matrix(s.intrinsics)
            noise = config.depth_noise_of(camera_of(s.intrinsics, s.depth.shape[0]), intrinsics.fx)
            t0 = time.perf_counter()
            rgb_only = detect_rgb(model, s.rgb, max_size)
            pred = segmenter.refine(rgb_only, s.depth, s.intrinsics)
            t1 = time.perf_counter()
            dets = detections_from_mask_rcnn(pred, classes, min_score)
            # Every detected part posed, as a frame's worth of work.
            frame_items = [d for d in dets if d.object_class in POSED]
            observations = frame_pipeline.observe(frame_items, s.depth, intrinsics, depth_noise=noise)
            frame_s.append(time.perf_counter() - t0)
            if args.picture and len(pictured) < args.picture_frames:
                pictured.append(
                    PosedFrame(f"{images.path(i).name}", s.rgb, s.intrinsics, frame_items, observations)
                )
            seg_s.append(t1 - t0)
            parts.append(len(frame_items))
            gt_masks = torch.as_tensor(s.masks, dtype=torch.bool)
            gt = {"masks": gt_masks, "labels": torch.as_tensor(s.labels, dtype=torch.long)}
            ap.add(pred, gt)
            ap_rgb.add(rgb_only, gt)

            matched, truth = [], []
            iou = mask_iou(pred["masks"], gt_masks) if len(pred["masks"]) and len(gt_masks) else None
            used: set[int] = set()
            for j, (label, name, pose) in enumerate(zip(s.labels, s.names, s.poses, strict=True)):
                cls = classes[int(label) - 1]
                if cls not in POSED:
                    continue
                item_name = instance_model(cls, str(name))
                truth.append((Detection(cls, s.masks[j]), item_name, pose, None))
                if iou is None:
                    continue
                same = (pred["labels"] == int(label)) & (pred["scores"] >= min_score)
                scores = torch.where(same, iou[:, j], torch.zeros_like(iou[:, j]))
                best = int(scores.argmax())
                if float(scores[best]) >= 0.5 and best not in used:
                    used.add(best)
                    matched.append((detection_of(pred, classes, best), item_name, pose, s.masks[j]))
            pose_instances(pipelines, estimators, matched, s.depth, intrinsics, from_model, noise)
            pose_instances(pipelines, estimators, truth, s.depth, intrinsics, from_twin, noise)
            print(
                f"  image {i + 1}/{len(images)}: {len(dets)} detections, {len(matched)} matched, "
                f"frame {frame_s[-1]:.2f} s",
                flush=True,
            )

    print(
        f"\n{args.weights.relative_to(ROOT) if args.weights.is_relative_to(ROOT) else args.weights} "
        f"on {len(images)} held-out images, max size {max_size or 'full'}, {args.threads} threads"
        + f", {args.camera_model} cameras"
        + (f", {args.lighting} light" if args.lighting else "")
        + (f", depth noise {args.depth_noise:g} of the depth" if args.depth_noise else "")
        + (f", image noise {args.image_noise:g} grey levels" if args.image_noise else "")
    )
    cut = (
        "cut where the depth jumps"
        if segmenter.depth_split
        else "not cut by depth (no segmentation.depth_split)"
    )
    if segmenter.trim is not None:
        cut += f", {', '.join(segmenter.trim.classes)} trimmed of thin parts' pixels"
    if segmenter.overlaps is not None:
        cut += f", {', '.join(segmenter.overlaps.classes)} masks exclusive"
    alone = f"the model alone, RGB (the head's background weighted {model.cfg.semantic_background_weight:g})"
    results = {}
    for key, title, acc in (("node", f"as the node segments ({cut})", ap), ("model_alone", alone, ap_rgb)):
        result = results[key] = acc.result()
        per_class = {classes[k - 1]: v for k, v in result["per_class"].items()}
        ap_line = ", ".join(f"{c} {per_class[c]:.3f}" if c in per_class else f"{c} -" for c in classes)
        print(
            f"mask AP50 {title}: {result['map']:.3f} (goal >= 0.90; ratio {result['map'] / 0.90:.2f}): "
            f"{ap_line}"
        )
    bound = config.depth_noise.max_allowance
    report_poses("C-3PO on Mask R-CNN masks matched to the twin's parts", from_model, bound)
    report_poses("C-3PO on the twin's own masks (segmentation taken out)", from_twin, bound)
    med, p95 = statistics.median(frame_s), float(np.percentile(frame_s, 95))
    print(
        f"segmentation + pose of every part in a frame ({statistics.mean(parts):.1f} parts on "
        f"average): median {med * 1000:.0f} ms, p95 {p95 * 1000:.0f} ms (goal <= 500 ms; ratio "
        f"{med / 0.5:.2f}); segmentation alone median {statistics.median(seg_s) * 1000:.0f} ms"
    )
    if args.json:
        figures = {
            "weights": str(args.weights),
            "images": len(images),
            "source": str(root) if args.images else None,
            "seed": None if args.images else args.seed,
            "camera_model": args.camera_model,
            "depth_noise": args.depth_noise,
            "image_noise": args.image_noise,
            "threads": args.threads,
            **{
                f"mask_ap50_{key}": {
                    "mean": r["map"],
                    "per_class": {classes[k - 1]: v for k, v in r["per_class"].items()},
                }
                for key, r in results.items()
            },
            "poses": pose_summary(from_model),
            "poses_twin_masks": pose_summary(from_twin),
            "frame_median_ms": med * 1000,
            "frame_p95_ms": p95 * 1000,
            "segmentation_median_ms": statistics.median(seg_s) * 1000,
            "parts_per_frame": statistics.mean(parts),
        }
        args.json.write_text(json.dumps(figures, indent=1) + "\n")
    if args.picture:
        models = {cls: e.model for cls, e in frame_pipeline.estimators.items()}
        written = write_pose_picture(args.picture, pictured, models, classes)
        print(f"picture of {len(pictured)} frames: {written}")
    print(
        "not measured here: inspection catch and false-reject rates (tests/tlt_vision/"
        "test_twin_parts.py checks each defect kind), AprilTag at 1 m (tests/tlt_vision/test_apriltag.py)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
