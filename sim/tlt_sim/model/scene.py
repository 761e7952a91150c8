"""The twin's simulation: a compiled EDU model, its actuators, assembly rules and cameras.

:class:`Scene` builds the MJCF (:mod:`tlt_sim.model.generate`) for a machine description, a
mission and a scenario, compiles it, and steps it. Device emulators drive it by joint name:
``command_position`` / ``command_velocity`` set what an actuator aims for (moved at no more than
the joint's rated speed, as the real controllers do), ``position`` / ``velocity`` / ``effort`` read
it back. Grasps, gripper holds and rivets follow :mod:`tlt_sim.model.assembly` after every step.
Cameras render only when :meth:`Scene.render` is called.

A model MuJoCo refuses raises :class:`ModelCompileError` with MuJoCo's message and the XML file.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from tlt_common.geometry import ur10e
from tlt_common.geometry.transforms import frame_from_axes, rotation_to_mujoco_quat
from tlt_common.mission.schema import Member, Mission
from tlt_sim.model import names
from tlt_sim.model.assembly import Assembly, CompressionResult, Release, RivetShot
from tlt_sim.model.config import DEFAULT_EDU, load_edu
from tlt_sim.model.generate import ModelInfo, PartInfo, build_model
from tlt_sim.model.placement import Placement, placement_of
from tlt_sim.model.scenario import NOMINAL, Scenario, load_scenario


def _perpendiculars(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors that make a right-handed frame with unit ``u``."""
    a = np.cross(u, [0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.cross(u, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    return a, np.cross(u, a)


class ModelCompileError(RuntimeError):
    """MuJoCo could not compile the generated model."""

    def __init__(self, path: Path, message: str) -> None:
        self.path, self.message = path, message
        super().__init__(f"{path}: MuJoCo could not compile the model: {message}")


def compile_model(path: str | Path) -> mujoco.MjModel:
    """Compile an MJCF file; MuJoCo's complaint comes back as :class:`ModelCompileError`."""
    path = Path(path)
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        raise ModelCompileError(path, str(exc).strip()) from exc


class Scene:
    """One simulated EDU. Not thread-safe: step and command it from one thread.

    ``scenario`` is a :class:`Scenario` or a path to a scenario YAML file; ``out_dir`` receives the
    generated XML and textures (a fresh temporary folder by default).
    """

    def __init__(
        self,
        edu_path: str | Path = DEFAULT_EDU,
        mission: Mission | str | Path | None = None,
        scenario: Scenario | str | Path | None = None,
        out_dir: str | Path | None = None,
        timestep: float | None = None,
    ) -> None:
        edu, mission = load_edu(edu_path, mission)
        if timestep is not None:
            if not 1e-4 <= timestep <= 0.02:
                raise ValueError(f"timestep {timestep} s is outside [0.0001, 0.02]")
            edu["physics"]["timestep"] = timestep
        if scenario is None:
            scenario = NOMINAL
        elif not isinstance(scenario, Scenario):
            scenario = load_scenario(scenario, mission)
        if out_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="tlt-twin-")
            out_dir = self._tmp.name
        self.info: ModelInfo = build_model(edu, mission, out_dir, scenario)
        self.model = compile_model(self.info.xml_path)
        self.data = mujoco.MjData(self.model)
        self.edu, self.mission, self.scenario = edu, mission, scenario
        self._actuators = {self.model.actuator(i).name: i for i in range(self.model.nu)}
        self._joint_qpos = {n: int(self.model.jnt_qposadr[self.model.joint(n).id]) for n in self._actuators}
        self._joint_dof = {n: int(self.model.jnt_dofadr[self.model.joint(n).id]) for n in self._actuators}
        nu = self.model.nu
        self._vmax = np.array([self._max_velocity(self.model.actuator(i).name) for i in range(nu)])
        self._lo = self.model.actuator_actrange[:, 0].copy()
        self._hi = self.model.actuator_actrange[:, 1].copy()
        self._actadr = self.model.actuator_actadr.copy()
        self._target = np.zeros(nu)
        self._velocity = np.zeros(nu)
        self._velocity_mode = np.zeros(nu, dtype=bool)
        self._speed = self._vmax.copy()  # present speed limit of each setpoint (<= rated)
        self._busy = False
        # Setpoint velocities are recomputed every control period (about 10 ms) or on a command.
        self._control_steps = max(1, round(0.01 / self.model.opt.timestep))
        self._tick = 0
        self.assembly = Assembly(self.model, self.data, self.info)
        self._renderers: dict[bool, Any] = {}  # antialias -> CameraRenderer
        self.reset()

    # -- lifecycle ---------------------------------------------------------------------------
    def _max_velocity(self, joint: str) -> float:
        e = self.edu
        if joint.startswith("lifter_joint"):
            return e["lifter"]["max_velocity"]
        if joint.startswith("active_gripper"):
            return e["active_grippers"]["max_velocity"]
        if joint.startswith("top_gripper"):
            return e["top_grippers"]["max_velocity"]
        if joint.startswith("camera_mount"):
            return e["camera_mounts"]["max_velocity"]
        if "/grasp_" in joint:
            return e["end_effector"]["jaw_max_velocity"]
        if joint.endswith("/width"):
            return e["end_effector"]["width_max_velocity"]
        for arm in names.ARMS:
            if joint in names.arm_joints(arm):
                return ur10e.VELOCITY_LIMIT[names.arm_joints(arm).index(joint)]
        raise KeyError(joint)

    def reset(self) -> None:
        """Back to the start: arms at home, payload held by the Top Grippers, parts in dispensers
        but for the members the scenario starts built."""
        mujoco.mj_resetData(self.model, self.data)
        self.assembly.reset()
        start = {names.lifter_joint(i): self.edu["lifter"]["build_position"] for i in range(4)}
        start.update({names.top_gripper(i): self.edu["top_grippers"]["stroke"] for i in range(4)})
        for arm in names.ARMS:
            start.update(zip(names.arm_joints(arm), self.edu["arms"][arm]["home"], strict=True))
        for joint, value in start.items():
            self.data.qpos[self._joint_qpos[joint]] = value
            self.data.act[self._actadr[self._actuators[joint]]] = value
        self._target[:] = self.data.act[self._actadr]
        self._velocity[:] = 0.0
        self._velocity_mode[:] = False
        self._speed[:] = self._vmax
        self._busy = False
        self.data.ctrl[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        self.assembly.update()
        # The scenario's members that start built stand as the build would have left them; their
        # rivets came out of the feeders.
        for member_id in self.scenario.built:
            self.stage_member(member_id)
            for rivet in self.mission.member(member_id).rivets:
                self.assembly.rivets_left[rivet.dispenser] -= 1
        if self.scenario.built:
            mujoco.mj_forward(self.model, self.data)
            self.assembly.update()

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()

    def __enter__(self) -> Scene:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- time --------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps; setpoint velocities follow the commands every control
        period, assembly rules are applied after every step."""
        m, d, update = self.model, self.data, self.assembly.update
        for _ in range(n):
            if self._tick == 0 and self._busy:
                self._control()
            mujoco.mj_step(m, d)
            update()
            self._tick = (self._tick + 1) % self._control_steps

    def _control(self) -> None:
        """Set each setpoint's velocity: commanded, or what reaches the target by the next period."""
        period = self._control_steps * self.model.opt.timestep
        act = self.data.act[self._actadr]
        gap = self._target - act
        # minimum/maximum rather than np.clip: the same numbers at a fraction of the call overhead.
        towards = np.minimum(np.maximum(gap / period, -self._speed), self._speed)
        self.data.ctrl[:] = np.where(self._velocity_mode, self._velocity, towards)
        # Nothing left to move: no work until the next command.
        self._busy = bool(self._velocity_mode.any()) or bool((np.abs(gap) > 1e-12).any())
        if not self._busy:
            self.data.ctrl[:] = 0.0

    def advance(self, seconds: float) -> None:
        """Step for ``seconds`` of simulated time (rounded to whole steps)."""
        self.step(max(0, round(seconds / self.timestep)))

    # -- actuators ---------------------------------------------------------------------------
    @property
    def actuated_joints(self) -> list[str]:
        return list(self._actuators)

    def _index(self, joint: str) -> int:
        try:
            return self._actuators[joint]
        except KeyError:
            raise KeyError(f"no actuated joint named {joint!r}") from None

    def command_position(self, joint: str, position: float) -> None:
        """Aim ``joint`` at ``position`` (m or rad), clamped to its range; moves at rated speed."""
        i = self._index(joint)
        if not math.isfinite(position):
            raise ValueError(f"{joint}: position must be finite, got {position}")
        self._target[i] = min(max(position, self._lo[i]), self._hi[i])
        self._velocity_mode[i] = False
        self._speed[i] = self._vmax[i]
        self._wake()

    def command_positions(self, joints: list[str], positions: list[float]) -> None:
        """Move several joints together, each slowed so that all arrive at once (a UR ``movej``)."""
        if len(joints) != len(positions):
            raise ValueError(f"{len(joints)} joints but {len(positions)} positions")
        for joint, position in zip(joints, positions, strict=True):
            self.command_position(joint, position)
        idx = [self._index(j) for j in joints]
        span = np.abs(self._target[idx] - self.data.act[self._actadr[idx]])
        duration = float(np.max(span / self._vmax[idx])) if idx else 0.0
        if duration > 0:
            self._speed[idx] = np.maximum(span / duration, 1e-9)

    def command_velocity(self, joint: str, velocity: float) -> None:
        """Drive ``joint`` at ``velocity`` (clamped to its rated speed) until told otherwise."""
        i = self._index(joint)
        if not math.isfinite(velocity):
            raise ValueError(f"{joint}: velocity must be finite, got {velocity}")
        self._velocity[i] = max(-self._vmax[i], min(self._vmax[i], velocity))
        self._velocity_mode[i] = True
        self._target[i] = self._setpoint_of(i)
        self._wake()

    def hold(self, joint: str) -> None:
        """Stop ``joint`` where its setpoint is now."""
        i = self._index(joint)
        self._velocity_mode[i] = False
        self._target[i] = self._setpoint_of(i)
        self._wake()

    def position(self, joint: str) -> float:
        self._index(joint)
        return float(self.data.qpos[self._joint_qpos[joint]])

    def velocity(self, joint: str) -> float:
        self._index(joint)
        return float(self.data.qvel[self._joint_dof[joint]])

    def effort(self, joint: str) -> float:
        """Force (N) or torque (N m) the joint's actuator applies now."""
        return float(self.data.actuator_force[self._index(joint)])

    def _wake(self) -> None:
        self._busy = True
        self._tick = 0  # act on the command at the next step

    def _setpoint_of(self, i: int) -> float:
        return float(self.data.act[self._actadr[i]])

    def setpoint(self, joint: str) -> float:
        """Where the joint's servo aims now (it moves towards the commanded target)."""
        return self._setpoint_of(self._index(joint))

    def max_velocity(self, joint: str) -> float:
        return float(self._vmax[self._index(joint)])

    def limits(self, joint: str) -> tuple[float, float]:
        i = self._index(joint)
        return float(self._lo[i]), float(self._hi[i])

    def at_target(self, joints: list[str], tolerance: float = 1e-3) -> bool:
        return all(abs(self.position(j) - self._target[self._index(j)]) <= tolerance for j in joints)

    def set_joint_state(self, joint: str, position: float, velocity: float = 0.0) -> None:
        """Place ``joint`` directly (no dynamics) and make that its setpoint; for initial states."""
        i = self._index(joint)
        self.data.qpos[self._joint_qpos[joint]] = position
        self.data.qvel[self._joint_dof[joint]] = velocity
        self.data.act[self._actadr[i]] = self._target[i] = position
        self.data.ctrl[i] = 0.0
        self._velocity_mode[i] = False
        mujoco.mj_forward(self.model, self.data)

    def run_until(self, done, timeout_s: float, check_every: int = 10) -> bool:
        """Step until ``done()`` is true (checked every few steps) or ``timeout_s`` of sim time."""
        end = self.time + timeout_s
        while self.time < end:
            if done():
                return True
            self.step(check_every)
        return bool(done())

    def move_arm(
        self,
        arm: str,
        waypoints: list[np.ndarray],
        tolerance: float = 2e-3,
        timeout_s: float = 10.0,
        settle_s: float = 0.2,
    ) -> bool:
        """Drive ``arm`` through joint waypoints, joints in step; False if one is not reached in time."""
        joints = names.arm_joints(arm)
        for q in waypoints:
            self.command_positions(joints, [float(v) for v in q])
            if not self.run_until(lambda: self.at_target(joints, tolerance), timeout_s):
                return False
        self.advance(settle_s)
        return True

    def ee_point(self, arm: str, which: str) -> np.ndarray:
        """EE-frame point of ``which``: 'grasp' (midway between the grippers at the present width),
        'gun_a' or 'gun_b' (the rivet gun muzzles)."""
        e = self.edu["end_effector"]
        w = self.position(names.width_joint(arm))
        s, d, g = e["grip_spacing"], e["grasp_depth"], e["rivet_gun_offset"]
        points = {"grasp": (w / 2, 0.0, d), "gun_a": (-s / 2 - g, 0.0, d), "gun_b": (s / 2 + w + g, 0.0, d)}
        return np.array(points[which])

    # -- end effector I/O (GPIO) -------------------------------------------------------------
    def limit_switch(self, arm: str) -> bool:
        """The EE limit switch: pressed while the width joint is at its zero."""
        return self.position(names.width_joint(arm)) < self.edu["end_effector"]["limit_switch_below"]

    def load_rivet(self, arm: str, side: str) -> bool:
        return self.assembly.load_rivet(arm, side)

    def rivet_loaded(self, arm: str, side: str) -> bool:
        return self.assembly.loaded[(arm, side)]

    def fire_rivet(self, arm: str, side: str) -> RivetShot:
        return self.assembly.fire_rivet(arm, side)

    def holding(self, arm: str) -> str | None:
        return self.assembly.held[arm]

    # -- ground truth ------------------------------------------------------------------------
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
        out = []
        for i in range(self.data.ncon):
            c = self.data.contact[i]
            a, b = self.model.geom(c.geom1).name, self.model.geom(c.geom2).name
            if b.startswith(prefix) and not a.startswith(prefix):
                a, b = b, a
            if a.startswith(prefix) and (a, b) not in out:
                out.append((a, b))
        return out

    # -- staging (tests, data generation, pictures) ------------------------------------------
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
        pos, rot = self.camera_pose(camera)  # optical frame: z forward, x right, y down
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
            self.set_joint_state(joint, float(value))
        mujoco.mj_forward(self.model, self.data)

    def seat_in_grasp(self, part: str, arm: str, roll: float = 0.0, slide: float = 0.0) -> None:
        """Put strut ``part`` where ``arm``'s closed jaws hold it (data generation, the inspection
        bench): its axis along the grasp line, its middle ``slide`` m along the line from the
        grasp's centre, turned ``roll`` rad about its axis, the jaws closed on it as a grasp
        leaves them. Nothing is welded."""
        for side in ("a", "b"):
            self.set_joint_state(names.grasp_joint(arm, side), self.edu["end_effector"]["jaw_contact"])
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
        points = [self.joint_position_world(j) for j, _ in member.joints]
        _, tower = self.tower_pose()
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
        part = part or self.next_part(member.dispenser)
        if part is None:
            raise ValueError(f"dispenser {member.dispenser} is empty")
        info = self.info.parts[part]
        pos, rot = self.member_pose(member, info.kind)
        self.place_part(part, pos, rot)
        self.assembly.state[part] = "placed"
        if info.kind == "cross_frame":
            for i in range(4):
                self.set_joint_state(names.active_gripper(i), self.edu["active_grippers"]["range"][1])
            self.assembly.update()
        elif rivet:
            for r in member.rivets:
                self._stage_rivet(info, r.joint)
        return part

    def _stage_rivet(self, part: PartInfo, joint: str) -> None:
        target = self.joint_position_world(joint)
        end = min(
            part.ends, key=lambda e: np.linalg.norm(self.assembly.part_point(part, part.ends[e]) - target)
        )
        reach = self.edu["end_effector"]["rivet_reach"]
        for cf in self.info.cross_frames:
            for i in range(4):
                corner = self.site_position(names.corner_site(cf, i))
                if np.linalg.norm(corner - target) <= reach:
                    self.assembly.rivet(part, end, cf, i)

    def stage_bay(self, bay: int, skip_rivets: tuple[tuple[str, str], ...] = ()) -> dict[str, str]:
        """Stage every member of ``bay``; ``skip_rivets`` lists (member id, joint id) left out."""
        placed = {}
        for member in self.mission.bay_members(bay):
            part = self.stage_member(member.id, rivet=False)
            placed[member.id] = part
            if member.kind != "cross_frame":
                for r in member.rivets:
                    if (member.id, r.joint) not in skip_rivets:
                        self._stage_rivet(self.info.parts[part], r.joint)
        mujoco.mj_forward(self.model, self.data)
        return placed

    def compression_test(self, force_n: float = 200.0, settle_s: float = 0.3) -> CompressionResult:
        return self.assembly.compression_test(self.advance, force_n, settle_s)

    # -- cameras -----------------------------------------------------------------------------
    def renderer(self, width: int = 640, height: int = 480, antialias: bool = True):
        """The offscreen renderer, made on first use with a buffer of at least ``width`` x ``height``
        (remade larger when a bigger frame is asked for, up to the model's offscreen size); one with
        the model's multisampling (``antialias``), another without it when that is asked for."""
        from tlt_sim.model.cameras import CameraRenderer

        r = self._renderers.get(antialias)
        if r is not None and (width > r.max_width or height > r.max_height):
            width, height = max(width, r.max_width), max(height, r.max_height)
            self._renderers.pop(antialias).close()
            r = None
        if r is None:
            # A small buffer is much cheaper to make with OSMesa than the model's largest.
            limit_w, limit_h = self.model.vis.global_.offwidth, self.model.vis.global_.offheight
            r = self._renderers[antialias] = CameraRenderer(
                self.model, min(max(width, 640), limit_w), min(max(height, 480), limit_h), antialias
            )
        return r

    def render(
        self,
        camera: Any,
        width: int = 320,
        height: int = 240,
        depth: bool = True,
        segmentation: bool = True,
        antialias: bool = True,
        rgb: bool = True,
    ):
        """Render ``camera`` (name or free ``mujoco.MjvCamera``) now; see :class:`cameras.Frame`.
        Only the images asked for are made (``rgb``, ``depth``, ``segmentation``). ``antialias``
        (multisampling, the model's setting) is what the vision's detectors were trained on;
        ``False`` is cheaper on the CPU.

        Depth and segmentation always come from a single-sample pass: resolved, a multisampled
        depth buffer gives each pixel the depth of one sample off the pixel's centre (the cloud a
        depth camera would give moved by a third of a pixel: 1-1.5 mm at a metre, which showed as
        that bias in every certified pose), and blended id colours name geoms that are not there."""
        limit_w, limit_h = self.model.vis.global_.offwidth, self.model.vis.global_.offheight
        if not (0 < width <= limit_w and 0 < height <= limit_h):
            raise ValueError(f"frame {width}x{height} exceeds the offscreen buffer {limit_w}x{limit_h}")
        if not (antialias and rgb):
            return self.renderer(width, height, False).render(
                self.data, camera, width, height, depth, segmentation, rgb
            )
        multisampled = self.renderer(width, height, True)
        colour = multisampled.render(self.data, camera, width, height, depth=False, segmentation=False)
        if not (depth or segmentation):
            return colour
        exact = self.renderer(width, height, False)
        frame = exact.render(self.data, camera, width, height, depth, segmentation, rgb=False)
        return dataclasses.replace(frame, rgb=colour.rgb)

    def camera_pose(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        """Optical frame (x right, y down, z forward) of ``camera`` in the world."""
        cid = self.model.camera(camera).id
        return self.data.cam_xpos[cid].copy(), self.data.cam_xmat[cid].reshape(3, 3) @ np.diag(
            [1.0, -1.0, -1.0]
        )

    def camera_fovy(self, camera: str) -> float:
        return float(self.model.cam_fovy[self.model.camera(camera).id])


__all__ = ["ModelCompileError", "Scene", "compile_model"]
