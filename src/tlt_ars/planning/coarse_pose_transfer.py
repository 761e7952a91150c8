"""Coarse dispenser poses carried over to the mission being built.

A part rack carries its AprilTag just above its top slot (:func:`tlt_common.mission.tag_mounts.tag_mount`),
so how high the tag stands depends on how many parts the mission fills the rack with: the two-bay
mission's vertical rack holds eight struts, the one-bay's five, and its tag stands 0.21 m higher.
The coarse poses in ``config/ars/<ars>.yaml`` were found and checked in the twin for the tags of
one mission (``poses.dispensers_mission``, :mod:`tlt_tools.coarse_pose_search`); from them, in
another mission, the camera would look under the tag and the build fault on "tag not in view".

:func:`follow_tags` moves each pose with its tag: the tool, and so the camera on it, is moved by
the same rigid motion that takes the configured mission's tag to this mission's, so the camera
keeps its view (distance, angle, the tag's place in the image); the joints are the IK solution
nearest the configured ones, which must be free of collisions in this mission's scene. A pose
whose tag does not move is kept as configured. Raises :class:`NoCoarsePose` naming the dispenser
and the reason when a pose cannot follow.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from tlt_ars.planning.world import SceneConfig, build_scene, dispenser_frame
from tlt_common.geometry.transforms import invert
from tlt_common.geometry.ur10e import IkFailed
from tlt_common.mission.schema import Mission, load_mission
from tlt_common.mission.tag_mounts import TagMounting

# Tags closer than this (m, and about the same in rad) to where the poses were made for count as
# not moved: the configured, twin-checked joints are then kept exactly.
_SAME_TAG = 1e-6


class NoCoarsePose(RuntimeError):
    """No configuration of an arm sees a dispenser's tag as asked; the message says why."""


def dispenser_tag_pose(
    scene: SceneConfig, mission: Mission, mounting: TagMounting, dispenser: str
) -> np.ndarray:
    """World pose of ``dispenser``'s tag (x right, y up as printed, z out of the face), where the
    twin mounts it."""
    return dispenser_frame(scene, mission.dispensers[dispenser]) @ mounting.pose(mission, dispenser)


def follow_tags(
    poses: Mapping[str, Sequence[float]],
    arm: str,
    made_for: str | Path,
    mission: str | Path,
    scene: SceneConfig,
    other_arm_q: Sequence[float] | None = None,
    mounting: TagMounting | None = None,
) -> dict[str, np.ndarray]:
    """``poses`` (dispenser -> joints, viewing the tags of mission file ``made_for``) moved to the
    tags of mission file ``mission``. ``other_arm_q`` places the other arm for the collision
    check (default: its home); ``mounting`` is where the tags are mounted (default: the vision
    configuration's)."""
    mounting = mounting or TagMounting.load()
    before, after = load_mission(made_for), load_mission(mission)
    kin = scene.kinematics(arm)
    collision = None
    out: dict[str, np.ndarray] = {}
    for dispenser, joints in poses.items():
        q = np.asarray(joints, dtype=float)
        if dispenser not in after.dispensers or dispenser not in before.dispensers:
            out[dispenser] = q  # not used by this mission (check_against_mission said which are)
            continue
        move = dispenser_tag_pose(scene, after, mounting, dispenser) @ invert(
            dispenser_tag_pose(scene, before, mounting, dispenser)
        )
        if np.max(np.abs(move - np.eye(4))) <= _SAME_TAG:
            out[dispenser] = q
            continue
        try:
            moved = kin.nearest(move @ kin.forward(q), q)
        except IkFailed as exc:
            raise NoCoarsePose(
                f"{arm}: the coarse pose for {dispenser} cannot follow its tag "
                f"{np.linalg.norm(move[:3, 3]):.3f} m: {exc}"
            ) from exc
        if collision is None:
            collision = build_scene(scene, arm, after, other_arm_q=other_arm_q)
        if collision.in_collision(moved):
            raise NoCoarsePose(
                f"{arm}: the coarse pose for {dispenser}, moved {np.linalg.norm(move[:3, 3]):.3f} m with "
                "its tag, collides"
            )
        out[dispenser] = moved
    return out


__all__ = ["NoCoarsePose", "dispenser_tag_pose", "follow_tags"]
