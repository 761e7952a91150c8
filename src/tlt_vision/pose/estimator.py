"""C-3PO pose estimation: detect keypoints, correct them, register, certify.

:class:`PoseEstimator` (one part model) reads an observed cloud (N, 3) in the camera frame and
returns a :class:`PoseEstimate`: rotation, translation, corrected keypoints and the certificate.
:func:`estimate_together` poses the clouds of several models in one batch. Neither raises on bad
input: too few points give an uncertified estimate whose reason says so, and an uncertified
estimate is always marked ``certified=False`` whatever its pose looks like.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from tlt_common.geometry.transforms import rotation_to_quaternion
from tlt_vision.cad.models import CadModel
from tlt_vision.cad.surface import SurfaceDistance
from tlt_vision.ops.registration import transform
from tlt_vision.pose.certificate import Certificate, certify, not_certified
from tlt_vision.pose.corrector import CorrectorConfig, chamfer_objective, correct, model_frame, refine_pose
from tlt_vision.pose.detector import KeypointDetector

MIN_POINTS = 16
# A quarter turn about the model frame's x axis and one about its y axis (model z -> -y, z -> x).
_QUARTER_TURNS = (
    np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
)


def tilted_turns(angle_deg: float) -> list[np.ndarray]:
    """Rotations by ``angle_deg`` either way about each model axis (x, y, z), six in all."""
    turns = []
    for axis in range(3):
        i, j = [k for k in range(3) if k != axis]
        for angle in (np.radians(angle_deg), -np.radians(angle_deg)):
            c, s = np.cos(angle), np.sin(angle)
            turn = np.eye(3)
            turn[i, i], turn[i, j], turn[j, i], turn[j, j] = c, -s, s, c
            turns.append(turn)
    return turns


def padded_batch(clouds: Sequence[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
    """Clouds of different sizes as one zero-padded batch (B, N, 3) and the mask (B, N) of their
    real points."""
    n = max(len(c) for c in clouds)
    obs = torch.zeros(len(clouds), n, 3)
    mask = torch.zeros(len(clouds), n, dtype=torch.bool)
    for j, c in enumerate(clouds):
        obs[j, : len(c)] = torch.from_numpy(np.asarray(c, dtype=np.float32))
        mask[j, : len(c)] = True
    return obs, mask


@dataclass(frozen=True)
class PoseEstimate:
    """A part's pose in the camera frame with its certificate (maps onto CertifiedPose)."""

    object_class: str
    model_name: str
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    keypoints: np.ndarray  # (K, 3) corrected, camera frame
    certificate: Certificate
    num_points: int
    objective: float  # fit objective after correction and refinement (trimmed where trimmed), m^2

    @property
    def certified(self) -> bool:
        return self.certificate.certified

    def certified_pose_fields(self, object_id: str = "") -> dict:
        """The fields of tlt_interfaces/msg/CertifiedPose (without the header)."""
        qx, qy, qz, qw = rotation_to_quaternion(self.rotation)
        c = self.certificate
        return {
            "object_class": self.object_class,
            "object_id": object_id,
            "position": tuple(float(v) for v in self.translation),
            "orientation": (qx, qy, qz, qw),
            "certified": bool(c.certified),
            "chamfer_p90": float(c.chamfer_p90),
            "chamfer_threshold": float(c.chamfer_threshold),
            "keypoint_groups_visible": int(c.keypoint_groups_visible),
            "keypoint_groups_required": int(c.keypoint_groups_required),
            "reason": c.reason,
        }


