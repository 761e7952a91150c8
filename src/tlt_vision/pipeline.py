"""From a camera frame to inspection observations: masks -> point clouds -> certified poses.

Reads detections (an instance mask and class per segmented instance, from Mask R-CNN or, for
checks on the twin, its ground-truth segmentation), the depth image, optional RGB and the camera
intrinsics; returns one :class:`~tlt_vision.inspection.Observation` per instance with a C-3PO
estimate, or the reason there is none (empty mask, no depth, too few points, no pose model for the
class). It never raises on image content.

The twin (and a segmentation model trained on it) labels each side of a cross frame as its own
instance, while the cross-frame CAD model is the whole square: instances of the classes in
``merge`` are joined into one before the pose is estimated (one part is inspected at a time).

Pieces of a cloud that nothing joins to the rest and that hold few of its points are dropped
before the pose is estimated (``detached``, :func:`tlt_vision.pointcloud.detached_pieces`): a
learned mask's stray pixels on what lies behind the part, and for compact parts every piece but the
largest (a neighbour of the same kind the mask took in). The classes in ``in_pieces`` keep
theirs: a cross frame's sides are pieces by design, its corner joints (another class) between
them, and a side half hidden is a small piece of it.

With ``axial_slide`` (node.yaml's is on for end fittings), a certified pose of its classes is
moved along its own axis to where its mask says the part ends (:mod:`tlt_vision.pose.axial_slide`):
seen from the side, the cloud leaves that open. Every certified pose is then checked against the
whole depth image (``free_space``, :mod:`tlt_vision.pose.free_space`): a pose that puts the model
where the camera saw past it is not certified. With ``parting`` (node.yaml's is on for end
fittings), a refused cloud of its classes that holds two pieces about two centres is posed again on
the larger one, taken only when certified and within its mask (:mod:`tlt_vision.pose.parting`): a
fitting's mask that took in its racked neighbour. A detection that carries a ``core`` (the pixels
of its mask the segmentation is surest of: Mask R-CNN's corner joints less what its semantic head
holds to be a frame side, :mod:`tlt_vision.segmentation.semantic_trim`) and whose pose is refused
has its core's cloud fitted from that pose (refined, :func:`~tlt_vision.pose.estimator.refined_together`),
and the fit taken on the same terms.

Given a real camera's depth noise (``depth_noise``; the twin's depth is exact), each cloud point
takes the median depth of its mask's pixels about it, and each certificate allows for the noise
left, or certifies nothing where the depth cannot place the part (:mod:`tlt_vision.depth_noise`).

A mask's border pixels are dropped (their depth may be what lies behind the part), except on a
mask smaller than ``keep_border_below`` pixels: on a small corner joint (100-300 pixels at a metre)
the border is most of the mask, and without it the cube's corners go unseen, so a good joint read
as a degenerate view, a missing joint. There a border pixel is kept only when its depth lies within
``BORDER_DEPTH_MARGIN`` of the depths the mask's interior spans (a few of a joint's border pixels
read the floor a metre behind it).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import cv2
import numpy as np

from tlt_vision.depth_noise import EXACT, DepthNoise
from tlt_vision.detections import Detection, merge_instances
from tlt_vision.inspection import Observation
from tlt_vision.pointcloud import (
    DEFAULT_DETACHED,
    MIN_POINTS,
    Detached,
    MaskedCloud,
    PinholeIntrinsics,
    detached_pieces,
    masked_point_cloud,
)
from tlt_vision.pose.axial_ends import AxialEnds, placed_along_axis
from tlt_vision.pose.axial_slide import AxialSlide, slid_along_axis
from tlt_vision.pose.certificate import Certificate
from tlt_vision.pose.estimator import PoseEstimate, PoseEstimator, estimate_together, refined_together
from tlt_vision.pose.free_space import DEFAULT as DEFAULT_FREE_SPACE
from tlt_vision.pose.free_space import FreeSpace, checked, nearest_depth
from tlt_vision.pose.parting import Parting, larger_piece, visible_share_in_mask
from tlt_vision.pose.precision import model_motion_matrix, pose_precision

BORDER_DEPTH_MARGIN = 0.01  # m


def border_kept(mask: np.ndarray, depth: np.ndarray | None) -> np.ndarray:
    """``mask`` without the border pixels whose depth is outside its interior's depth span."""
    sel = np.asarray(mask, dtype=bool)
    if depth is None or np.asarray(depth).shape != sel.shape:
        return sel
    core = cv2.erode(sel.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    with np.errstate(invalid="ignore"):
        inner = depth[core & np.isfinite(depth) & (depth > 0)]
        if inner.size == 0:
            return core
        near, far = float(inner.min()) - BORDER_DEPTH_MARGIN, float(inner.max()) + BORDER_DEPTH_MARGIN
        return core | (sel & (depth >= near) & (depth <= far))


class PartPipeline:
    """Poses for the detections of one frame, with one estimator per object class."""

    def __init__(
        self,
        estimators: Mapping[str, PoseEstimator],
        max_points: int = 1024,
        min_points: int = MIN_POINTS,
        merge: Sequence[str] = ("cross_frame",),
        in_pieces: Sequence[str] = ("cross_frame",),
        keep_border_below: int = 0,
        free_space: FreeSpace | None = DEFAULT_FREE_SPACE,
        detached: Detached | None = DEFAULT_DETACHED,
        axial_slide: AxialSlide | None = None,
        axial_ends: AxialEnds | None = None,
        depth_noise: DepthNoise = EXACT,
        parting: Parting | None = None,
    ) -> None:
        self.estimators = dict(estimators)
        self.parting = parting
        self.depth_noise = depth_noise
        self.free_space = free_space
        self.detached = detached
        self.axial_slide = axial_slide
        self.axial_ends = axial_ends
        self._surfaces: dict[str, np.ndarray] = {}
        self._motions: dict[str, np.ndarray] = {}
        self._slide_surfaces: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.keep_border_below = keep_border_below
        self.max_points = max_points
        self.min_points = min_points
        self.merge = tuple(merge)
        self.in_pieces = tuple(in_pieces)

    def cloud(
        self,
        detection: Detection,
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> MaskedCloud:
        """The point cloud C-3PO is given for one detection (its reason when there is none), the
        depth's noise ``depth_noise`` (by default the pipeline's) filtered out; a mask of more
        than ``max_points`` pixels gives that many, evenly spaced over it
        (:func:`~tlt_vision.pointcloud.masked_point_cloud`)."""
        noise = depth_noise or self.depth_noise
        small = np.count_nonzero(detection.mask) < self.keep_border_below
        estimator = self.estimators.get(detection.object_class)
        cloud = masked_point_cloud(
            border_kept(detection.mask, depth) if small else detection.mask,
            depth,
            intrinsics,
            rgb,
            self.min_points,
            max_points=self.max_points,
            erode=0 if small else 1,
            extent=estimator.model.diameter if estimator is not None else None,
            smooth=0 if noise.exact else noise.window,
        )
        if not cloud.ok or self.detached is None or detection.object_class in self.in_pieces:
            return cloud
        keep = ~detached_pieces(cloud.points, self.detached, detection.object_class)
        if keep.all():
            return cloud
        if keep.sum() < self.min_points:
            return MaskedCloud(
                cloud.points[:0],
                None,
                cloud.mask_pixels,
                f"too few points: {int(keep.sum())} joined to the part < {self.min_points}",
            )
        colours = cloud.colours[keep] if cloud.colours is not None else None
        return MaskedCloud(cloud.points[keep], colours, cloud.mask_pixels)

    def observe(
        self,
        detections: Sequence[Detection],
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None = None,
        prior: Callable[[str, np.ndarray], np.ndarray | None] | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> list[Observation]:
        """Poses of ``detections``; ``prior(object_class, points)``, when given, says where a piece
        with those points (camera frame) is expected (4x4, camera frame) or None
        (:meth:`PoseEstimator.estimate_batch`). Every class's clouds are posed together
        (:func:`~tlt_vision.pose.estimator.estimate_together`). ``depth_noise`` is the camera's,
        by default the pipeline's."""
        noise = depth_noise or self.depth_noise
        dets = merge_instances(detections, self.merge)
        out: list[Observation | None] = [None] * len(dets)
        again = self.parting is not None and depth is not None
        pending: dict[str, list[tuple[int, np.ndarray]]] = {}
        for i, d in enumerate(dets):
            cloud = self.cloud(d, depth, intrinsics, rgb, noise)
            if not cloud.ok:
                out[i] = Observation(d.object_class, None, cloud.reason, d.object_id)
            elif d.object_class not in self.estimators:
                out[i] = Observation(
                    d.object_class, None, f"no pose model for class {d.object_class}", d.object_id
                )
            else:
                pending.setdefault(d.object_class, []).append((i, cloud.points))
        jobs = []
        for cls, items in pending.items():
            clouds = [p for _, p in items]
            priors = None if prior is None else [prior(cls, p) for p in clouds]
            jobs.append((self.estimators[cls], clouds, priors))
        near = None
        if pending and self.free_space is not None and depth is not None:
            near = nearest_depth(depth, self.free_space.window)
        parted = self.parting.classes if again else ()
        refused: dict[str, list[tuple[int, np.ndarray]]] = {}
        for (cls, items), estimates in zip(pending.items(), estimate_together(jobs), strict=True):
            for (i, points), e in zip(items, estimates, strict=True):
                e = self._judged(e, points, dets[i].mask, depth, intrinsics, noise, near)
                out[i] = Observation(cls, e, "", dets[i].object_id)
                if cls in parted and not e.certified:
                    refused.setdefault(cls, []).append((i, points))
        if again:
            estimates = [o.estimate for o in out]
            cored = [
                i
                for i, e in enumerate(estimates)
                if dets[i].core is not None and e is not None and not e.certified
            ]
            for i, e in self._cored(cored, estimates, dets, depth, intrinsics, rgb, noise, near):
                out[i] = replace(out[i], estimate=e)
        refused = {
            cls: [(i, p) for i, p in items if not out[i].estimate.certified] for cls, items in refused.items()
        }
        if any(refused.values()):
            for i, e in self._parted(refused, dets, depth, intrinsics, noise, near):
                out[i] = replace(out[i], estimate=e)
        return [o for o in out if o is not None]

    def _judged(
        self,
        estimate: PoseEstimate,
        points: np.ndarray,
        mask: np.ndarray,
        depth: np.ndarray | None,
        intrinsics: PinholeIntrinsics,
        noise: DepthNoise,
        near: np.ndarray | None,
    ) -> PoseEstimate:
        """``estimate`` of ``points`` as the pipeline reports it: certified again allowing for the
        depth's noise, slid along its axis by its mask, checked against the free space seen."""
        cls = estimate.object_class
        if not noise.exact:
            certificate = self._certificate(cls, points, estimate.rotation, estimate.translation, noise)
            estimate = replace(estimate, certificate=certificate)
        if depth is not None:
            slid = self._slid(estimate, points, mask, depth, intrinsics, noise)
            estimate = self._placed_along_axis(
                [slid, estimate] if slid is not estimate else [slid], points, depth, intrinsics, noise
            )
        if near is not None:
            estimate = checked(estimate, near, intrinsics, self._surface(cls), self.free_space)
        return estimate

    def _parted(
        self,
        refused: Mapping[str, list[tuple[int, np.ndarray]]],
        dets: Sequence[Detection],
        depth: np.ndarray,
        intrinsics: PinholeIntrinsics,
        noise: DepthNoise,
        near: np.ndarray | None,
    ) -> list[tuple[int, PoseEstimate]]:
        """For the refused clouds of the parting's classes, ``(index, estimate)`` of those whose
        larger piece is certified and lies within its mask (:mod:`tlt_vision.pose.parting`); every
        piece of the frame posed in one batch."""
        parting = self.parting
        pieces: dict[str, list[tuple[int, np.ndarray]]] = {}
        for cls, items in refused.items():
            separation = parting.min_separation * self.estimators[cls].model.diameter
            for i, points in items:
                keep = larger_piece(points, parting.min_share, separation)
                if keep is not None and keep.sum() >= self.min_points:
                    pieces.setdefault(cls, []).append((i, points[keep]))
        if not pieces:
            return []
        jobs = [(self.estimators[cls], [p for _, p in items], None) for cls, items in pieces.items()]
        posed = estimate_together(jobs)
        return self._taken(
            [x for items in pieces.values() for x in items],
            [e for es in posed for e in es],
            dets,
            depth,
            intrinsics,
            noise,
            near,
        )

    def _cored(
        self,
        refused: Sequence[int],
        estimates: Sequence[PoseEstimate | None],
        dets: Sequence[Detection],
        depth: np.ndarray,
        intrinsics: PinholeIntrinsics,
        rgb: np.ndarray | None,
        noise: DepthNoise,
        near: np.ndarray | None,
    ) -> list[tuple[int, PoseEstimate]]:
        """For the ``refused`` detections (indices) that carry a core, ``(index, estimate)`` of
        those whose core's cloud, refined from the whole mask's pose, is certified and lies within
        the whole mask; every core of the frame refined in one batch. Refined, not posed afresh:
        keypoints and a corrector's run of their own for the few refused joints would add a large
        share to the cost of a frame's poses."""
        items, clouds = [], []
        for i in refused:
            d = dets[i]
            cloud = self.cloud(replace(d, mask=d.core), depth, intrinsics, rgb, noise)
            if cloud.ok:
                e = estimates[i]
                items.append((self.estimators[d.object_class], cloud.points, e.rotation, e.translation))
                clouds.append((i, cloud.points))
        return self._taken(clouds, refined_together(items), dets, depth, intrinsics, noise, near)

    def _taken(
        self,
        clouds: Sequence[tuple[int, np.ndarray]],
        estimates: Sequence[PoseEstimate],
        dets: Sequence[Detection],
        depth: np.ndarray,
        intrinsics: PinholeIntrinsics,
        noise: DepthNoise,
        near: np.ndarray | None,
    ) -> list[tuple[int, PoseEstimate]]:
        """Of the ``estimates`` of parts of refused detections' clouds (``(index, points)``: a
        parted piece, a core's cloud), each judged as any, ``(index, estimate)`` of those taken:
        certified, and the posed model's visible surface within the detection's whole mask on the
        parting's terms."""
        parting = self.parting
        taken = []
        for (i, points), estimate in zip(clouds, estimates, strict=True):
            e = self._judged(estimate, points, dets[i].mask, depth, intrinsics, noise, near)
            if not e.certified:
                continue
            surface = self._surface(e.object_class) @ e.rotation.T + e.translation
            share = visible_share_in_mask(
                surface, dets[i].mask, depth, intrinsics, parting.mask_margin, parting.hidden_margin
            )
            if share >= parting.in_mask:
                taken.append((i, e))
        return taken

    def _slid(
        self,
        estimate: PoseEstimate,
        points: np.ndarray,
        mask: np.ndarray,
        depth: np.ndarray,
        intrinsics: PinholeIntrinsics,
        noise: DepthNoise,
    ) -> PoseEstimate:
        """``estimate`` placed along its axis by its mask, certified again where it moved (the
        Chamfer figures change a little, and the certificate says what they are now). A slide the
        cloud does not certify is not taken: a learned mask is not exact where it ends."""
        slide, cls = self.axial_slide, estimate.object_class
        if slide is None or cls not in slide.classes or not estimate.certified:
            return estimate
        if cls not in self._slide_surfaces:
            model = self.estimators[cls].model
            self._slide_surfaces[cls] = model.sample(slide.samples, np.random.default_rng(0))
        moved, by = slid_along_axis(
            estimate, points, mask, depth, intrinsics, self._slide_surfaces[cls], slide
        )
        if by == 0.0:
            return estimate
        certificate = self._certificate(cls, points, moved.rotation, moved.translation, noise)
        return replace(moved, certificate=certificate) if certificate.certified else estimate

    def _placed_along_axis(
        self,
        candidates: list[PoseEstimate],
        points: np.ndarray,
        depth: np.ndarray,
        intrinsics: PinholeIntrinsics,
        noise: DepthNoise,
    ) -> PoseEstimate:
        """The first of ``candidates`` (the pose slid by its mask, then as fitted) whose ends the
        depth shows where its axis leaves its place open, or, seen end-on, whose cloud holds an
        end face (:mod:`tlt_vision.pose.axial_ends`);
        when none, the first slid to where the depth shows an end and certified again on
        ``points``; when none either, the first, not certified: its place along its axis is not
        seen."""
        first = candidates[0]
        ends, cls = self.axial_ends, first.object_class
        if ends is None or cls not in ends.classes or not first.certified:
            return first
        dims = self.estimators[cls].model.dims
        margin = 2.0 * noise.allowance(float(first.translation[2])) if not noise.exact else 0.0
        return placed_along_axis(
            candidates,
            points,
            dims["radius"],
            dims["half_length"],
            depth,
            intrinsics,
            lambda rotation, translation: self._certificate(cls, points, rotation, translation, noise),
            ends,
            margin,
        )

    def _certificate(
        self,
        object_class: str,
        points: np.ndarray,
        rotation: np.ndarray,
        translation: np.ndarray,
        noise: DepthNoise,
    ) -> Certificate:
        """The certificate of a pose of ``object_class`` for ``points``, allowing for the depth's
        ``noise`` at their depth; not certified where the fit to so noisy a cloud cannot place the
        part to ``noise.max_allowance`` of its size (:mod:`tlt_vision.pose.precision`)."""
        estimator = self.estimators[object_class]
        if noise.exact:
            return estimator.certify_at(points, rotation, translation)
        depth = float(np.median(points[:, 2]))
        certificate = estimator.certify_at(points, rotation, translation, noise.allowance(depth))
        if not certificate.certified:
            return certificate
        model = estimator.model
        if object_class not in self._motions:
            self._motions[object_class] = model_motion_matrix(model)
        precision = pose_precision(
            model, self._motions[object_class], points, rotation, translation, noise, noise.frame_fx
        )
        bound = noise.max_allowance * model.diameter
        if noise.precision_sigmas * precision.add_s <= bound:
            return replace(certificate, precision=precision.add_s, rotation_precision=precision.rotation)
        reason = (
            f"depth too noisy to certify at {depth:.2f} m: the fit places the part to "
            f"{precision.add_s * 1000:.1f} mm (1 sigma, ADD-S), over {noise.max_allowance:.0%} of "
            f"its size ({bound * 1000:.1f} mm) at {noise.precision_sigmas:g} sigma"
        )
        return replace(
            certificate, certified=False, reason=reason, precision=precision.add_s, depth_limited=True
        )

    def _surface(self, object_class: str) -> np.ndarray:
        """A fixed surface sample of the class's model, of the free-space check's size."""
        if object_class not in self._surfaces:
            model = self.estimators[object_class].model
            samples = (self.free_space or DEFAULT_FREE_SPACE).samples  # the parting's without the check
            self._surfaces[object_class] = model.sample(samples, np.random.default_rng(0))[0]
        return self._surfaces[object_class]


__all__ = ["BORDER_DEPTH_MARGIN", "PartPipeline", "border_kept"]
