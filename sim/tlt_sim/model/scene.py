"""The twin's simulation: a compiled EDU model, its actuators, assembly rules and cameras.

:class:`Scene` builds the MJCF (:mod:`tlt_sim.model.generate`) for a machine description, a
mission and a scenario, compiles it, and steps it. Device emulators drive it by joint name:
``command_position`` / ``command_velocity`` set what an actuator aims for (moved at no more than
the joint's rated speed, as the real controllers do), ``position`` / ``velocity`` / ``effort`` read
it back (:mod:`tlt_sim.model.servos`). Grasps, gripper holds and rivets follow
:mod:`tlt_sim.model.assembly` after every step. Cameras render only when :meth:`Scene.render` is
called (:mod:`tlt_sim.model.camera_views`); the true state is read through
:mod:`tlt_sim.model.ground_truth` and parts are set at rest through :mod:`tlt_sim.model.staging`.

A model MuJoCo refuses raises :class:`ModelCompileError` with MuJoCo's message and the XML file.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

import mujoco
import numpy as np

from tlt_common.geometry import ur10e
from tlt_common.mission.schema import Member, Mission
from tlt_sim.model import names
from tlt_sim.model.assembly import Assembly, Release, RivetShot
from tlt_sim.model.camera_views import CameraViews
from tlt_sim.model.cameras import CameraRenderer, Frame
from tlt_sim.model.compression import CompressionResult, compression_test
from tlt_sim.model.config import DEFAULT_EDU, load_edu
from tlt_sim.model.end_effectors import EndEffectors
from tlt_sim.model.generate import ModelInfo, PartInfo, build_model
from tlt_sim.model.ground_truth import GroundTruth
from tlt_sim.model.placement import Placement
from tlt_sim.model.scenario import NOMINAL, Scenario, load_scenario
from tlt_sim.model.servos import Servos
from tlt_sim.model.staging import Staging


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

    The scene owns the clock (:meth:`step`) and composes one collaborator per concern, built on the
    same model and data: :attr:`servos` (:class:`Servos`: the actuated joints), :attr:`assembly`
    (:class:`Assembly`: grasps, holds, rivets), :attr:`end_effectors` (:class:`EndEffectors`: EE
    signals and tool points), :attr:`truth` (:class:`GroundTruth`: poses, parts, dispensers, forces),
    :attr:`staging` (:class:`Staging`: parts and arms set at rest) and :attr:`cameras`
    (:class:`CameraViews`: frames and camera poses). The methods below are the API the device
    emulators, tools and tests share, each handed to its collaborator; the more specialised reads
    are made on the collaborators themselves (``scene.truth.contact_force(...)``).
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
        model, data, info = self.model, self.data, self.info
        self.servos = Servos(model, data, self._rated_velocity)
        self.assembly = Assembly(model, data, info)
        self.end_effectors = EndEffectors(edu, self.servos, self.assembly)
        self.truth = GroundTruth(model, data, info, mission, self.assembly)
        self.cameras = CameraViews(model, data)
        self.staging = Staging(
            model, data, info, edu, mission, self.assembly, self.servos, self.truth, self.cameras
        )
        self.reset()

    # -- lifecycle ---------------------------------------------------------------------------
    def _rated_velocity(self, joint: str) -> float:
        """The rated speed (m/s or rad/s) of an actuated joint, from the EDU description."""
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
        self.servos.reset(start)
        mujoco.mj_forward(self.model, self.data)
        self.assembly.update()
        self.staging.stage_built(self.scenario.built)

    def close(self) -> None:
        self.cameras.close()

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
        m, d, control, update = self.model, self.data, self.servos.update, self.assembly.update
        for _ in range(n):
            control()
            mujoco.mj_step(m, d)
            update()

    def advance(self, seconds: float) -> None:
        """Step for ``seconds`` of simulated time (rounded to whole steps)."""
        self.step(max(0, round(seconds / self.timestep)))

    def run_until(self, done: Callable[[], bool], timeout_s: float, check_every: int = 10) -> bool:
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
            self.servos.command_positions(joints, [float(v) for v in q])
            if not self.run_until(lambda: self.servos.at_target(joints, tolerance), timeout_s):
                return False
        self.advance(settle_s)
        return True

    def compression_test(self, force_n: float = 200.0, settle_s: float = 0.3) -> CompressionResult:
        """See :func:`tlt_sim.model.compression.compression_test`."""
        return compression_test(self.assembly, self.advance, force_n, settle_s)

    # -- actuators (servos) ------------------------------------------------------------------
    def command_position(self, joint: str, position: float) -> None:
        self.servos.command_position(joint, position)

    def command_positions(self, joints: list[str], positions: list[float]) -> None:
        self.servos.command_positions(joints, positions)

    def command_velocity(self, joint: str, velocity: float) -> None:
        self.servos.command_velocity(joint, velocity)

    def hold(self, joint: str) -> None:
        self.servos.hold(joint)

    def position(self, joint: str) -> float:
        return self.servos.position(joint)

    def velocity(self, joint: str) -> float:
        return self.servos.velocity(joint)

    def effort(self, joint: str) -> float:
        return self.servos.effort(joint)

    def max_velocity(self, joint: str) -> float:
        return self.servos.max_velocity(joint)

    def limits(self, joint: str) -> tuple[float, float]:
        return self.servos.limits(joint)

    def set_joint_state(self, joint: str, position: float, velocity: float = 0.0) -> None:
        self.servos.set_joint_state(joint, position, velocity)

    # -- end effectors -----------------------------------------------------------------------
    def ee_point(self, arm: str, which: str) -> np.ndarray:
        return self.end_effectors.ee_point(arm, which)

    def limit_switch(self, arm: str) -> bool:
        return self.end_effectors.limit_switch(arm)

    def load_rivet(self, arm: str, side: str) -> bool:
        return self.end_effectors.load_rivet(arm, side)

    def rivet_loaded(self, arm: str, side: str) -> bool:
        return self.end_effectors.rivet_loaded(arm, side)

    def fire_rivet(self, arm: str, side: str) -> RivetShot:
        return self.end_effectors.fire_rivet(arm, side)

    def holding(self, arm: str) -> str | None:
        return self.end_effectors.holding(arm)

    # -- ground truth ------------------------------------------------------------------------
    def body_pose(self, body: str) -> tuple[np.ndarray, np.ndarray]:
        return self.truth.body_pose(body)

    def site_position(self, site: str) -> np.ndarray:
        return self.truth.site_position(site)

    def tower_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.truth.tower_pose()

    def joint_position_world(self, joint_id: str) -> np.ndarray:
        return self.truth.joint_position_world(joint_id)

    def part(self, name: str) -> PartInfo:
        return self.truth.part(name)

    def part_state(self, name: str) -> str:
        return self.truth.part_state(name)

    def placement(self, release: Release) -> Placement:
        return self.truth.placement(release)

    def dispenser_count(self, dispenser: str) -> int:
        return self.truth.dispenser_count(dispenser)

    def next_part(self, dispenser: str) -> str | None:
        return self.truth.next_part(dispenser)

    # -- staging (tests, data generation, pictures) ------------------------------------------
    def place_part(self, name: str, position: np.ndarray, rotation: np.ndarray) -> None:
        self.staging.place_part(name, position, rotation)

    def place_in_view(self, part: str, camera: str, distance: float = 0.45) -> None:
        self.staging.place_in_view(part, camera, distance)

    def pose_arm(self, arm: str, joints: np.ndarray) -> None:
        self.staging.pose_arm(arm, joints)

    def seat_in_grasp(self, part: str, arm: str, roll: float = 0.0, slide: float = 0.0) -> None:
        self.staging.seat_in_grasp(part, arm, roll, slide)

    def member_pose(self, member: Member, kind: str) -> tuple[np.ndarray, np.ndarray]:
        return self.staging.member_pose(member, kind)

    def stage_member(self, member_id: str, part: str | None = None, rivet: bool = True) -> str:
        return self.staging.stage_member(member_id, part, rivet)

    def stage_bay(
        self,
        bay: int,
        skip_rivets: tuple[tuple[str, str], ...] = (),
        rivet_kinds: Mapping[tuple[str, str], str] | None = None,
    ) -> dict[str, str]:
        return self.staging.stage_bay(bay, skip_rivets, rivet_kinds)

    # -- cameras -----------------------------------------------------------------------------
    def renderer(self, width: int = 640, height: int = 480, antialias: bool = True) -> CameraRenderer:
        return self.cameras.renderer(width, height, antialias)

    def render(
        self,
        camera: str | mujoco.MjvCamera,
        width: int = 320,
        height: int = 240,
        depth: bool = True,
        segmentation: bool = True,
        antialias: bool = True,
        rgb: bool = True,
    ) -> Frame:
        return self.cameras.render(camera, width, height, depth, segmentation, antialias, rgb)

    def camera_pose(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        return self.cameras.camera_pose(camera)


__all__ = ["ModelCompileError", "Scene", "compile_model"]
