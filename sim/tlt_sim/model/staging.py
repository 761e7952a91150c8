"""Setting the twin's parts and arms straight where a test, a picture or a data set wants them.

:class:`Staging` puts things at rest without dynamics, as if they had been moved there: a free
part at a pose, across a camera's view or seated in an arm's grasp, an arm at a joint position,
and members of the tower placed and riveted as the mission says (a scenario's members that start
built, a bay for the compression test or a picture).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import mujoco
import numpy as np

from tlt_common.geometry.transforms import frame_from_axes, rotation_to_mujoco_quat
from tlt_common.mission.schema import Member, Mission
from tlt_sim.model import names
from tlt_sim.model.assembly import Assembly
from tlt_sim.model.camera_views import CameraViews
from tlt_sim.model.generate import ModelInfo, PartInfo
from tlt_sim.model.ground_truth import GroundTruth
from tlt_sim.model.rivet_outcomes import RivetJoint
from tlt_sim.model.servos import Servos


def _perpendiculars(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors that make a right-handed frame with unit ``u``."""
    a = np.cross(u, [0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.cross(u, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    return a, np.cross(u, a)


class Staging:
    """Stages parts and arms of ``data`` (a compiled ``model`` of ``info``, the EDU ``edu`` built
    for ``mission``): joints through ``servos``, joins through ``assembly``, places from ``truth``
    and camera poses from ``cameras``."""

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        info: ModelInfo,
        edu: dict[str, Any],
        mission: Mission,
        assembly: Assembly,
        servos: Servos,
        truth: GroundTruth,
        cameras: CameraViews,
    ) -> None:
        self.model, self.data, self.info, self.edu, self.mission = model, data, info, edu, mission
        self.assembly, self.servos, self.truth, self.cameras = assembly, servos, truth, cameras

    def place_part(self, name: str, position: np.ndarray, rotation: np.ndarray) -> None:
        """Put a free part at a world pose at rest (no dynamics), as if it had been set there."""
        part = self.info.parts[name]
        jid = self.model.body(part.body).jntadr[0]
        adr, dof = self.model.jnt_qposadr[jid], self.model.jnt_dofadr[jid]
        self.data.qpos[adr : adr + 3] = position
        self.data.qpos[adr + 3 : adr + 7] = rotation_to_mujoco_quat(rotation)
        self.data.qvel[dof : dof + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def place_in_view(self, part: str, camera: str, distance: float = 0.45) -> None:
        """Put ``part`` across ``camera``'s view, centred ``distance`` in front of it (data generation,
        inspection tests)."""
        pos, rot = self.cameras.camera_pose(camera)  # optical frame: z forward, x right, y down
        info = self.info.parts[part]
        centre = pos + distance * rot[:, 2]
        if info.kind == "cross_frame":
            self.place_part(
                part,
                centre - (rot[:, 0] + rot[:, 1]) * info.length / 2,
                np.column_stack([rot[:, 0], rot[:, 1], rot[:, 2]]),
            )
        else:
            self.place_part(part, centre - rot[:, 0] * info.length / 2, frame_from_axes(rot[:, 1], rot[:, 0]))

    def pose_arm(self, arm: str, joints: np.ndarray) -> None:
        """Set ``arm``'s six joints at rest (no dynamics), as if it had moved there."""
        for joint, value in zip(names.arm_joints(arm), joints, strict=True):
            self.servos.set_joint_state(joint, float(value))
        mujoco.mj_forward(self.model, self.data)

    def seat_in_grasp(self, part: str, arm: str, roll: float = 0.0, slide: float = 0.0) -> None:
        """Put strut ``part`` where ``arm``'s closed jaws hold it (data generation, the inspection
        bench): its axis along the grasp line, its middle ``slide`` m along the line from the
        grasp's centre, turned ``roll`` rad about its axis, the jaws closed on it as a grasp
        leaves them. Nothing is welded."""
        for side in ("a", "b"):
            self.servos.set_joint_state(names.grasp_joint(arm, side), self.edu["end_effector"]["jaw_contact"])
        info = self.info.parts[part]
        centre, axis = self.assembly.grasp_line(arm)
        middle = (info.ends["a"] + info.ends["b"]) / 2
        along = info.ends["b"] - info.ends["a"]
        p, q = _perpendiculars(axis)
        p, q = math.cos(roll) * p + math.sin(roll) * q, -math.sin(roll) * p + math.cos(roll) * q
        along = along / np.linalg.norm(along)
        rotation = np.column_stack([axis, p, q]) @ np.column_stack([along, *_perpendiculars(along)]).T
        self.place_part(part, centre + slide * axis - rotation @ middle, rotation)

    def member_pose(self, member: Member, kind: str) -> tuple[np.ndarray, np.ndarray]:
        """World pose a part's body takes when it is ``member`` (mission joints, present tower)."""
        points = [self.truth.joint_position_world(j) for j, _ in member.joints]
        _, tower = self.truth.tower_pose()
        if kind == "cross_frame":
            return points[0], tower
        axis = (points[1] - points[0]) / np.linalg.norm(points[1] - points[0])
        x = np.cross(axis, tower[:, 2])
        x = tower[:, 0] if np.linalg.norm(x) < 1e-6 else x / np.linalg.norm(x)
        return points[0], np.column_stack([x, np.cross(axis, x), axis])

    def stage_member(self, member_id: str, part: str | None = None, rivet: bool = True) -> str:
        """Set a part as ``member_id`` (next part of its dispenser unless named), riveted as the
        mission says. A cross frame is taken by the Active Grippers. Returns the part's name."""
        member = self.mission.member(member_id)
        part = part or self.truth.next_part(member.dispenser)
        if part is None:
            raise ValueError(f"dispenser {member.dispenser} is empty")
        info = self.info.parts[part]
        pos, rot = self.member_pose(member, info.kind)
        self.place_part(part, pos, rot)
        self.assembly.state[part] = "placed"
        if info.kind == "cross_frame":
            for i in range(4):
                self.servos.set_joint_state(names.active_gripper(i), self.edu["active_grippers"]["range"][1])
            self.assembly.update()
        elif rivet:
            for r in member.rivets:
                self._stage_rivet(info, member_id, r.joint)
        return part

    def _stage_rivet(self, part: PartInfo, member_id: str, joint: str, kind: str = "good") -> None:
        """Rivet ``part`` (standing as ``member_id``) at ``joint`` as a rivet of outcome ``kind``
        leaves it, and record that outcome."""
        target = self.truth.joint_position_world(joint)
        end = min(
            part.ends, key=lambda e: np.linalg.norm(self.assembly.part_point(part, part.ends[e]) - target)
        )
        reach = self.edu["end_effector"]["rivet_reach"]
        for cf in self.info.cross_frames:
            for i in range(4):
                corner = self.truth.site_position(names.corner_site(cf, i))
                if np.linalg.norm(corner - target) <= reach:
                    self.assembly.rivet(part, end, cf, i, kind)
                    name = f"rivet/{part.body}/{cf}"
                    cause = "staged" if kind == "good" else "injected"
                    self.assembly.record_joint(RivetJoint(member_id, joint, name, kind, cause, "staged", 1))

    def stage_bay(
        self,
        bay: int,
        skip_rivets: tuple[tuple[str, str], ...] = (),
        rivet_kinds: Mapping[tuple[str, str], str] | None = None,
    ) -> dict[str, str]:
        """Stage every member of ``bay``; ``skip_rivets`` lists (member id, joint id) left out,
        ``rivet_kinds`` maps (member id, joint id) to a rivet outcome other than good
        (:data:`~tlt_sim.model.rivet_outcomes.KINDS`)."""
        kinds = dict(rivet_kinds or {})
        placed = {}
        for member in self.mission.bay_members(bay):
            part = self.stage_member(member.id, rivet=False)
            placed[member.id] = part
            if member.kind != "cross_frame":
                for r in member.rivets:
                    if (member.id, r.joint) not in skip_rivets:
                        kind = kinds.pop((member.id, r.joint), "good")
                        self._stage_rivet(self.info.parts[part], member.id, r.joint, kind)
        if kinds:
            raise ValueError(f"bay {bay} has no rivet at {', '.join(f'{m} {j}' for m, j in kinds)}")
        mujoco.mj_forward(self.model, self.data)
        return placed

    def stage_built(self, member_ids: Iterable[str]) -> None:
        """Members that start built stand as the build would have left them; their rivets came
        out of the feeders, each turned out as the scenario's rivet faults say for a first shot
        (good where none is injected)."""
        member_ids = list(member_ids)
        plan = self.info.scenario.rivets
        for member_id in member_ids:
            part = self.stage_member(member_id, rivet=False)
            for rivet in self.mission.member(member_id).rivets:
                if self.info.parts[part].kind != "cross_frame":
                    kind = plan.injected(member_id, rivet.joint, 1)
                    self._stage_rivet(self.info.parts[part], member_id, rivet.joint, kind or "good")
                self.assembly.rivets_left[rivet.dispenser] -= 1
        if member_ids:
            mujoco.mj_forward(self.model, self.data)
            self.assembly.update()


__all__ = ["Staging"]
