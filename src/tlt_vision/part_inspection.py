"""Inspection of one part presented to a camera: pick out its instances, pose them, decide.

:class:`PartInspector` holds the C-3PO estimators of the vision node's detectors
(``node.yaml`` ``detectors``) and one :class:`~tlt_vision.pipeline.PartPipeline` per part kind.
From one frame's detections (instance masks and classes, from the twin's labels or Mask R-CNN),
its depth image and intrinsics it answers the InspectPart decision for a strut or a cross frame
(:meth:`PartInspector.inspect`), and the instances and observations CheckAlignment needs. It needs
no ROS: the vision node's handlers (:mod:`tlt_vision.services`) wrap it in its services, and
tests run it on the twin's renders directly.

Which instances are the part (:func:`select_part`), among those in the working depth range: with a
``gap``, the instances are joined into parts, two instances being of one part when a chain of
instances links them with 3-D gaps of at most ``gap`` (a cross frame's sides meet at its corner
joints, a strut's fittings sit on its tube's ends); the part presented is the one with the most
pixels of its main class (a cross frame's sides, a strut's tube), kept to ``reach`` of its biggest
main instance. Other parts in view, however close in the image (the lifter's top cross frame below
a held one, the rest of a dispenser's stack behind it, a few pixels of a fitting in a rack beside a
held strut), stay out of it as long as they do not touch it. A strut is one tube: a group of
several (struts of the tower in view, joined at their joints) is not the strut presented, while
pieces of one tube (along one line, or end to end at a bend) count once. Without
a ``gap`` the biggest main instance is the anchor and every instance within ``reach`` of its
centre is taken.

Only detections scoring ``segmentation.min_score`` or more are the part. A strut that fails for a
missing end fitting gets a second look (``segmentation.second_look_score``): the end fitting
detections scoring between the two, and only those whose cloud lies where the certified tube puts
a missing fitting (within ``part_gap`` and the fitting's half size), are posed, and the strut is
decided again with those certified. If it still fails, and the caller can segment a region of
the frame again (``closer``: Mask R-CNN on a crop about each missing fitting's place, enlarged,
``segmentation.second_look_closer``), the end fittings found there are posed and counted the
same way. It passes if it now passes; otherwise the first decision stands, with the reasons of
what was seen with confidence. Mask R-CNN can score a held vertical's fitting beside the rivet gun
low, or miss it in the whole frame; lowering ``min_score`` for every detection instead would pose
every low-scored piece of every frame, at a cost in frame time. A
strut missing a fitting has none to certify at its place (its bare tube end, the fitting's length
away, may fit the fitting model but not there), so it still fails.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from tlt_common.mission.schema import Mission
from tlt_vision import inspection
from tlt_vision.cad.models import load_parts, models_for_mission
from tlt_vision.depth_noise import DepthNoise
from tlt_vision.detections import Detection, detections_near
from tlt_vision.node_config import VisionConfig
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pointcloud import PinholeIntrinsics, masked_point_cloud
from tlt_vision.pose.corrector import CorrectorConfig
from tlt_vision.pose.detector_weights import load_detector
from tlt_vision.pose.estimator import PoseEstimator
from tlt_vision.weights import WeightsError, read_manifest

STRUT_KINDS = ("vertical", "diagonal")
log = logging.getLogger("tlt.vision")
Region = tuple[int, int, int, int]  # x0, y0, x1, y1: pixels, x1 and y1 past the last
# Segments one region of the frame again, enlarged, into detections with full-frame masks.
LookCloser = Callable[[Region], list[Detection]]
# Points per instance used to measure how far apart two instances are (a subsample: the gaps
# looked for are centimetres, the masks thousands of pixels).
_GAP_POINTS = 400


def load_estimators(config: VisionConfig, mission: Mission) -> dict[str, PoseEstimator]:
    """One estimator per ``detectors`` entry; WeightsError names a file that is missing or wrong."""
    models = models_for_mission(mission)
    thresholds = mission.inspection["chamfer_thresholds"]
    settings = dict(config.raw["corrector"])
    turned = set(settings.pop("turned_starts"))
    tilted = settings.pop("tilted_starts")
    trim = settings.pop("trim")
    corrector = CorrectorConfig(**settings)
    out = {}
    for name in config.raw["detectors"]:
        path = config.detector_path(name)
        manifest = read_manifest(path)
        width = manifest["settings"].get("width")
        if not isinstance(width, int):
            raise WeightsError(path, "manifest settings lack the detector width")
        model = models[name]
        out[name] = PoseEstimator(
            model,
            load_detector(path, model, width),
            thresholds[model.object_class],
            corrector,
            turned_starts=model.object_class in turned,
            tilted_deg=tilted["angle_deg"] if model.object_class in tilted["classes"] else 0.0,
            trim=trim["fraction"] if model.object_class in trim["classes"] else 0.0,
        )
    return out


@dataclass(frozen=True, eq=False)
class _Instance:
    detection: Detection
    centre: np.ndarray  # (3,) camera frame, m
    points: np.ndarray  # (n, 3) subsample, camera frame, m


def _instance(d: Detection, depth: np.ndarray, k: PinholeIntrinsics) -> _Instance | None:
    with np.errstate(invalid="ignore"):
        valid = d.mask & np.isfinite(depth) & (depth > 0)
    if not valid.any():
        return None
    v, u = np.nonzero(valid)
    z = depth[v, u].astype(float)
    zc = float(np.median(z))
    centre = np.array([(np.median(u) - k.cx) * zc / k.fx, (np.median(v) - k.cy) * zc / k.fy, zc])
    # Off the mask's border: a border pixel where one part occludes another may carry the
    # front part's depth and would join the two (a tiny instance keeps its border pixels).
    cloud = masked_point_cloud(d.mask, depth, k, min_points=1, max_points=_GAP_POINTS)
    if not cloud.ok:
        cloud = masked_point_cloud(d.mask, depth, k, min_points=1, max_points=_GAP_POINTS, erode=0)
    if not cloud.ok:
        return None
    return _Instance(d, centre, cloud.points.astype(float))


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest distance between two point sets (m)."""
    return float(np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1).min()))