class PoseEstimator:
    """C-3PO for one CAD model with its trained detector and certificate threshold (m)."""

    def __init__(
        self,
        model: CadModel,
        detector: KeypointDetector,
        threshold: float,
        corrector: CorrectorConfig | None = None,
        use_corrector: bool = True,
        turned_starts: bool = False,
        tilted_deg: float = 0.0,
        trim: float = 0.0,
    ) -> None:
        if detector.num_keypoints != len(model.keypoint_names):
            raise ValueError(
                f"detector predicts {detector.num_keypoints} keypoints, model {model.name} has "
                f"{len(model.keypoint_names)}"
            )
        self.model = model
        self.detector = detector.eval()
        self.threshold = float(threshold)
        self.corrector = corrector or CorrectorConfig()
        self.use_corrector = use_corrector
        self.surface = model.surface
        self.model_keypoints = torch.as_tensor(model.keypoints, dtype=torch.float32)
        self.scale = model.diameter / 2
        # Refinement starts (model-frame turn, depth offset): as corrected, and one tube diameter
        # further (a tube fitted from behind); with ``turned_starts`` also the model's z axis turned
        # a quarter about its x and about its y axis: an end fitting, about as long as it is wide,
        # can be fitted end-on where the camera saw its side (or side-on seen end-on), millimetres off.
        radii = self.surface.seg_r
        self.starts: list[tuple[np.ndarray, float]] = [(np.eye(3), 0.0)]
        if radii.numel():
            self.starts.append((np.eye(3), 2.0 * float(radii.min())))
        if turned_starts:
            self.starts += [(turn, 0.0) for turn in _QUARTER_TURNS]
        # With ``tilted_deg``, also turned that far either way about each model axis: a corner
        # joint seen by one face can be fitted tens of degrees turned (and left uncertified) where
        # a start within about 30 degrees of the truth finds the right fit.
        if tilted_deg:
            self.starts += [(turn, 0.0) for turn in tilted_turns(tilted_deg)]
        # The fraction of its cloud's points farthest from the model the refinement leaves out
        # (pose/corrector.py refine_pose): a mask spilling onto a neighbour pulls the fit less.
        self.trim = float(trim)

    def _failed(self, reason: str, n: int) -> PoseEstimate:
        return PoseEstimate(
            self.model.object_class,
            self.model.name,
            np.eye(3),
            np.zeros(3),
            np.zeros((len(self.model.keypoint_names), 3)),
            not_certified(reason, self.threshold, self.model.visibility),
            n,
            float("inf"),
        )

    def certify_at(
        self,
        points: np.ndarray | torch.Tensor,
        rotation: np.ndarray | torch.Tensor,
        translation: np.ndarray | torch.Tensor,
        allowance: float = 0.0,
    ) -> Certificate:
        """The certificate of the pose ``rotation, translation`` (camera frame) for the observed
        ``points`` (N, 3), the threshold grown by ``allowance`` (m) for the depth's noise."""
        seen = torch.as_tensor(points, dtype=torch.float32)
        rot = torch.as_tensor(rotation, dtype=torch.float32)
        t = torch.as_tensor(translation, dtype=torch.float32)
        with torch.no_grad():
            dist = self.surface(model_frame(seen[None], rot[None], t[None]))[0]
        posed = transform(self.model_keypoints, rot, t)
        return certify(seen, dist, posed, self.model.visibility, self.threshold, allowance=allowance)

    def estimate(self, points: np.ndarray) -> PoseEstimate:
        """Pose and certificate of the part from its observed points (N, 3), camera frame, m."""
        return self.estimate_batch([points])[0]

    def estimate_batch(
        self, clouds: list[np.ndarray], priors: Sequence[np.ndarray | None] | None = None
    ) -> list[PoseEstimate]:
        """:meth:`estimate` for several clouds at once (padded into one batch).

        ``priors`` (one per cloud, or None): where the part is expected (4x4, camera frame), when
        the caller knows (a piece at its place). The refinement then also starts from there and
        keeps whichever fit is closer to the observed points: seen from one side, a corner joint's
        cube fits about as well turned (the detector's keypoints sometimes land in that minimum),
        and a start near the truth finds the better fit. The certificate judges the result as any.
        """
        return estimate_together([(self, clouds, priors)])[0]


@dataclass(frozen=True)
class _Cloud:
    """One cloud of :func:`estimate_together`: where its estimate goes, and what poses it."""

    job: int
    index: int
    estimator: PoseEstimator
    points: np.ndarray  # (N, 3) finite
    prior: np.ndarray | None


