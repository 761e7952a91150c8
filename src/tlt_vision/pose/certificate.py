"""The C-3PO certificate of a pose: observable correctness and non-degeneracy (paper §V.E).

*Observable correctness*: the 90th percentile (``percentile``) of the distances from each observed
point to the posed CAD model's surface (:mod:`tlt_vision.cad.surface`) is at most the object's
threshold (the mission's ``inspection.chamfer_thresholds``). *Non-degeneracy*: at least
``groups_required`` keypoint groups are visible, a keypoint being visible when ``min_points``
observed points lie within ``visibility radius`` of it once posed (config/vision/keypoints.yaml).
A pose is certified when both hold; otherwise ``reason`` says which failed and by how much.

On a noisy depth camera the threshold grows by an ``allowance`` for the noise, added in quadrature
(:mod:`tlt_vision.depth_noise`); the certificate reports the threshold it was judged against, and
how precisely the fit places the part (``precision``): a pose refused only because the depth
cannot place it to 2 % of its size (``depth_limited``) can still serve a check whose tolerance is
wider than that (a cross frame's corner joints, :mod:`tlt_vision.inspection.cross_frame`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from tlt_vision.cad.models import Visibility

PERCENTILE = 0.9


@dataclass(frozen=True)
class Certificate:
    """A pose's certificate and the figures behind it (tlt_interfaces/msg/CertifiedPose fields)."""

    certified: bool
    chamfer_p90: float  # m
    chamfer_threshold: float  # m
    keypoint_groups_visible: int
    keypoint_groups_required: int
    visible_groups: tuple[str, ...]
    reason: str  # empty when certified
    allowance: float = 0.0  # m, the depth noise's share of the threshold (0 on exact depth)
    # On noisy depth: the fit's predicted ADD-S error, 1 sigma (m; 0 on exact depth or where not
    # predicted), and whether the depth's noise alone kept the pose from being certified (observably
    # correct, non-degenerate, but not placed to 2 % of the part's size: tlt_vision.pose.precision).
    precision: float = 0.0
    depth_limited: bool = False
    rotation_precision: float = 0.0  # rad, 1 sigma: the largest turn the depth leaves the fit

    @property
    def observably_correct(self) -> bool:
        return self.chamfer_p90 <= self.chamfer_threshold

    @property
    def non_degenerate(self) -> bool:
        return self.keypoint_groups_visible >= self.keypoint_groups_required


def not_certified(reason: str, threshold: float, visibility: Visibility) -> Certificate:
    """The certificate of an estimate that could not be made at all (no points, no model)."""
    return Certificate(False, float("inf"), threshold, 0, visibility.groups_required, (), reason)


def visible_groups(
    observed: torch.Tensor, posed_keypoints: torch.Tensor, visibility: Visibility
) -> tuple[str, ...]:
    """Names of the keypoint groups visible in ``observed`` (N, 3) for keypoints (K, 3)."""
    d = torch.linalg.vector_norm(posed_keypoints[:, None, :] - observed[None, :, :], dim=-1)
    seen = (d <= visibility.radius).sum(1) >= visibility.min_points
    return tuple(
        g
        for g, members in visibility.groups.items()
        if int(seen[list(members)].sum()) >= visibility.group_min_visible
    )


def certify(
    observed: torch.Tensor,
    distances: torch.Tensor,
    posed_keypoints: torch.Tensor,
    visibility: Visibility,
    threshold: float,
    percentile: float = PERCENTILE,
    allowance: float = 0.0,
) -> Certificate:
    """Certificate of one pose from the observed points (N, 3), their distances (N,) to the posed
    model (the Chamfer distances) and the posed keypoints (K, 3); ``allowance`` (m) for the depth's
    noise grows the threshold in quadrature."""
    threshold = math.hypot(threshold, allowance)
    if observed.shape[0] == 0:
        return not_certified("no observed points", threshold, visibility)
    dist = distances.detach()
    p90 = float(torch.quantile(dist.to(torch.float64), percentile))
    groups = visible_groups(observed.detach(), posed_keypoints.detach(), visibility)
    reasons = []
    if not p90 <= threshold:
        reasons.append(
            f"not observably correct: {percentile:.0%} Chamfer distance {p90 * 1000:.1f} mm "
            f"> threshold {threshold * 1000:.1f} mm"
        )
    if len(groups) < visibility.groups_required:
        reasons.append(
            f"degenerate view: {len(groups)} of {visibility.groups_required} required keypoint groups visible"
        )
    return Certificate(
        certified=not reasons,
        chamfer_p90=p90,
        chamfer_threshold=threshold,
        keypoint_groups_visible=len(groups),
        keypoint_groups_required=visibility.groups_required,
        visible_groups=groups,
        reason="; ".join(reasons),
        allowance=allowance,
    )


__all__ = ["PERCENTILE", "Certificate", "certify", "not_certified", "visible_groups"]