def select_part(
    detections: Sequence[Detection],
    depth: np.ndarray | None,
    intrinsics: PinholeIntrinsics,
    classes: Sequence[str],
    anchor: str,
    reach: float,
    depth_range: Sequence[float],
    min_pixels: int,
    gap: float | None = None,
    anchors_per_part: int | None = None,
) -> list[Detection]:
    """The instances of one part (see the module docstring); empty when no anchor instance of at
    least ``min_pixels`` pixels lies in ``depth_range``: the part is not in view. With
    ``anchors_per_part`` (a strut: one tube), groups with more anchors than a part has are
    structure in view, passed over while a group that could be the part remains."""
    if depth is None:
        return []
    near, far = depth_range
    found = []
    for d in detections:
        if d.object_class not in classes:
            continue
        inst = _instance(d, depth, intrinsics)
        if inst is not None and near <= inst.centre[2] <= far:
            found.append(inst)
    anchors = [i for i in found if i.detection.object_class == anchor and _pixels(i) >= min_pixels]
    if not anchors:
        return []
    if gap is None:
        first = max(anchors, key=_pixels)
        return [i.detection for i in found if np.linalg.norm(i.centre - first.centre) <= reach]
    # Parts as groups of instances joined within ``gap``; the part presented is the group with
    # the most pixels of the anchor class (a held frame, not the bigger side of one behind it).
    groups = [g for g in _joined(found, gap) if any(i in anchors for i in g)]
    if anchors_per_part is not None:
        # A held strut before a lifted bay: the bay's near vertical, riveted to its diagonal,
        # can show more tube than the strut and would be inspected in its place.
        parts = [g for g in groups if len(_lines(g, anchor)) <= anchors_per_part]
        groups = parts or groups
    best = max(groups, key=lambda g: sum(_pixels(i) for i in g if i.detection.object_class == anchor))
    first = max((i for i in best if i in anchors), key=_pixels)
    centre = first.centre
    if anchors_per_part is not None:  # from the middle of all the pieces of the anchor
        line = next(line for line in _lines(best, anchor) if any(i is first for i in line))
        if len(line) > 1:
            centre = np.vstack([i.points for i in line]).mean(axis=0)
    return [i.detection for i in best if np.linalg.norm(i.centre - centre) <= reach]


# Points of one straight tube lie within its radius (12.5 mm) of the line through its cloud.
_ONE_LINE = 0.02  # m, 95th percentile of the points' distances from that line
# A bent tube's two halves meet at its bend (the twin bends them 3-12 deg); a lifted bay's vertical
# and diagonal meet at 45 deg.
_BEND = np.radians(20.0)


def _lines(group: list[_Instance], anchor: str) -> list[list[_Instance]]:
    """The ``anchor`` instances of ``group``, those of one tube together: along one straight line
    (Mask R-CNN split a held diagonal's tube into two detections) or end to end at a bend (a bent
    tube split there). A lifted bay's vertical and diagonal, riveted end to end, are two."""
    lines: list[list[_Instance]] = []
    for inst in (i for i in group if i.detection.object_class == anchor):
        along = (line for line in lines if _one_tube(np.vstack([i.points for i in line]), inst.points))
        line = next(along, None)
        if line is None:
            lines.append([inst])
        else:
            line.append(inst)
    return lines


