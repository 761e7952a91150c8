"""Point-cloud filters on the twin's realistic depth: the pipeline's own against open3d's (issue 64).

Renders ``--count`` held-out images through the twin's camera models (config/twin/cameras.yaml:
the ZED 2i's and D405's stereo noise growing as z squared and shared over a few pixels, holes at
edges, thin parts and highlights) and, for every part instance the twin segments (its own masks,
so segmentation takes no share), builds the cloud C-3PO is given in each of these ways:

* ``exact``: the pipeline's cloud on the render's exact depth (the twin's exact cameras);
* ``raw``: the pipeline's cloud with no depth filter (its mask, border, depth span and detached
  pieces, ``max_points`` evenly spaced), what every other way starts from;
* ``median``: the pipeline's cloud as the node builds it for that camera (node.yaml
  ``depth_noise.cameras``): each point the median depth of its mask's pixels in a 5 x 5 window
  (src/tlt_vision/depth_noise.py); ``median9`` the same in a 9 x 9 window;
* ``o3d``: every valid pixel of the mask back-projected, then open3d's statistical outlier
  removal, radius outlier removal and voxel grid (each voxel's points averaged), evenly thinned to
  ``max_points``;
* ``median+o3d``: the pipeline's filtered cloud, then open3d's two outlier removals;
* ``plane``: every valid pixel, each point moved along its ray onto the plane fitted to its
  nearest neighbours in space (a moving-least-squares step in numpy), evenly thinned.

Each cloud is measured against the part's true surface (the CAD model at the twin's pose, exact
distances from its primitives, tlt_vision.cad.surface): RMS and 90th percentile of the points'
distances, the share more than 5 mm off, and the milliseconds it took. The 90th percentile is set
beside the allowance the certificate makes for the noise left (``DepthNoise.allowance``). Then
each kind of cloud is posed by the node's pipeline (C-3PO, refinement, certificate with the
camera's allowance, axial slide, free space): the share certified, of those the share within 2 %
of the part's size in ADD-S, and the share and median ADD-S of all. The views counted are those
whose cloud on the exact depth shows enough of the part at its true pose, the same for every way,
each camera's apart. With ``--icp``, the ``median`` cloud's poses are also refined by open3d's
ICP onto the model's side facing the camera, point-to-plane with a Tukey kernel and
point-to-point, and their ADD-S compared. The open3d ways need ``pip install open3d``; without
it the bench says so and measures the rest.

    .venv/bin/python bench/cloud_filters.py [--count 16] [--seed 930] [--icp] [--no-pose]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import ModuleType

import numpy as np
import torch
from scipy.spatial import cKDTree
from tlt_sim.model.camera_sensor import DEFAULT_CAMERAS, load_camera_sensors
from tlt_sim.model.config import load_edu
from tlt_tools.vision_training.dataset import instance_model
from tlt_tools.vision_training.twin_renderer import CLASSES, RenderSettings, TwinRenderer

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import CadModel
from tlt_vision.depth_noise import EXACT, DepthNoise
from tlt_vision.detections import Detection
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import load_estimators
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pointcloud import Intrinsics, MaskedCloud, PinholeIntrinsics
from tlt_vision.pose.errors import add_s, non_degenerate_at

ROOT = Path(__file__).resolve().parents[1]
POSED = ("strut_tube", "end_fitting", "corner_joint", "rivet")
ADD_S_FRACTION = 0.02
OFF_M = 0.005  # a point this far from the true surface counts as an outlier
# open3d's settings: its tutorials' statistical outlier removal (20 neighbours, 2 sigma); a radius
# of three times the cloud's spacing needing 6 neighbours.
SOR_NEIGHBOURS, SOR_STD = 20, 2.0
ROR_POINTS, ROR_SPACINGS = 6, 3.0
PLANE_NEIGHBOURS = 16
ICP_TUKEY_M, ICP_MAX_M, ICP_MODEL_POINTS = 0.004, 0.01, 4096
ICP_KINDS = {"plane": "point-to-plane, Tukey kernel", "point": "point-to-point"}


def open3d_or_none() -> ModuleType | None:
    """open3d, where it is installed."""
    try:
        import open3d
    except ImportError:
        return None
    return open3d


def evenly(points: np.ndarray, count: int | None) -> np.ndarray:
    """At most ``count`` of ``points``, evenly spaced in their order (as the pipeline thins)."""
    if count is None or len(points) <= count:
        return points
    return points[np.linspace(0, len(points) - 1, count).round().astype(np.intp)]


def spacing(points: np.ndarray) -> float:
    """The median distance (m) from a point of ``points`` to its nearest neighbour."""
    d, _ = cKDTree(points).query(points, 2)
    return float(np.median(d[:, 1]))


def o3d_filtered(o3d: ModuleType, points: np.ndarray, keep: int | None) -> np.ndarray:
    """``points`` through open3d's statistical and radius outlier removal (the radius a few times
    the cloud's spacing) and, with more than ``keep`` points left, its voxel grid sized to leave
    about ``keep``: each voxel's points averaged, where the pipeline would thin them."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    step = spacing(points)
    cloud, _ = cloud.remove_statistical_outlier(SOR_NEIGHBOURS, SOR_STD)
    cloud, _ = cloud.remove_radius_outlier(ROR_POINTS, ROR_SPACINGS * step)
    n = len(cloud.points)
    if keep is not None and n > keep:
        cloud = cloud.voxel_down_sample(step * math.sqrt(n / keep))
    return np.asarray(cloud.points)


