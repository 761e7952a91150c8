"""The vision system's transform tree: where each camera is in the world, from joint states.

Reads joint positions (with their ROS-time stamps) as the drivers publish them, and the fixed
extrinsics of ``config/vision/node.yaml``:

* a lifter ZED: world <- hinge frame (fixed) <- rotation about the hinge's z by the camera-mount
  joint (``/camera_mounts/joint_states``, e.g. ``camera_mount_1``) <- optical frame (fixed);
* an EE D405: world <- arm base (fixed) <- UR10e flange by the published DH forward kinematics of
  the six joints (``/ur_x/joint_states``, ``ur_x_shoulder_pan_joint`` ...;
  :class:`tlt_common.geometry.ur10e.Ur10eKinematics`) <- slide along flange x by the EE width
  joint for a camera on gripper b (``/ee_x/state``, ``ee_x_width``) <- optical frame (fixed).

Optical frames are ROS camera frames (x right, y down, z forward). :meth:`CameraRig.camera_pose`
answers the 4x4 pose of a camera at a ROS time (each joint interpolated between its states either
side of that time, :class:`JointStates`), or raises :class:`FrameUnavailable` saying which
joint state is missing or how old it is; it never guesses.
"""

from __future__ import annotations

import bisect
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tlt_common import ros_names
from tlt_common.geometry.transforms import pose_matrix, rot_z
from tlt_common.geometry.ur10e import JOINT_NAMES, Ur10eKinematics
from tlt_vision.node_config import VisionConfig, pose_of


class FrameUnavailable(RuntimeError):
    """A camera pose cannot be given now; the message says why."""


def arm_joint_names(arm: str) -> list[str]:
    """The UR driver's joint names of ``arm`` (``ars_x`` -> ``ur_x_shoulder_pan_joint`` ...)."""
    component = ros_names.ur(arm)
    return [f"{component}_{j}_joint" for j in JOINT_NAMES]


def width_joint_name(arm: str) -> str:
    """The EE driver's width joint of ``arm`` (``ars_x`` -> ``ee_x_width``)."""
    return f"{ros_names.ee(arm)}_width"


def grasp_joint_names(arm: str) -> dict[str, str]:
    """The EE driver's grasp joints of ``arm`` by jaw side (``ars_x`` -> a: ``ee_x_grasp_left``,
    b: ``ee_x_grasp_right``), as the twin binds them."""
    ee = ros_names.ee(arm)
    return {"a": f"{ee}_grasp_left", "b": f"{ee}_grasp_right"}


class EeState(NamedTuple):
    """An end effector at one time: its flange's world pose (4x4), width (m) and jaws by side (rad)."""

    flange: np.ndarray
    width: float
    jaws: dict[str, float]