def _one_tube(a: np.ndarray, b: np.ndarray) -> bool:
    if _straightness(np.vstack([a, b]))[1] <= _ONE_LINE:
        return True
    (ua, off_a), (ub, off_b) = _straightness(a), _straightness(b)
    if max(off_a, off_b) > _ONE_LINE or math.acos(min(1.0, abs(float(ua @ ub)))) > _BEND:
        return False
    # End to end, not side by side: along their common direction they barely overlap.
    u = ua if float(ua @ ub) >= 0 else -ua
    u = (u + ub) / np.linalg.norm(u + ub)
    pa, pb = a @ u, b @ u
    return min(pa.max(), pb.max()) - max(pa.min(), pb.min()) <= _ONE_LINE


def _straightness(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The direction of the line through ``points`` and the 95th percentile of their distances
    from it (m)."""
    centred = points - points.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    off = np.linalg.norm(centred - np.outer(centred @ axis, axis), axis=1)
    return axis, float(np.percentile(off, 95))


def _pixels(i: _Instance) -> int:
    return int(i.detection.mask.sum())


def _joined(instances: list[_Instance], gap: float) -> list[list[_Instance]]:
    """Groups of instances linked by chains of gaps of at most ``gap`` (m)."""
    parent = list(range(len(instances)))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    # Two instances whose bounding boxes are further apart than ``gap`` cannot be joined: most
    # pairs in a frame are, and the point-to-point gap is the costly part (50 instances a frame).
    lo = [i.points.min(0) for i in instances]
    hi = [i.points.max(0) for i in instances]
    for a in range(len(instances)):
        for b in range(a + 1, len(instances)):
            apart = np.linalg.norm(np.maximum(0.0, np.maximum(lo[a] - hi[b], lo[b] - hi[a])))
            if apart > gap or root(a) == root(b):
                continue
            if _gap(instances[a].points, instances[b].points) <= gap:
                parent[root(a)] = root(b)
    groups: dict[int, list[_Instance]] = {}
    for k, inst in enumerate(instances):
        groups.setdefault(root(k), []).append(inst)
    return list(groups.values())


class PartInspector:
    """The estimators and pipelines of part inspection and the choices of which instances are the
    part; thread-safe (one pipeline's random draws are not shared by threads)."""

    def __init__(
        self,
        config: VisionConfig,
        mission: Mission,
        estimators: dict[str, PoseEstimator] | None = None,
    ) -> None:
        self.config = config
        self.mission = mission
        seg = config.raw["segmentation"]
        self.min_score: float = seg["min_score"]
        self.second_look_score: float | None = seg["second_look_score"]
        closer = seg["second_look_closer"]
        self.closer_size: float | None = closer["size"] if closer else None
        self.parts = load_parts()
        self.tol = inspection.Tolerances.from_mission(mission)
        self.estimators = estimators if estimators is not None else load_estimators(config, mission)
        e = self.estimators
        opts = config.pipeline_options
        # A strut has one tube: Mask R-CNN's two detections of one long tube, each too little of it
        # to pose, are one cloud (a bent tube's two halves then fail the straight tube's fit).
        self.pipelines = {
            kind: PartPipeline(
                {"strut_tube": e[f"strut_tube/{kind}"], "end_fitting": e["end_fitting"]},
                merge=("strut_tube",),
                **opts,
            )
            for kind in STRUT_KINDS
        }
        self.pipelines["cross_frame"] = PartPipeline(
            {"cross_frame": e["cross_frame"], "corner_joint": e["corner_joint"]}, **opts
        )
        self.pipelines["bay"] = PartPipeline({"corner_joint": e["corner_joint"]}, **opts)
        self.pipelines["rivet"] = PartPipeline({"rivet": e["rivet"]}, **opts)
        self._locks = {k: threading.Lock() for k in self.pipelines}

    def observe(
        self,
        pipeline: str,
        detections: Sequence[Detection],
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None = None,
        prior: Callable[[str, np.ndarray], np.ndarray | None] | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> list[inspection.Observation]:
        """The observations of ``pipeline`` (a part kind, "bay" or "rivet") for ``detections``;
        ``depth_noise``, the camera's, by default node.yaml's for cameras it does not name."""
        with self._locks[pipeline]:
            return self.pipelines[pipeline].observe(detections, depth, intrinsics, rgb, prior, depth_noise)

    def select(
        self,
        kind: str,
        detections: Sequence[Detection],
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
    ) -> list[Detection]:
        """The instances of the ``kind`` part (vertical, diagonal, cross_frame) presented."""
        raw = self.config.raw
        shape = depth.shape if depth is not None else next((d.mask.shape for d in detections), (0, 0))
        min_pixels = max(1, round(raw["min_part_area"] * shape[0] * shape[1]))
        common = {"depth_range": raw["part_depth_range"], "min_pixels": min_pixels}
        if kind == "cross_frame":
            return select_part(
                detections,
                depth,
                intrinsics,
                ("cross_frame", "corner_joint"),
                "cross_frame",
                self.mission.bay_width * 1.2,
                gap=raw["part_gap"],
                **common,
            )
        length = self.mission.strut_lengths[kind]
        return select_part(
            detections,
            depth,
            intrinsics,
            ("strut_tube", "end_fitting"),
            "strut_tube",
            length / 2 + 0.1,
            # Not only within reach: a few pixels of a racked strut's fitting near a held one's
            # tube would count as a third fitting, which cannot be measured, and fail good struts.
            gap=raw["part_gap"],
            anchors_per_part=1,
            **common,
        )

    def inspect(
        self,
        member_id: str,
        kind: str,
        detections: Sequence[Detection],
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None = None,
        closer: LookCloser | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> tuple[inspection.InspectionReport, list[inspection.Observation]]:
        """InspectPart's decision for a strut (vertical, diagonal) or a cross frame in one frame;
        ``detections`` may hold those scoring under ``min_score`` for the second look, and
        ``closer`` segments a region of the frame again, enlarged (the module docstring);
        ``depth_noise`` is the camera's (:meth:`observe`)."""
        confident = [d for d in detections if d.score >= self.min_score]
        part = self.select(kind, confident, depth, intrinsics)
        obs = self.observe(kind, part, depth, intrinsics, rgb, depth_noise=depth_noise)
        if kind == "cross_frame":
            report = inspection.inspect_cross_frame(member_id, self.mission.bay_width, obs, self.tol)
            return report, obs
        length = self.mission.strut_lengths[kind]
        report = inspection.inspect_strut(member_id, kind, length, obs, self.parts, self.tol)
        floor = self.second_look_score
        places = (
            inspection.missing_fitting_places(length, obs, self.parts, self.tol)
            if not report.passed and floor is not None
            else np.zeros((0, 3))
        )
        if not len(places):
            return report, obs
        doubtful = [d for d in detections if floor <= d.score < self.min_score]
        looks: list[tuple[str, Callable[[], list[Detection]]]] = [
            (f"scored {floor} to {self.min_score}", lambda: doubtful)
        ]
        if closer is not None and self.closer_size is not None:
            regions = [self._region(p, intrinsics, depth) for p in places]
            looks.append(("in a closer look", lambda: [d for r in regions for d in closer(r)]))
        seen: list[inspection.Observation] = []
        for how, look in looks:
            seen += self._fittings_at(kind, places, look(), depth, intrinsics, rgb, depth_noise)
            again = inspection.inspect_strut(member_id, kind, length, [*obs, *seen], self.parts, self.tol)
            # Only to pass a good strut: a failure keeps the reasons of what was seen with confidence.
            if seen and again.passed:
                # The report has no field for it; an engineer reading the node's log should know.
                log.info("%s passed on a second look: %d end fitting(s) %s", member_id, len(seen), how)
                return again, [*obs, *seen]
        return report, obs

    def _fittings_at(
        self,
        kind: str,
        places: np.ndarray,
        candidates: Sequence[Detection],
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None,
        depth_noise: DepthNoise | None,
    ) -> list[inspection.Observation]:
        """Certified end fittings among ``candidates`` whose clouds lie at one of ``places``
        (within ``part_gap`` and the fitting's half size)."""
        floor = self.second_look_score or 0.0
        fittings = [d for d in candidates if d.object_class == "end_fitting" and d.score >= floor]
        radius = self.config.raw["part_gap"] + self.estimators["end_fitting"].model.diameter / 2
        near = detections_near(fittings, depth, intrinsics, np.eye(4), places, radius)
        seen = self.observe(kind, near, depth, intrinsics, rgb, depth_noise=depth_noise) if near else []
        return [o for o in seen if o.estimate is not None and o.estimate.certified]

    def _region(self, place: np.ndarray, intrinsics: PinholeIntrinsics, depth: np.ndarray | None) -> Region:
        """The pixel box (x0, y0, x1, y1) about ``place`` (camera frame), ``closer_size`` (m)
        wide at its depth and of the frame's shape (the model was trained on whole frames), within
        the frame."""
        h, w = depth.shape if depth is not None else (0, 0)
        u = intrinsics.fx * place[0] / place[2] + intrinsics.cx
        v = intrinsics.fy * place[1] / place[2] + intrinsics.cy
        hu = intrinsics.fx * self.closer_size / place[2] / 2
        hv = hu * h / max(w, 1)
        x0, y0 = int(max(0, u - hu)), int(max(0, v - hv))
        return x0, y0, int(min(w, np.ceil(u + hu))), int(min(h, np.ceil(v + hv)))


__all__ = ["STRUT_KINDS", "LookCloser", "PartInspector", "Region", "load_estimators", "select_part"]