def plane_smoothed(points: np.ndarray, neighbours: int = PLANE_NEIGHBOURS) -> np.ndarray:
    """Each point moved along its ray (from the camera's centre) onto the plane fitted to its
    ``neighbours`` nearest points."""
    p = np.asarray(points, dtype=np.float64)
    k = min(neighbours, len(p))
    _, idx = cKDTree(p).query(p, k)
    near = p[idx]  # (N, k, 3)
    centre = near.mean(1)
    _, _, vt = np.linalg.svd(near - centre[:, None], full_matrices=False)
    normal = vt[:, 2]  # the least spread direction
    ray = p / np.linalg.norm(p, axis=1, keepdims=True)
    along = np.einsum("ij,ij->i", ray, normal)
    # Along the ray to the plane: p + s * ray with (p + s ray - centre) . n = 0; a plane seen edge-on
    # moves nothing.
    to_plane = np.einsum("ij,ij->i", centre - p, normal)
    s = np.where(np.abs(along) > 0.2, to_plane / np.where(along == 0, 1, along), 0)
    return p + s[:, None] * ray


class GivenClouds(PartPipeline):
    """The node's pipeline with its clouds made by ``make(pipeline, detection, depth, intrinsics,
    noise)``, timed into ``seconds``."""

    def __init__(self, make: Callable[..., MaskedCloud], **options) -> None:
        super().__init__(**options)
        self.make = make
        self.seconds: list[float] = []

    def cloud(
        self,
        detection: Detection,
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> MaskedCloud:
        t0 = time.perf_counter()
        cloud = self.make(self, detection, depth, intrinsics, depth_noise or self.depth_noise)
        self.seconds.append(time.perf_counter() - t0)
        return cloud

    def base_cloud(
        self,
        detection: Detection,
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        noise: DepthNoise,
        max_points: int | None,
    ) -> MaskedCloud:
        """The pipeline's own cloud with ``noise`` filtered and ``max_points`` points at most."""
        kept, self.max_points = self.max_points, max_points
        try:
            return PartPipeline.cloud(self, detection, depth, intrinsics, None, noise)
        finally:
            self.max_points = kept


def make_variants(o3d: ModuleType | None, max_points: int) -> dict[str, Callable[..., MaskedCloud]]:
    """The ways of making a cloud, by name (the open3d ones only with ``o3d``)."""

    def replaced(cloud: MaskedCloud, points: np.ndarray, min_points: int) -> MaskedCloud:
        if len(points) < min_points:
            return MaskedCloud(
                cloud.points[:0],
                None,
                cloud.mask_pixels,
                f"too few points: {len(points)} after filtering < {min_points}",
            )
        return MaskedCloud(points.astype(np.float32), None, cloud.mask_pixels)

    def raw(pipe, det, depth, k, noise):
        return pipe.base_cloud(det, depth, k, EXACT, max_points)

    def median(pipe, det, depth, k, noise):
        return pipe.base_cloud(det, depth, k, noise, max_points)

    def median9(pipe, det, depth, k, noise):
        return pipe.base_cloud(det, depth, k, replace(noise, window=9), max_points)

    def dense_then(step):
        def make(pipe, det, depth, k, noise):
            cloud = pipe.base_cloud(det, depth, k, EXACT, None)
            if not cloud.ok:
                return cloud
            return replaced(cloud, evenly(step(cloud.points, k), max_points), pipe.min_points)

        return make

    variants = {"exact": raw, "raw": raw, "median": median, "median9": median9}
    if o3d is not None:
        variants["o3d"] = dense_then(lambda p, k: o3d_filtered(o3d, p, max_points))

        def median_o3d(pipe, det, depth, k, noise):
            cloud = median(pipe, det, depth, k, noise)
            if not cloud.ok:
                return cloud
            return replaced(cloud, o3d_filtered(o3d, cloud.points, None), pipe.min_points)

        variants["median+o3d"] = median_o3d
    variants["plane"] = dense_then(lambda p, k: plane_smoothed(p))
    return variants


def surface_distances(model: CadModel, points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Distances (m) of camera-frame ``points`` to ``model``'s surface at ``pose`` (4x4)."""
    local = (np.asarray(points, dtype=np.float64) - pose[:3, 3]) @ pose[:3, :3]
    with torch.no_grad():
        return model.surface(torch.as_tensor(local, dtype=torch.float32)[None])[0].abs().numpy()


def icp_refined(
    o3d: ModuleType,
    model: CadModel,
    points: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    kind: str,
) -> tuple[np.ndarray, np.ndarray]:
    """The pose ``rotation, translation`` refined by open3d's ICP of the observed ``points`` onto
    the model's surface sample there, the side facing the camera (at the origin): ``kind``
    ``plane`` (point-to-plane, Tukey kernel) or ``point`` (point-to-point)."""
    reg = o3d.pipelines.registration
    surface, normals = model.sample(ICP_MODEL_POINTS, np.random.default_rng(0))
    surface, normals = surface @ rotation.T + translation, normals @ rotation.T
    facing = np.einsum("ij,ij->i", surface, normals) < 0
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(surface[facing]))
    target.normals = o3d.utility.Vector3dVector(normals[facing])
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    estimation = (
        reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=ICP_TUKEY_M))
        if kind == "plane"
        else reg.TransformationEstimationPointToPoint()
    )
    result = reg.registration_icp(source, target, ICP_MAX_M, np.eye(4), estimation)
    back = np.linalg.inv(result.transformation)  # observed -> model's place; the model follows back
    return back[:3, :3] @ rotation, back[:3, :3] @ translation + back[:3, 3]