def estimate_together(
    jobs: Sequence[tuple[PoseEstimator, Sequence[np.ndarray], Sequence[np.ndarray | None] | None]],
) -> list[list[PoseEstimate]]:
    """:meth:`PoseEstimator.estimate_batch` of several estimators at once: one list of estimates
    per ``(estimator, clouds, priors)`` job.

    Each model's detector reads its own clouds; then one corrector and one refinement run over the
    clouds of every model that shares their settings. The refinement treats each cloud on its own
    and the corrector keeps each cloud's best iterate, so a part is posed as in its own model's
    batch (the corrector runs on while any part still improves); a frame's parts of four kinds take
    about as long as its slowest kind's alone, not the sum of the four.
    """
    out: list[list[PoseEstimate | None]] = [[None] * len(clouds) for _, clouds, _ in jobs]
    groups: dict[tuple[CorrectorConfig, bool], list[_Cloud]] = {}
    for j, (estimator, clouds, priors) in enumerate(jobs):
        for i, c in enumerate(clouds):
            c = np.asarray(c, dtype=np.float32).reshape(-1, 3)
            finite = c[np.isfinite(c).all(1)]
            if len(finite) < MIN_POINTS:
                out[j][i] = estimator._failed(f"too few points: {len(finite)} < {MIN_POINTS}", len(finite))
            else:
                prior = priors[i] if priors is not None else None
                key = (estimator.corrector, estimator.use_corrector)
                groups.setdefault(key, []).append(_Cloud(j, i, estimator, finite, prior))
    for (config, use_corrector), group in groups.items():
        for cloud, estimate in zip(group, _estimate_group(group, config, use_corrector), strict=True):
            out[cloud.job][cloud.index] = estimate
    return [[e for e in row if e is not None] for row in out]


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """At most ``count`` of ``points``, evenly spaced through them (a cloud of a mask's pixels in
    raster order keeps its extent)."""
    if len(points) <= count:
        return points
    return points[np.linspace(0, len(points) - 1, count).round().astype(int)]


