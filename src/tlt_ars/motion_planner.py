"""The ARS's interface to the planning package (``tlt_ars.planning``), paper §V.D.

:class:`MotionPlanner` builds the collision scene as the arm stands (tower as placed so far, the
other arm where its JointState says, the part held), plans with OMPL, blends the plan's corners
where the arcs are free in the same scene, time-parameterises the result under the UR10e limits
scaled by ``arm.velocity_scale`` and returns a ``trajectory_msgs/JointTrajectory``
of the arm's joints, or raises :class:`~tlt_ars.planning.planner.PlanningFailed` with the reason.
The arm is only ever sent a trajectory that came out of it, so it never moves on a path that was
not checked. :class:`MotionGoal` says where a motion goes; the behaviours that plan and execute
one are in :mod:`tlt_ars.motion`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from tlt_ars.planning.planner import Planner, PlanningFailed
from tlt_ars.planning.reachability import TargetUnreachable, reach_target
from tlt_ars.planning.targets import Target
from tlt_ars.planning.time_parameterisation import time_parameterise
from tlt_ars.planning.world import SceneConfig, Width, build_scene
from tlt_common.ros.stamps import split_seconds


@dataclass
class MotionGoal:
    """Where a motion goes: a joint configuration, or the first usable of candidate targets
    (``use`` picks the target's ``pose`` or its ``pre_pose``). ``contact`` lets the end effector and
    the held part touch the tower (the last move onto a joint). ``key`` names the approach, so the
    fine move after a coarse one takes the same candidate (``RequestData.targets[key]``).
    ``straight`` moves the tool on the straight line to the (single) target's pose or pre-pose: the
    fine move onto a part or joint and the retreat from it, along the line its approach was checked
    on."""

    joints: np.ndarray | None = None
    targets: list[Target] = field(default_factory=list)
    use: str = "pose"
    contact: bool = False
    key: str | None = None
    straight: bool = False


@dataclass
class PlannedMotion:
    trajectory: JointTrajectory
    duration: float
    target: Target | None


class MotionPlanner:
    """Plans for one arm in the scene as it stands; see the module docstring."""

    def __init__(
        self,
        scene: SceneConfig,
        arm: str,
        mission: Any,
        joint_names: Sequence[str],
        *,
        velocity_scale: float,
        sample_period: float,
        time_limit: float | None = None,
    ) -> None:
        self.scene = scene
        self.arm = arm
        self.mission = mission
        self.joint_names = list(joint_names)
        lim = scene.limits
        self.velocity = np.asarray(lim["velocity"], dtype=float) * velocity_scale
        self.acceleration = np.asarray(lim["acceleration"], dtype=float) * velocity_scale
        self.sample_period = sample_period
        self.time_limit = time_limit

    @property
    def search_time(self) -> float:
        """The OMPL search time of one plan, s: ``time_limit``, or the scene's ``planning_time_s``."""
        if self.time_limit is not None:
            return float(self.time_limit)
        return float(self.scene.planning["planning_time_s"])

    def plan(
        self,
        start: np.ndarray,
        goal: MotionGoal,
        *,
        placed: set[str],
        bay: int,
        carrying: str | None,
        other_q: np.ndarray | None,
        width: Width = 0.0,
        search_time: float | None = None,
    ) -> PlannedMotion:
        """A checked, time-parameterised trajectory from ``start`` to ``goal`` with the EE ``width``
        wide (or moving between a ``(from, to)`` pair), searching at most ``search_time`` s
        (:attr:`search_time`) for each candidate; PlanningFailed if none. A goal whose every usable
        candidate ran out of search time fails as ``timeout``: more time may find a path."""
        limit = self.search_time if search_time is None else search_time
        kwargs = dict(placed=placed, bay=bay, other_arm_q=other_q, carrying=carrying, width=width)
        scene = build_scene(self.scene, self.arm, self.mission, contact=goal.contact, **kwargs)
        planner = Planner.from_config(scene, self.scene.planning, home=self.scene.home(self.arm))
        chosen = None
        if goal.joints is not None:
            plan = planner.plan_to_joints(start, goal.joints, limit)
        elif goal.straight:
            # Not the joint-space line between the ends: on a 0.7 m approach that line swings a
            # carried cross frame into the lifter's posts, where the tool's straight line is free.
            if len(goal.targets) != 1:
                raise PlanningFailed("ik", f"a straight move needs one target, not {len(goal.targets)}")
            chosen = goal.targets[0]
            plan = planner.plan_cartesian(start, chosen.pose if goal.use == "pose" else chosen.pre_pose)
        else:
            if not goal.targets:
                raise PlanningFailed("ik", "no candidate pose to move to")
            free = build_scene(self.scene, self.arm, self.mission, contact=False, **kwargs)
            contact = build_scene(self.scene, self.arm, self.mission, contact=True, **kwargs)
            reasons, searched_out = [], False
            for target in goal.targets:
                # A candidate counts only when its pose, its pre-pose and the straight move between
                # them are all free: the coarse approach must not commit to a dead end. The arm then
                # goes to exactly those configurations, so the final straight move is the one checked.
                try:
                    q_pre, q = reach_target(
                        free, contact, target, start, self.scene.planning["dense_check_resolution"]
                    )
                except TargetUnreachable as exc:
                    reasons.append(f"{target.label}: {exc}")
                    continue
                try:
                    plan = planner.plan_to_joints(start, q_pre if goal.use == "pre_pose" else q, limit)
                except PlanningFailed as exc:
                    reasons.append(f"{target.label}: {exc.reason}")
                    searched_out |= exc.kind == "timeout"
                    continue
                chosen = target
                break
            else:
                raise PlanningFailed(
                    "timeout" if searched_out else "ik",
                    f"none of {len(goal.targets)} candidate(s) is usable: " + "; ".join(reasons),
                )
        traj = time_parameterise(planner.blended(plan), self.velocity, self.acceleration)
        return PlannedMotion(self.to_msg(traj), traj.duration, chosen)

    def to_msg(self, traj: Any) -> JointTrajectory:
        msg = JointTrajectory()
        msg.joint_names = list(self.joint_names)
        for p in traj.points(self.sample_period):
            point = JointTrajectoryPoint()
            point.positions = [float(v) for v in p.q]
            point.velocities = [float(v) for v in p.qd]
            point.accelerations = [float(v) for v in p.qdd]
            point.time_from_start = duration_msg(p.t)
            msg.points.append(point)
        return msg


def duration_msg(seconds: float) -> Duration:
    """builtin_interfaces/Duration of ``seconds`` (>= 0), rounded to the nanosecond."""
    sec, nanosec = split_seconds(seconds)
    return Duration(sec=sec, nanosec=nanosec)


__all__ = ["MotionGoal", "MotionPlanner", "PlannedMotion", "duration_msg"]