@dataclass
class Poses:
    """One way's poses of the views counted, from one camera."""

    views: int = 0
    certified: int = 0
    certified_right: int = 0
    right: int = 0
    add_s_mm: list[float] = field(default_factory=list)
    by_class: dict[str, list[int]] = field(default_factory=lambda: defaultdict(lambda: [0, 0]))


@dataclass
class Tally:
    """One way's figures, per camera."""

    rms: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    p90: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    allowance: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    off: dict[str, list[int]] = field(default_factory=lambda: defaultdict(lambda: [0, 0]))
    points: dict[str, list[int]] = field(default_factory=lambda: defaultdict(list))
    failed: int = 0
    poses: dict[str, Poses] = field(default_factory=lambda: defaultdict(Poses))


class CameraOptics:
    """Which camera's optics an image used, from its focal length (the renders use the ZED's or the
    D405's, config/twin/edu.yaml)."""

    def __init__(self) -> None:
        cams = load_edu()[0]["cameras"]
        self.fovy = {"zed_1": cams["zed_fovy_deg"], "ars_x/d405_a": cams["d405_fovy_deg"]}

    def __call__(self, k: np.ndarray, height: int) -> str:
        fovy = math.degrees(2 * math.atan(height / 2 / float(k[1, 1])))
        return min(self.fovy, key=lambda camera: abs(self.fovy[camera] - fovy))


