"""Part and bay inspection from the pose pipeline's results (paper §V.E; Figs. 22, 26).

Reads :class:`Observation` s, one per segmented instance: its class and either a C-3PO
:class:`~tlt_vision.pose.estimator.PoseEstimate` (with its certificate) or the reason no estimate
could be made (empty mask, no depth, too few points, from :mod:`tlt_vision.pointcloud`). Returns an
:class:`InspectionReport` (tlt_interfaces/msg/InspectionReport): pass, or fail with every reason.
Only certified poses are trusted for geometry; an uncertified one is reported with its reason and
never counted as a found part.

* Strut: one straight strut tube and an end fitting at each end, on the tube's axis, at the
  strut's layout positions (:func:`tlt_vision.cad.models.strut_layout`), parallel to it. A tube
  that does not fit a straight tube (not observably correct although well seen) is a bent tube.
* Cross frame: the frame itself (its four sides) and a corner joint at each of its four corners.
* Placement alignment: a placed part's centre and axis, moved into the tower frame, against the
  mission's joint positions of its member; a held part from the end pieces (corner joints, end
  fittings) its arm's EE cameras see.
* Bay: the corner joints found match the mission's joint positions up to one rigid motion (the
  camera's pose drops out) within the position tolerance.
* Rivet joint (:mod:`.rivet_joint`, from one EE camera frame's rivet masks and depth rather than
  from poses): the head present, seated and in its hole, or what is wrong, or cannot judge.

One module per check (:mod:`.strut`, :mod:`.cross_frame`, :mod:`.alignment`, :mod:`.bay`,
:mod:`.rivet_joint`), the
shared verdict and tolerance types in :mod:`.report`, the rigid fit in :mod:`.rigid`.
"""

from __future__ import annotations

from tlt_vision.inspection.alignment import (
    HeldAlignment,
    corner_joint_prior,
    expected_pieces,
    held_part_alignment,
)
from tlt_vision.inspection.bay import bay_joints, inspect_bay
from tlt_vision.inspection.cross_frame import inspect_cross_frame
from tlt_vision.inspection.report import InspectionReport, Observation, Tolerances
from tlt_vision.inspection.rivet_joint import (
    HoleView,
    RivetJointJudgement,
    RivetJointLimits,
    judge_rivet_joint,
)
from tlt_vision.inspection.strut import inspect_strut, missing_fitting_places

__all__ = [
    "HeldAlignment",
    "HoleView",
    "InspectionReport",
    "Observation",
    "RivetJointJudgement",
    "RivetJointLimits",
    "Tolerances",
    "bay_joints",
    "corner_joint_prior",
    "expected_pieces",
    "held_part_alignment",
    "inspect_bay",
    "inspect_cross_frame",
    "inspect_strut",
    "judge_rivet_joint",
    "missing_fitting_places",
]
