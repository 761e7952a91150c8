"""What the twin knows that the robots must measure: poses, parts, dispensers and forces.

:class:`GroundTruth` reads the simulation as it stands: world poses of bodies, sites and the
mission's joints (on the tower as it stands now), where each part is and in what state, what the
dispensers still hold, the forces constraints and contacts carry, and how each riveted joint truly
turned out (:meth:`GroundTruth.rivet_joints`). The twin's record of a placement
(:meth:`GroundTruth.placement`) judges a release here, and tests check the physics with it. All of
it is for judging: the system under test measures, it never reads this.
"""

from __future__ import annotations

import mujoco
import numpy as np

from tlt_common.mission.schema import Mission
from tlt_sim.model.assembly import Assembly, Release
from tlt_sim.model.generate import ModelInfo, PartInfo
from tlt_sim.model.placement import Placement, placement_of
from tlt_sim.model.rivet_outcomes import RivetJoint


class GroundTruth:
    """The true state of ``data`` (a compiled ``model`` of ``info``, built for ``mission``), its
    joins followed by ``assembly``."""

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        info: ModelInfo,
        mission: Mission,
        assembly: Assembly,
    ) -> None:
        self.model, self.data, self.info, self.mission, self.assembly = model, data, info, mission, assembly

    def body_pose(self, body: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of ``body``."""
        return self.assembly.body_pose(body)

    def site_position(self, site: str) -> np.ndarray:
        return self.assembly.site_pos(site)

    def tower_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The tower frame (mission joint coordinates) in the world: the payload's cross frame."""
        return self.body_pose("payload")

    def joint_position_world(self, joint_id: str) -> np.ndarray:
        pos, rot = self.tower_pose()
        return pos + rot @ np.asarray(self.mission.joints[joint_id], dtype=float)

    def part(self, name: str) -> PartInfo:
        return self.info.parts[name]

    def part_state(self, name: str) -> str:
        return self.assembly.state[name]

    def placement(self, release: Release) -> Placement:
        """Where ``release`` left its part against the mission's places (the twin's truth)."""
        part = self.info.parts[release.part]
        points = [release.position + release.rotation @ p for p in part.ends.values()]
        return placement_of(part.name, part.kind, points, self.mission, self.joint_position_world)

    def part_end(self, name: str, end: str) -> np.ndarray:
        part = self.info.parts[name]
        return self.assembly.part_point(part, part.ends[end])

    def dispenser_count(self, dispenser: str) -> int:
        """Parts (or rivets) still in ``dispenser``."""
        if dispenser in self.assembly.rivets_left:
            return self.assembly.rivets_left[dispenser]
        return sum(
            1
            for p in self.info.parts.values()
            if p.dispenser == dispenser and self.assembly.state[p.name] == "stowed"
        )

    def next_part(self, dispenser: str) -> str | None:
        stowed = [
            p
            for p in self.info.parts.values()
            if p.dispenser == dispenser and self.assembly.state[p.name] == "stowed"
        ]
        return min(stowed, key=lambda p: p.index).name if stowed else None

    def active_constraints(self, prefix: str = "") -> list[str]:
        return self.assembly.active(prefix)

    def constraint_force(self, name: str) -> np.ndarray:
        """Force (first 3 rows, N) an active equality transmits; zeros when inactive."""
        i = self.assembly.eq[name]
        rows = np.nonzero(
            (self.data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (self.data.efc_id == i)
        )[0]
        return self.data.efc_force[rows[:3]].copy() if len(rows) else np.zeros(3)

    def constraint_slip(self, name: str) -> float:
        """How far (m) the two points an active equality holds together have moved apart: a weld
        or connect giving under load; 0 when inactive."""
        return self.assembly.slip(name)

    def rivet_joints(self) -> list[RivetJoint]:
        """Every joint a rivet reached (shot or staged), as its latest shot left it."""
        return list(self.assembly.rivet_joints.values())

    def rivet_joint(self, member: str, joint: str) -> RivetJoint | None:
        """The outcome at ``joint`` of mission member ``member`` (None: never riveted)."""
        return next((r for r in self.rivet_joints() if (r.member, r.joint) == (member, joint)), None)

    def contact_force(self, body: str) -> np.ndarray:
        """Total contact force (N, world frame) that other bodies exert on ``body`` now."""
        b = self.model.body(body).id
        total, wrench = np.zeros(3), np.zeros(6)
        for i in range(self.data.ncon):
            c = self.data.contact[i]
            b1, b2 = self.model.geom_bodyid[c.geom1], self.model.geom_bodyid[c.geom2]
            if b not in (b1, b2):
                continue
            mujoco.mj_contactForce(self.model, self.data, i, wrench)
            # The contact frame's first axis is the normal from geom1 to geom2: it pushes geom2 along it.
            world = c.frame.reshape(3, 3).T @ wrench[:3]
            total += world if b == b2 else -world
        return total

    def contacts_of(self, prefix: str) -> list[tuple[str, str]]:
        """(own geom, other geom) names of the contacts now of geoms whose names start with ``prefix``."""
        out: list[tuple[str, str]] = []
        for i in range(self.data.ncon):
            c = self.data.contact[i]
            a, b = self.model.geom(c.geom1).name, self.model.geom(c.geom2).name
            if b.startswith(prefix) and not a.startswith(prefix):
                a, b = b, a
            if a.startswith(prefix) and (a, b) not in out:
                out.append((a, b))
        return out


__all__ = ["GroundTruth"]