def measure(
    args: argparse.Namespace, o3d: ModuleType | None
) -> tuple[dict[str, Tally], dict[str, list[float]], dict[str, list[float]]]:
    """Every way's tally, its seconds per cloud, and with ``--icp`` the ADD-S (mm) of the median
    cloud's poses before and after ICP and the seconds ICP took."""
    mission = load_mission(args.mission)
    config = load_config(args.config, args.mission)
    estimators = load_estimators(config, mission)
    opts = {**config.pipeline_options, "merge": ()}
    variants = make_variants(o3d, opts["max_points"])
    pipes = {
        (v, name): GivenClouds(make, estimators={estimators[name].model.object_class: e}, **opts)
        for v, make in variants.items()
        for name, e in estimators.items()
    }
    views = {name: PartPipeline({e.model.object_class: e}, **opts) for name, e in estimators.items()}
    tallies = {v: Tally() for v in variants}
    icp: dict[str, list[float]] = defaultdict(list)
    camera_of = CameraOptics()
    # Rendered exact and taken through the camera models here, so that each view's exact depth is
    # at hand as well.
    renderer = TwinRenderer(RenderSettings(seed=args.seed, mission=str(args.mission)))
    sensors = load_camera_sensors(DEFAULT_CAMERAS)
    try:
        for i in range(args.count):
            s, kind = renderer.sample(i)
            k = Intrinsics.from_matrix(s.intrinsics)
            camera = camera_of(s.intrinsics, s.depth.shape[0])
            _, depth = sensors.for_camera(camera).apply(s.rgb, s.depth, k.fx, sensors.frame_rng(camera, i))
            noise = config.depth_noise_of(camera, k.fx)
            cam = "zed" if camera.startswith("zed") else "d405"
            items = []
            for j, (label, name, pose) in enumerate(zip(s.labels, s.names, s.poses, strict=True)):
                cls = CLASSES[int(label) - 1]
                if cls in POSED:
                    det, model_name = Detection(cls, s.masks[j]), instance_model(cls, str(name))
                    # The views counted: those whose cloud on the exact depth shows enough of the
                    # part at its true pose, the same for every way.
                    exact = views[model_name].cloud(det, s.depth, k, depth_noise=EXACT)
                    shown = exact.ok and non_degenerate_at(estimators[model_name].model, exact.points, pose)
                    items.append((det, model_name, pose, shown))
            for v in variants:
                exact = v == "exact"
                count_instances(
                    tallies[v],
                    pipes,
                    v,
                    estimators,
                    items,
                    s.depth if exact else depth,
                    k,
                    EXACT if exact else noise,
                    cam,
                    args,
                    icp if (v == "median" and o3d is not None and args.icp) else None,
                    o3d,
                )
            print(f"  image {i + 1}/{args.count} ({kind}, {cam}): {len(items)} parts", flush=True)
    finally:
        renderer.close()
    seconds = {v: [t for (w, _), p in pipes.items() if w == v for t in p.seconds] for v in variants}
    return tallies, seconds, icp


