"""What an ARS checks of its mission before it serves anything (paper §V.C.2, §V.D).

* every dispenser the mission has this ARS use has a coarse pose
  (:func:`tlt_ars.config.check_against_mission`);
* each coarse dispenser pose follows its rack's tag to this mission's racks
  (:mod:`tlt_ars.planning.coarse_pose_transfer`);
* every place and rivet step the mission gives this arm is within reach
  (:mod:`tlt_ars.planning.reachability`).

The ARS process runs them at start-up and refuses (exit status 2) a mission that fails one;
``tlt mission-check`` (:mod:`tlt_ars.mission_check_cli`) runs the same functions for both ARSs
before anything starts. Nothing here moves an arm or needs ROS.
"""

from __future__ import annotations

from typing import Any

from tlt_ars.config import ArsConfig, check_against_mission
from tlt_ars.planning.reachability import ReachReport, check_mission_reach
from tlt_ars.planning.world import SceneConfig
from tlt_common.config_schema import ConfigError


def prepare_for_mission(config: ArsConfig, mission: Any, scene: SceneConfig) -> ArsConfig:
    """``config`` with its coarse dispenser poses moved to ``mission``'s racks; :class:`ConfigError`
    naming the ARS file and the pose when a dispenser has no pose or a pose cannot follow its tag."""
    from tlt_ars.planning.coarse_pose_transfer import NoCoarsePose, follow_tags

    check_against_mission(config, mission)
    joints = {n: p.joints for n, p in config.dispenser_poses.items() if p.joints is not None}
    try:
        moved = follow_tags(joints, config.ars, config.dispensers_mission_path, config.mission_path, scene)
    except NoCoarsePose as exc:
        raise ConfigError(config.source, "poses.dispensers", str(exc)) from exc
    return config.with_dispenser_joints(moved)


def check_reach(config: ArsConfig, mission: Any, scene: SceneConfig) -> ReachReport:
    """Every place and rivet step of ``mission`` for this ARS's arm, each part held at the width the
    ARS file gives its kind; the report lists the unreachable steps with their reasons."""
    return check_mission_reach(scene, mission, [config.ars], config.ee["width"])


__all__ = ["check_reach", "prepare_for_mission"]