class JointStates:
    """Every joint's recent positions with their stamps (ROS time, s); thread-safe.

    A camera's pose is wanted at its frame's stamp, and the arm carrying it may have moved since:
    :meth:`get` interpolates each joint between the states stamped either side of the time asked
    for, so a frame is placed where its camera was when it was taken, not where the arm is when
    the frame is read. ``history`` states are kept per joint (50 Hz joint states: 5 s)."""

    def __init__(self, history: int = 256) -> None:
        self._lock = threading.Lock()
        self._history = history
        self._stamps: dict[str, list[float]] = {}
        self._values: dict[str, list[float]] = {}

    def update(self, names: Sequence[str], positions: Sequence[float], stamp: float) -> None:
        stamp = float(stamp)
        with self._lock:
            for n, p in zip(names, positions, strict=False):
                stamps, values = self._stamps.setdefault(n, []), self._values.setdefault(n, [])
                i = bisect.bisect_left(stamps, stamp)
                if i < len(stamps) and stamps[i] == stamp:
                    values[i] = float(p)
                    continue
                stamps.insert(i, stamp)
                values.insert(i, float(p))
                if len(stamps) > self._history:
                    del stamps[0], values[0]

    def get(self, names: Sequence[str], at: float, max_age: float) -> list[float]:
        """Positions of ``names`` at ROS time ``at``: interpolated between the states either side
        of it when both lie within ``max_age`` of it, else the state nearest ``at``;
        FrameUnavailable when that is further than ``max_age`` from it."""
        with self._lock:
            return [self._at(n, at, max_age) for n in names]

    def unheard(self, names: Sequence[str]) -> list[str]:
        """Those of ``names`` no state has been heard of yet, in their order."""
        with self._lock:
            return [n for n in names if n not in self._values]

    def latest(self, names: Sequence[str]) -> list[float]:
        """The newest position of each of ``names``; FrameUnavailable for one never heard of."""
        with self._lock:
            unheard = [n for n in names if n not in self._values]
            if unheard:
                raise FrameUnavailable(f"no joint state for {unheard[0]} yet")
            return [self._values[n][-1] for n in names]

    def _at(self, name: str, at: float, max_age: float) -> float:
        stamps = self._stamps.get(name)
        if not stamps:
            raise FrameUnavailable(f"no joint state for {name} yet")
        values = self._values[name]
        i = bisect.bisect_left(stamps, at)
        if 0 < i < len(stamps) and max(at - stamps[i - 1], stamps[i] - at) <= max_age:
            t0, t1 = stamps[i - 1], stamps[i]
            return values[i - 1] + (at - t0) / (t1 - t0) * (values[i] - values[i - 1])
        # Before the first state, after the last, or across a silence of the driver longer than
        # the age limit (what happened there is not known): the nearest state, if near enough.
        near = min((k for k in (i - 1, i) if 0 <= k < len(stamps)), key=lambda k: abs(at - stamps[k]))
        gap = abs(at - stamps[near])
        if gap > max_age:
            raise FrameUnavailable(
                f"joint state of {name} is {gap:.2f} s from the frame (limit {max_age:.2f} s)"
            )
        return values[near]


@dataclass(frozen=True)
class LifterCamera:
    name: str
    joint: str
    hinge: np.ndarray  # 4x4, world
    optical: np.ndarray  # 4x4, hinge frame

    def pose(self, angle: float) -> np.ndarray:
        return self.hinge @ pose_matrix((0.0, 0.0, 0.0), rot_z(angle)) @ self.optical


@dataclass(frozen=True)
class EeCamera:
    name: str
    arm: str
    kinematics: Ur10eKinematics  # base = the arm's base in the world, tool = identity (flange)
    on_width_slide: bool
    optical: np.ndarray  # 4x4, flange frame at width 0
    gun_name: str
    gun_position: np.ndarray  # (3,) flange frame at width 0

    def slide(self, width: float) -> np.ndarray:
        return pose_matrix((width if self.on_width_slide else 0.0, 0.0, 0.0))

    def pose(self, q: Sequence[float], width: float = 0.0) -> np.ndarray:
        return self.kinematics.forward(q) @ self.slide(width) @ self.optical

    def gun_in_camera(self) -> np.ndarray:
        """The rivet gun's muzzle in this camera's optical frame (both ride the same gripper)."""
        p = np.append(self.gun_position, 1.0)
        return (np.linalg.inv(self.optical) @ p)[:3]


