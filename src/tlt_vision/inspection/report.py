"""The inspection verdict and its inputs: :class:`Observation` s in, an :class:`InspectionReport`
out, judged within :class:`Tolerances`; with the helpers every check shares to pick the certified
poses of a class and read their axes. Only certified poses are trusted for geometry."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tlt_vision.pose.estimator import PoseEstimate


@dataclass(frozen=True)
class Observation:
    """A segmented instance: its class, and its pose estimate or the reason there is none."""

    object_class: str
    estimate: PoseEstimate | None = None
    reason: str = ""
    object_id: str = ""


@dataclass(frozen=True)
class Tolerances:
    position: float  # m
    angle: float  # rad

    @classmethod
    def from_mission(cls, mission: Any) -> Tolerances:
        return cls(
            float(mission.inspection["position_tolerance"]), float(mission.inspection["angle_tolerance"])
        )


@dataclass(frozen=True)
class InspectionReport:
    """A verdict on one part or bay. ``cannot_judge``: not a verdict; the view showed nothing
    wrong but could not settle what it must (a part seen where it should be but not placed well
    enough to certify), and ``reasons`` say what: look again, never discard on it."""

    target_id: str
    target_kind: str
    passed: bool
    reasons: tuple[str, ...]
    poses: tuple[PoseEstimate, ...] = field(default=())
    cannot_judge: bool = False


# A pose the depth's noise alone kept from being certified (placed, but not to 2 % of the part's
# size) still serves a check of a position tolerance that ``JUDGE_SIGMAS`` of its precision fit
# within; a position over the tolerance by less than that band is a doubt, not a verdict.
JUDGE_SIGMAS = 3.0


def noise_band(e: PoseEstimate) -> float:
    """How far (m) the depth's noise may have moved ``e``: ``JUDGE_SIGMAS`` times the fit's
    predicted precision; 0 on exact depth."""
    return JUDGE_SIGMAS * e.certificate.precision


def judged_by_depth(o: Observation, tolerance: float) -> bool:
    """Whether ``o`` was refused only for the depth's noise and is placed precisely enough to be
    judged against a position ``tolerance`` (m)."""
    e = o.estimate
    return e is not None and e.certificate.depth_limited and 0.0 < noise_band(e) <= tolerance


def joint_position_verdicts(
    joints: Sequence[tuple[str, float, PoseEstimate]], tolerance: float
) -> tuple[list[str], list[str]]:
    """For each corner joint ``(name, residual, pose)``: a reason when its residual (m) is over
    ``tolerance`` by more than its :func:`noise_band`, a doubt when over it within the band."""
    reasons, unsure = [], []
    for name, r, e in joints:
        if r > tolerance + noise_band(e):
            reasons.append(f"corner joint {name} off by {r * 1000:.1f} mm")
        elif r > tolerance:
            unsure.append(
                f"cannot judge the corner joint {name}: off by {r * 1000:.1f} mm, within what the "
                f"depth's noise allows over the {tolerance * 1000:.0f} mm tolerance"
            )
    return reasons, unsure


def split_certified(observations: Sequence[Observation], cls: str) -> tuple[list[PoseEstimate], list[str]]:
    """Certified estimates of a class, and the reasons its other instances were not trusted."""
    good, bad = [], []
    for o in observations:
        if o.object_class != cls:
            continue
        if o.estimate is None:
            bad.append(f"{cls}: {o.reason or 'no pose estimate'}")
        elif not o.estimate.certified:
            bad.append(f"{cls}: pose not certified ({o.estimate.certificate.reason})")
        else:
            good.append(o.estimate)
    return good, bad


def one_per_place(estimates: list[PoseEstimate], within: float) -> list[PoseEstimate]:
    """``estimates`` with those centred within ``within`` (m) of a better one left out: two
    overlapping masks of one fitting (Mask R-CNN's gun-and-fitting box beside its fitting-only
    box) give two certified poses of it, which are not two parts. The better one has the lower
    Chamfer 90th percentile."""
    kept: list[PoseEstimate] = []
    for e in sorted(estimates, key=lambda e: e.certificate.chamfer_p90):
        if all(np.linalg.norm(np.asarray(e.translation) - np.asarray(k.translation)) > within for k in kept):
            kept.append(e)
    return kept


def axis_of(e: PoseEstimate) -> np.ndarray:
    return np.asarray(e.rotation)[:, 2]


def angle_between_axes(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two undirected axes, rad."""
    return math.acos(min(1.0, abs(float(np.dot(a, b)))))


def uncertified(observations: Sequence[Observation], cls: str) -> list[Observation]:
    """The observations of ``cls`` :func:`split_certified` gives a reason for, in its order."""
    return [
        o for o in observations if o.object_class == cls and (o.estimate is None or not o.estimate.certified)
    ]
