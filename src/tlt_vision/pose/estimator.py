"""C-3PO pose estimation of one part model: detect keypoints, correct them, register, certify.

:class:`PoseEstimator` reads an observed cloud (N, 3) in the camera frame and returns a
:class:`PoseEstimate`: rotation, translation, corrected keypoints and the certificate. It never
raises on bad input: too few points give an uncertified estimate whose reason says so, and an
uncertified estimate is always marked ``certified=False`` whatever its pose looks like.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from tlt_vision.cad.models import CadModel
from tlt_vision.ops.registration import transform
from tlt_vision.pose.certificate import Certificate, certify, not_certified
from tlt_vision.pose.corrector import CorrectorConfig, chamfer_objective, correct, model_frame, refine_pose
from tlt_vision.pose.detector import KeypointDetector

MIN_POINTS = 16


def rotation_to_quaternion(rot: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` (geometry_msgs order) of a rotation matrix, ``w >= 0``."""
    m = np.asarray(rot, dtype=float)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    q = np.array([x, y, z, w])
    q /= np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


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
    objective: float  # corrector objective after correction, m^2

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
        # Refinement starts: as corrected, and one tube diameter further (a tube fitted from behind).
        radii = self.surface.seg_r
        self.depth_offsets = (0.0, 2.0 * float(radii.min())) if radii.numel() else (0.0,)

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
        out: list[PoseEstimate | None] = [None] * len(clouds)
        good = []
        for i, c in enumerate(clouds):
            c = np.asarray(c, dtype=np.float32).reshape(-1, 3)
            finite = c[np.isfinite(c).all(1)]
            if len(finite) < MIN_POINTS:
                out[i] = self._failed(f"too few points: {len(finite)} < {MIN_POINTS}", len(finite))
            else:
                good.append((i, finite))
        if good:
            obs, mask = padded_batch([c for _, c in good])
            with torch.no_grad():
                kp = self.detector(obs, mask)
            if self.use_corrector:
                res = correct(obs, kp, self.surface, self.model_keypoints, self.scale, mask, self.corrector)
                kp, rot, t, obj = res.keypoints, res.rotation, res.translation, res.objective_after
            else:
                with torch.no_grad():
                    obj, rot, t = chamfer_objective(obs, mask, kp, self.surface, self.model_keypoints)
            if self.corrector.refine_iterations > 0:
                rot, t, obj = refine_pose(
                    obs, mask, rot, t, self.surface, self.corrector.refine_iterations, self.depth_offsets
                )
            known = [j for j, (i, _) in enumerate(good) if priors is not None and priors[i] is not None]
            if known and self.corrector.refine_iterations > 0:  # both objectives then the refined Chamfer
                start = torch.as_tensor(np.stack([priors[good[j][0]] for j in known]), dtype=rot.dtype)
                p_rot, p_t, p_obj = refine_pose(
                    obs[known], mask[known], start[:, :3, :3], start[:, :3, 3], self.surface,
                    self.corrector.refine_iterations, self.depth_offsets,
                )
                for k, j in enumerate(known):
                    if p_obj[k] < obj[j]:
                        rot[j], t[j], obj[j] = p_rot[k], p_t[k], p_obj[k]
            for j, (i, c) in enumerate(good):
                seen = obs[j, : len(c)]
                with torch.no_grad():
                    dist = self.surface(model_frame(seen[None], rot[j : j + 1], t[j : j + 1]))[0]
                posed_kp = transform(self.model_keypoints, rot[j], t[j])
                cert = certify(seen, dist, posed_kp, self.model.visibility, self.threshold)
                out[i] = PoseEstimate(
                    self.model.object_class,
                    self.model.name,
                    rot[j].double().numpy(),
                    t[j].double().numpy(),
                    posed_kp.double().numpy(),
                    cert,
                    len(c),
                    float(obj[j]),
                )
        return [o for o in out if o is not None]


__all__ = ["MIN_POINTS", "PoseEstimate", "PoseEstimator", "padded_batch", "rotation_to_quaternion"]