class CameraRig:
    """Every configured camera and the joint states that place it."""

    def __init__(self, config: VisionConfig, joints: JointStates | None = None) -> None:
        raw = config.raw
        self.joints = joints or JointStates()
        self.max_age = raw["timeouts"]["joint_state_age_s"]
        self.lifter: dict[str, LifterCamera] = {
            name: LifterCamera(name, c["joint"], pose_of(c["hinge"]), pose_of(c["optical"]))
            for name, c in raw["lifter_cameras"].items()
        }
        self.ee: dict[str, EeCamera] = {
            name: EeCamera(
                name,
                c["arm"],
                Ur10eKinematics(base=pose_of(raw["arms"][c["arm"]]["base"])),
                c["on_width_slide"],
                pose_of(c["optical"]),
                c["rivet_gun"]["name"],
                np.asarray(c["rivet_gun"]["position"], dtype=float),
            )
            for name, c in raw["ee_cameras"].items()
        }

    def joint_names(self, camera: str) -> list[str]:
        """The joints whose states place ``camera``."""
        if camera in self.lifter:
            return [self.lifter[camera].joint]
        cam = self.ee[camera]
        return arm_joint_names(cam.arm) + ([width_joint_name(cam.arm)] if cam.on_width_slide else [])

    def needed_joints(self) -> list[str]:
        """Every joint a request may need: those placing each camera, and each arm's end effector
        (width and jaws, :meth:`end_effector`)."""
        names = [n for camera in (*self.lifter, *self.ee) for n in self.joint_names(camera)]
        for arm in self.arms:
            names += [width_joint_name(arm), *grasp_joint_names(arm).values()]
        return list(dict.fromkeys(names))

    def not_ready(self) -> str:
        """Why a request could meet a joint never heard of ('' when it cannot): a driver not up,
        or this node's subscription not matched to it yet, though the drivers' other listeners
        (the CRS) may hear it already."""
        unheard = self.joints.unheard(self.needed_joints())
        if not unheard:
            return ""
        more = f" and {len(unheard) - 3} more" if len(unheard) > 3 else ""
        return f"no joint state yet for {', '.join(unheard[:3])}{more}"

    def pose_from_joints(self, camera: str, positions: Mapping[str, float]) -> np.ndarray:
        """Pose (4x4, world) of ``camera`` for the given joint positions (driver names)."""
        if camera in self.lifter:
            cam = self.lifter[camera]
            return cam.pose(positions[cam.joint])
        if camera not in self.ee:
            raise FrameUnavailable(f"unknown camera {camera!r}")
        ee = self.ee[camera]
        q = [positions[n] for n in arm_joint_names(ee.arm)]
        width = positions[width_joint_name(ee.arm)] if ee.on_width_slide else 0.0
        return ee.pose(q, width)

    def camera_pose(self, camera: str, at: float) -> np.ndarray:
        """Pose (4x4, world) of ``camera`` at ROS time ``at`` from the joint states about then."""
        if camera not in self.lifter and camera not in self.ee:
            raise FrameUnavailable(f"unknown camera {camera!r}")
        names = self.joint_names(camera)
        values = self.joints.get(names, at, self.max_age)
        return self.pose_from_joints(camera, dict(zip(names, values, strict=True)))

    def end_effector(self, arm: str, at: float) -> EeState:
        """``arm``'s end effector at ROS time ``at`` from the joint states about then."""
        kinematics = next((c.kinematics for c in self.ee.values() if c.arm == arm), None)
        if kinematics is None:
            raise FrameUnavailable(f"no EE camera configured on {arm!r}, so no forward kinematics for it")
        jaws = grasp_joint_names(arm)
        names = [*arm_joint_names(arm), width_joint_name(arm), *jaws.values()]
        values = self.joints.get(names, at, self.max_age)
        angles = {side: float(v) for side, v in zip(jaws, values[7:], strict=True)}
        return EeState(kinematics.forward(values[:6]), float(values[6]), angles)

    @property
    def arms(self) -> list[str]:
        return sorted({c.arm for c in self.ee.values()})

    def tool_pose(self, camera: str, at: float, tool: np.ndarray) -> np.ndarray:
        """World pose of the tool frame (``tool`` in the flange) of the arm carrying EE ``camera``."""
        ee = self.ee[camera]
        q = self.joints.get(arm_joint_names(ee.arm), at, self.max_age)
        return ee.kinematics.forward(q) @ tool


__all__ = [
    "CameraRig",
    "EeCamera",
    "EeState",
    "FrameUnavailable",
    "JointStates",
    "LifterCamera",
    "arm_joint_names",
    "grasp_joint_names",
    "width_joint_name",
]