def count_instances(
    tally: Tally,
    pipes,
    variant: str,
    estimators,
    items,
    depth,
    k,
    noise: DepthNoise,
    cam: str,
    args: argparse.Namespace,
    icp: dict[str, list[float]] | None,
    o3d: ModuleType | None,
) -> None:
    """Measure ``variant``'s cloud of each of ``items`` (detection, model name, true pose, whether
    its view is counted) on ``depth`` into ``tally``, and its pose; with ``icp``, refine the pose
    by open3d's ICP too."""
    for det, name, true, shown in items:
        pipe = pipes[variant, name]
        model = estimators[name].model
        cloud = pipe.cloud(det, depth, k, depth_noise=noise)
        poses = tally.poses[cam]
        if shown and not args.no_pose:
            poses.views += 1
            poses.by_class[model.object_class][0] += 1
        if not cloud.ok:
            tally.failed += 1
            continue
        d = surface_distances(model, cloud.points, true)
        tally.rms[cam].append(float(np.sqrt(np.mean(d * d))) * 1000)
        tally.p90[cam].append(float(np.percentile(d, 90)) * 1000)
        tally.allowance[cam].append(noise.allowance(float(np.median(cloud.points[:, 2]))) * 1000)
        tally.off[cam][0] += int((d > OFF_M).sum())
        tally.off[cam][1] += len(d)
        tally.points[cam].append(len(d))
        if args.no_pose or not shown:
            continue
        (obs,) = pipe.observe([det], depth, k, depth_noise=noise)
        e = obs.estimate
        if e is None:
            continue
        err = add_s(model, e.rotation, e.translation, true[:3, :3], true[:3, 3])
        right = err < ADD_S_FRACTION * model.diameter
        poses.right += right
        poses.add_s_mm.append(err * 1000)
        if e.certified:
            poses.certified += 1
            poses.certified_right += right
            poses.by_class[model.object_class][1] += 1
        if icp is not None:
            icp["before_mm"].append(err * 1000)
            icp["before_right"].append(float(right))
            for kind in ICP_KINDS:
                t0 = time.perf_counter()
                r, t = icp_refined(o3d, model, cloud.points, e.rotation, e.translation, kind)
                icp[f"{kind}_seconds"].append(time.perf_counter() - t0)
                after = add_s(model, r, t, true[:3, :3], true[:3, 3])
                icp[f"{kind}_mm"].append(after * 1000)
                icp[f"{kind}_right"].append(float(after < ADD_S_FRACTION * model.diameter))


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def report(
    tallies: dict[str, Tally],
    seconds: dict[str, list[float]],
    icp: dict[str, list[float]],
    o3d: ModuleType | None,
    pose: bool,
) -> None:
    base = tallies["median"]
    print(
        "\nclouds against the true surface (per camera; medians over clouds; ratio: RMS over the "
        "median filter's)"
    )
    print(
        f"  {'way':11s} {'camera':6s} {'clouds':>6s} {'points':>6s} {'RMS mm':>7s} {'ratio':>6s} "
        f"{'p90 mm':>7s} {'allowed':>7s} {'>5 mm':>7s} {'ms/cloud':>8s}"
    )
    for v, t in tallies.items():
        ms = _median(seconds[v]) * 1000
        for cam in sorted(t.rms):
            rms, ref = _median(t.rms[cam]), _median(base.rms[cam])
            off, total = t.off[cam]
            print(
                f"  {v:11s} {cam:6s} {len(t.rms[cam]):6d} {_median(t.points[cam]):6.0f} {rms:7.2f} "
                f"{rms / ref:6.2f} {_median(t.p90[cam]):7.2f} {_median(t.allowance[cam]):7.2f} "
                f"{off / max(total, 1) * 100:6.2f}% {ms:8.2f}"
            )
        if t.failed:
            print(f"  {v:11s} {t.failed} clouds refused (too few points)")
    print(
        "  (p90: the clouds' 90th percentile distance; allowed: what the certificate allows for the "
        "noise left)"
    )
    if pose:
        print(
            "\nposes by the node's pipeline, of the views whose exact cloud shows enough of the part "
            "at its true pose (a way's cloud that is refused or too small counts as wrong)"
        )
        for cam in sorted({cam for t in tallies.values() for cam in t.poses}):
            for v, t in tallies.items():
                p = t.poses[cam]
                n, c = p.views, p.certified
                classes = ", ".join(f"{cls} {b}/{a}" for cls, (a, b) in sorted(p.by_class.items()))
                print(
                    f"  {v:11s} {cam:5s} views {n:4d}: certified {c / max(n, 1) * 100:5.1f} %, of them "
                    f"within 2 % ADD-S {p.certified_right / max(c, 1) * 100:5.1f} %; all within 2 % "
                    f"{p.right / max(n, 1) * 100:5.1f} %, median ADD-S {_median(p.add_s_mm):.2f} mm of "
                    f"{len(p.add_s_mm)} posed (certified by class: {classes})"
                )
    if icp:
        before = np.array(icp["before_mm"])
        print(
            f"\nopen3d ICP after the median cloud's poses ({len(before)} views; Tukey k "
            f"{ICP_TUKEY_M * 1000:.0f} mm, pairs within {ICP_MAX_M * 1000:.0f} mm): median ADD-S "
            f"{_median(icp['before_mm']):.2f} mm, within 2 % {np.mean(icp['before_right']) * 100:.1f} % "
            "before"
        )
        for kind, title in ICP_KINDS.items():
            after = np.array(icp[f"{kind}_mm"])
            print(
                f"  {title:28s} median ADD-S {_median(icp[f'{kind}_mm']):8.2f} mm, within 2 % "
                f"{np.mean(icp[f'{kind}_right']) * 100:5.1f} %, better by > 0.5 mm "
                f"{np.mean(after < before - 0.5) * 100:5.1f} %, worse by > 0.5 mm "
                f"{np.mean(after > before + 0.5) * 100:5.1f} %, "
                f"{_median(icp[f'{kind}_seconds']) * 1000:.1f} ms"
            )
    if o3d is None:
        print("\nopen3d is not installed: `pip install open3d` to measure its filters and ICP beside these")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--count", type=int, default=16, help="images to render")
    p.add_argument("--seed", type=int, default=930, help="render seed (training sets use 0-9)")
    p.add_argument("--mission", type=Path, default=ROOT / "missions/one_bay.yaml")
    p.add_argument("--config", type=Path, default=ROOT / "config/vision/node.yaml")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--icp", action="store_true", help="also refine the median cloud's poses by open3d's ICP")
    p.add_argument("--no-pose", action="store_true", help="measure the clouds only, pose none")
    args = p.parse_args(argv)
    if args.count < 1:
        p.error(f"--count {args.count}: at least one image")
    torch.set_num_threads(args.threads)
    o3d = open3d_or_none()
    print(
        f"rendering {args.count} held-out images (seed {args.seed}) through the twin's camera models; "
        f"open3d {o3d.__version__ if o3d else 'not installed'}",
        flush=True,
    )
    tallies, seconds, icp = measure(args, o3d)
    report(tallies, seconds, icp, o3d, not args.no_pose)
    return 0


if __name__ == "__main__":
    sys.exit(main())