def _starts(estimators: Sequence[PoseEstimator]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Each element's refinement starts, padded to the most any has: depth offsets (B, S), turns
    (B, S, 3, 3) and which of them it has (B, S)."""
    count = max(len(e.starts) for e in estimators)
    offsets = torch.zeros(len(estimators), count)
    turns = torch.eye(3).repeat(len(estimators), count, 1, 1)
    use = torch.zeros(len(estimators), count, dtype=torch.bool)
    for b, e in enumerate(estimators):
        for k, (turn, offset) in enumerate(e.starts):
            offsets[b, k], turns[b, k], use[b, k] = offset, torch.as_tensor(turn), True
    return offsets, turns, use


def _estimate_group(
    group: Sequence[_Cloud], config: CorrectorConfig, use_corrector: bool
) -> list[PoseEstimate]:
    """Poses of clouds of one or more models, in one batch (see :func:`estimate_together`)."""
    estimators = [c.estimator for c in group]
    obs, mask = padded_batch([c.points for c in group])
    k = max(len(e.model.keypoint_names) for e in estimators)
    kp = torch.zeros(len(group), k, 3)
    model_kp = torch.zeros(len(group), k, 3)
    weights = torch.zeros(len(group), k)
    for estimator in {id(e): e for e in estimators}.values():
        rows = [b for b, e in enumerate(estimators) if e is estimator]
        n = len(estimator.model.keypoint_names)
        with torch.no_grad():
            kp[rows, :n] = estimator.detector(*padded_batch([group[b].points for b in rows]))
        model_kp[rows, :n] = estimator.model_keypoints
        weights[rows, :n] = 1.0
    surface = SurfaceDistance.stacked([e.surface for e in estimators])
    if use_corrector:
        scale = torch.tensor([e.scale for e in estimators])
        few_obs, few_mask = obs, mask
        if config.points and obs.shape[1] > config.points:
            few_obs, few_mask = padded_batch([_spread(c.points, config.points) for c in group])
        res = correct(few_obs, kp, surface, model_kp, scale, few_mask, config, weights)
        rot, t, obj = res.rotation, res.translation, res.objective_after
    else:
        with torch.no_grad():
            obj, rot, t = chamfer_objective(obs, mask, kp, surface, model_kp, weights)
    if config.refine_iterations > 0:
        offsets, turns, use = _starts(estimators)
        trim = torch.tensor([e.trim for e in estimators])
        rot, t, obj = refine_pose(
            obs, mask, rot, t, surface, config.refine_iterations, offsets, turns, use, trim
        )
        known = [b for b, c in enumerate(group) if c.prior is not None]
        if known:  # both objectives then the refined Chamfer
            start = torch.as_tensor(np.stack([group[b].prior for b in known]), dtype=rot.dtype)
            p_rot, p_t, p_obj = refine_pose(
                obs[known], mask[known], start[:, :3, :3], start[:, :3, 3],
                SurfaceDistance.stacked([estimators[b].surface for b in known]),
                config.refine_iterations, offsets[known], turns[known], use[known], trim[known],
            )  # fmt: skip
            for i, b in enumerate(known):
                if p_obj[i] < obj[b]:
                    rot[b], t[b], obj[b] = p_rot[i], p_t[i], p_obj[i]
    return _certified(estimators, [len(c.points) for c in group], obs, rot, t, obj)


def refined_together(
    items: Sequence[tuple[PoseEstimator, np.ndarray, np.ndarray, np.ndarray]],
) -> list[PoseEstimate]:
    """Poses of clouds refined from poses already known, with no keypoints and no corrector, in
    one batch: one estimate per ``(estimator, points (N, 3), rotation (3, 3), translation (3,))``.

    The refinement (:func:`~tlt_vision.pose.corrector.refine_pose`, each estimator's starts,
    trim and ``refine_iterations``) starts from the pose given: a part of a cloud whose pose is
    known about, its corner joint's cloud less the frame side its mask took in, whose fit the side
    pulled off. The starts matter: from a joint's pose turned by the side, the given start
    alone leads to a certified fit turned off the truth (tests/tlt_vision/test_core_pose.py). Each
    is certified as any estimate."""
    if not items:
        return []
    estimators = [e for e, *_ in items]
    clouds = [np.asarray(p, dtype=np.float32).reshape(-1, 3) for _, p, _, _ in items]
    obs, mask = padded_batch(clouds)
    rot = torch.as_tensor(np.stack([r for *_, r, _ in items]), dtype=obs.dtype)
    t = torch.as_tensor(np.stack([x for *_, x in items]), dtype=obs.dtype)
    offsets, turns, use = _starts(estimators)
    surface = SurfaceDistance.stacked([e.surface for e in estimators])
    trim = torch.tensor([e.trim for e in estimators])
    iterations = max(e.corrector.refine_iterations for e in estimators)
    rot, t, obj = refine_pose(obs, mask, rot, t, surface, iterations, offsets, turns, use, trim)
    return _certified(estimators, [len(c) for c in clouds], obs, rot, t, obj)


def _certified(
    estimators: Sequence[PoseEstimator],
    counts: Sequence[int],
    obs: torch.Tensor,
    rot: torch.Tensor,
    t: torch.Tensor,
    obj: torch.Tensor,
) -> list[PoseEstimate]:
    """The estimates of a batch's poses, each certified on its own ``counts[b]`` points."""
    out = []
    for b, (n, estimator) in enumerate(zip(counts, estimators, strict=True)):
        posed_kp = transform(estimator.model_keypoints, rot[b], t[b])
        cert = estimator.certify_at(obs[b, :n], rot[b], t[b])
        out.append(
            PoseEstimate(
                estimator.model.object_class,
                estimator.model.name,
                rot[b].double().numpy(),
                t[b].double().numpy(),
                posed_kp.double().numpy(),
                cert,
                n,
                float(obj[b]),
            )
        )
    return out


__all__ = [
    "MIN_POINTS",
    "PoseEstimate",
    "PoseEstimator",
    "estimate_together",
    "padded_batch",
    "refined_together",
    "tilted_turns",
]
