"""Coarse dispenser poses (paper §V.C.3): a joint configuration per dispenser from which the end
effector's camera sees the dispenser's AprilTag head-on, centred and near, so the fine approach
(vision's LocateTag) starts from a clear, well-conditioned view.

Reads the planning scene (config/planning/scene.yaml: arm bases, tool, joint limits, obstacles),
the vision configuration (config/vision/node.yaml: the EE camera's hand-eye extrinsic and where
each dispenser's tag is mounted), the tag size (config/vision/apriltag.yaml) and the mission (the
dispensers). Nothing here moves an arm or talks to ROS.

For a dispenser, :func:`search` puts the camera on a grid of views of the tag: at each distance
of :attr:`ViewSpec.distances`, tilted from the tag normal by up to :attr:`ViewSpec.max_tilt_deg`
towards several azimuths, and turned about its optical axis, the optical axis always through the
tag centre. A view counts when the tag's printed square (quiet zone included) lies, under the
pinhole model, at least :attr:`ViewSpec.margin` of the image size inside every border. Each view
is solved by the analytic IK (every branch within the joint limits); the configurations are ranked
by how long the arm needs to get there from the reference (its home, or the current coarse pose),
the slowest joint at its velocity limit deciding, with a penalty for tilt and for straying from
:attr:`ViewSpec.preferred_distance`. The best collision-free ones come back as
:class:`Candidate` s. Fails with :class:`NoCoarsePose` naming the dispenser when no view works.

The pinhole check does not see occlusions (the gripper, a rack upright) or how well the detector
copes; :func:`verify_in_twin` renders a candidate in the twin and runs the vision's detector on
it, and ``main`` keeps the first candidate that passes.

``python -m tlt_tools.coarse_pose_search [--ars ars_x] [--verify]`` prints the poses as the
``poses.dispensers`` YAML of config/ars/<ars>.yaml.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tlt_ars.planning.coarse_pose_transfer import NoCoarsePose, dispenser_tag_pose
from tlt_ars.planning.world import SceneConfig, build_scene, load_scene_config
from tlt_common.geometry.transforms import invert, pose_matrix
from tlt_common.geometry.ur10e import VELOCITY_LIMIT, IkFailed
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tag_mounts import TagMounting, printed_size
from tlt_vision.apriltag import TagConfig
from tlt_vision.node_config import VisionConfig, load_config, pose_of

DEFAULT_MISSION = "missions/one_bay.yaml"  # every mission shares the dispenser layout
ARMS = ("ars_x", "ars_y")
# The twin's D405 (config/twin/edu.yaml cameras.d405_fovy_deg) and its frame shape (run.yaml).
D405_FOVY_DEG = 58.0
D405_ASPECT = 4.0 / 3.0


@dataclass(frozen=True)
class ViewSpec:
    """What a good view of a tag is, and how finely to look for one."""

    distances: tuple[float, ...] = (0.30, 0.34, 0.38, 0.42)  # m, camera to tag centre
    preferred_distance: float = 0.34
    max_tilt_deg: float = 20.0  # optical axis from the tag normal
    tilt_steps: int = 3  # 0, max/2, max
    azimuths: int = 8  # directions of the tilt around the normal
    rolls: int = 24  # turns about the optical axis
    margin: float = 0.15  # fraction of the image size the tag keeps from each border
    fovy_deg: float = D405_FOVY_DEG
    aspect: float = D405_ASPECT  # width / height
    # Seconds of motion one degree of tilt, and one metre away from the preferred distance, cost.
    tilt_weight: float = 0.02
    distance_weight: float = 4.0


@dataclass(frozen=True)
class Candidate:
    """One coarse pose: joints, and the view of the tag the camera has from there."""

    q: np.ndarray
    distance: float  # m
    tilt_deg: float
    margin: float  # smallest gap between the tag and an image border, fraction of the image size
    cost: float  # s of motion from the reference, plus the view penalties

    def joints(self, digits: int = 3) -> list[float]:
        return [round(float(v), digits) for v in self.q]


@dataclass
class Setup:
    """The configuration one search needs, loaded once."""

    scene: SceneConfig
    vision: VisionConfig
    tag: TagConfig
    mission: Any
    camera: str = "d405_a"

    @classmethod
    def load(
        cls,
        mission: str | Path = DEFAULT_MISSION,
        scene: SceneConfig | None = None,
        vision: VisionConfig | None = None,
        tag: TagConfig | None = None,
    ) -> Setup:
        return cls(
            scene or load_scene_config(),
            vision or load_config(),
            tag or TagConfig.load(),
            load_mission(mission),
        )

    @property
    def printed_size(self) -> float:
        """Side of the printed tag, quiet zone included (the black square is 8 of its 10 cells)."""
        return printed_size(self.tag.tag_side)

    def camera_name(self, arm: str) -> str:
        return f"{arm}/{self.camera}"

    def optical(self, arm: str) -> np.ndarray:
        """The camera's optical frame in the flange (a camera on the width slide at width 0)."""
        return pose_of(self.vision.raw["ee_cameras"][self.camera_name(arm)]["optical"])

    def tag_pose(self, dispenser: str) -> np.ndarray:
        """World pose of ``dispenser``'s tag (x right, y up as printed, z out of the face), where the
        twin mounts it: the shared rule (:func:`tlt_common.mission.tag_mounts.tag_mount`)."""
        mounting = TagMounting(self.vision.raw["tag_mount"], self.tag.tag_side)
        return dispenser_tag_pose(self.scene, self.mission, mounting, dispenser)


def _rot_axis(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def camera_views(tag_pose: np.ndarray, spec: ViewSpec) -> Iterable[tuple[np.ndarray, float, float]]:
    """Camera poses (optical frame in the world) looking at the tag centre: (pose, distance, tilt deg)."""
    centre, r = tag_pose[:3, 3], tag_pose[:3, :3]
    normal = r[:, 2]
    tilts = np.linspace(0.0, spec.max_tilt_deg, spec.tilt_steps) if spec.tilt_steps > 1 else [0.0]
    for tilt in tilts:
        azimuths = [0.0] if tilt == 0 else np.linspace(0, 2 * math.pi, spec.azimuths, endpoint=False)
        for az in azimuths:
            axis = r @ np.array([math.cos(az), math.sin(az), 0.0])
            direction = _rot_axis(axis, math.radians(tilt)) @ normal  # tag centre -> camera
            z = -direction
            helper = r[:, 0] if abs(float(np.dot(r[:, 0], z))) < 0.9 else r[:, 1]
            x0 = helper - np.dot(helper, z) * z
            x0 /= np.linalg.norm(x0)
            for roll in np.linspace(0, 2 * math.pi, spec.rolls, endpoint=False):
                x = _rot_axis(z, roll) @ x0
                rot = np.column_stack([x, np.cross(z, x), z])
                for d in spec.distances:
                    yield pose_matrix(centre + d * direction, rot), float(d), float(tilt)


def image_margin(camera: np.ndarray, tag_pose: np.ndarray, side: float, spec: ViewSpec) -> float:
    """Smallest gap between the tag's printed square (side ``side``) and an image border, as a
    fraction of the image's width or height (negative: outside; -inf: behind the camera)."""
    h = side / 2
    corners = np.array([[-h, h, 0, 1], [h, h, 0, 1], [h, -h, 0, 1], [-h, -h, 0, 1]], dtype=float)
    pts = (invert(camera) @ tag_pose @ corners.T)[:3]
    if np.any(pts[2] <= 1e-6):
        return -math.inf
    tan_y = math.tan(math.radians(spec.fovy_deg) / 2)
    u = 0.5 + pts[0] / pts[2] / (2 * tan_y * spec.aspect)  # fraction of the width
    v = 0.5 + pts[1] / pts[2] / (2 * tan_y)
    return float(min(u.min(), v.min(), 1 - u.max(), 1 - v.max()))


def search(
    setup: Setup,
    arm: str,
    dispenser: str,
    *,
    reference: Sequence[float] | None = None,
    other_arm_q: Sequence[float] | None = None,
    spec: ViewSpec | None = None,
    count: int = 5,
) -> list[Candidate]:
    """The ``count`` best collision-free configurations of ``arm`` viewing ``dispenser``'s tag,
    best first. ``reference`` (default: the arm's home) is where the motion cost is measured from;
    ``other_arm_q`` places the other arm (default: its home). Raises NoCoarsePose."""
    spec = spec or ViewSpec()
    cfg = setup.scene
    if dispenser not in setup.mission.dispensers:
        raise NoCoarsePose(f"{arm}: no dispenser {dispenser!r} in the mission")
    kin = cfg.kinematics(arm)
    ref = cfg.home(arm) if reference is None else np.asarray(reference, dtype=float)
    to_tool = invert(setup.optical(arm)) @ kin.tool
    tag = setup.tag_pose(dispenser)
    vel = np.asarray(VELOCITY_LIMIT)
    ranked: list[tuple[float, np.ndarray, float, float, float]] = []
    views = 0
    for cam, d, tilt in camera_views(tag, spec):
        margin = image_margin(cam, tag, setup.printed_size, spec)
        if margin < spec.margin:
            continue
        views += 1
        try:
            qs = kin.inverse(cam @ to_tool, ref)
        except IkFailed:
            continue
        penalty = spec.tilt_weight * tilt + spec.distance_weight * abs(d - spec.preferred_distance)
        for q in qs:
            ranked.append((float(np.max(np.abs(q - ref) / vel)) + penalty, q, d, tilt, margin))
    if not ranked:
        raise NoCoarsePose(
            f"{arm}: no configuration within the joint limits puts its camera at any of {views} views of "
            f"{dispenser}'s tag"
        )
    collision = build_scene(cfg, arm, setup.mission, other_arm_q=other_arm_q)
    out: list[Candidate] = []
    ranked.sort(key=lambda c: c[0])
    for cost, q, d, tilt, margin in ranked:
        if any(np.max(np.abs(q - c.q)) < 0.05 for c in out) or collision.in_collision(q):
            continue
        out.append(Candidate(q, d, tilt, margin, cost))
        if len(out) >= count:
            break
    if not out:
        raise NoCoarsePose(
            f"{arm}: every one of {len(ranked)} configurations viewing {dispenser}'s tag collides"
        )
    return out


@dataclass(frozen=True)
class TwinCheck:
    """What the twin's camera saw from a candidate at one frame size."""

    size: tuple[int, int]
    found: bool
    reason: str
    margin: float  # smallest gap between the detected corners and a border, fraction of the size
    position_error: float  # m, estimated tag centre against the tag's pose (world)
    angle_error_deg: float

    def good(self, margin: float, position: float = 0.003, angle_deg: float = 1.5) -> bool:
        """Found, at least ``margin`` inside every border, and located to ``position`` m and
        ``angle_deg`` (what the fine approach relies on)."""
        return (
            self.found
            and self.margin >= margin
            and self.position_error <= position
            and self.angle_error_deg <= angle_deg
        )


def verify_in_twin(
    twin: Any,
    setup: Setup,
    arm: str,
    dispenser: str,
    q: Sequence[float],
    sizes: Sequence[tuple[int, int]] = ((320, 240), (640, 480)),
) -> list[TwinCheck]:
    """Put ``arm`` at ``q`` in ``twin`` (a ``tlt_sim.model.scene.Scene``), render its camera at each
    size and locate the dispenser's tag as LocateTag does; the pose found is compared with
    :meth:`Setup.tag_pose` through the vision's camera extrinsic."""
    from tlt_sim.model import names

    from tlt_vision.apriltag import TagLocator, dispenser_tag_ids

    for joint, value in zip(names.arm_joints(arm), q, strict=True):
        twin.set_joint_state(joint, float(value))
    twin.step(1)
    tag_id = dispenser_tag_ids(list(setup.mission.dispensers))[dispenser]
    locator = TagLocator(setup.tag)
    cam_world = setup.scene.kinematics(arm).base @ setup.scene.kinematics(arm).flange(q) @ setup.optical(arm)
    truth = setup.tag_pose(dispenser)
    out = []
    for w, h in sizes:
        frame = twin.render(setup.camera_name(arm), w, h, depth=False, segmentation=False)
        i = frame.intrinsics
        k = np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
        result = locator.locate(frame.rgb, tag_id, k)
        if result.pose is None or not result.found:
            out.append(TwinCheck((w, h), False, result.reason, math.nan, math.nan, math.nan))
            continue
        c = result.pose.corners
        margin = float(
            min(c[:, 0].min() / w, c[:, 1].min() / h, 1 - c[:, 0].max() / w, 1 - c[:, 1].max() / h)
        )
        seen = cam_world @ pose_matrix(result.pose.translation, result.pose.rotation)
        dp = float(np.linalg.norm(seen[:3, 3] - truth[:3, 3]))
        rel = seen[:3, :3].T @ truth[:3, :3]
        angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1) / 2))))
        out.append(TwinCheck((w, h), True, "", margin, dp, angle))
    return out


def _format(value: list[float]) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in value) + "]"


def main(argv: list[str] | None = None) -> int:
    """Print coarse dispenser poses as ``poses.dispensers`` YAML; 1 when a dispenser has none."""
    parser = argparse.ArgumentParser(
        prog="python -m tlt_tools.coarse_pose_search",
        description="Find coarse dispenser poses from which the EE camera sees the dispenser's tag well.",
    )
    parser.add_argument("--ars", choices=ARMS, action="append", help="arm (repeatable; default both)")
    parser.add_argument(
        "--dispenser", action="append", help="only these dispensers (default: the ARS config's)"
    )
    parser.add_argument("--mission", default=DEFAULT_MISSION)
    parser.add_argument("--margin", type=float, default=ViewSpec.margin, help="image fraction kept clear")
    parser.add_argument(
        "--max-tilt", type=float, default=ViewSpec.max_tilt_deg, help="deg from the tag normal"
    )
    parser.add_argument(
        "--near-current",
        action="store_true",
        help="rank by the motion from the ARS file's present pose instead of from home",
    )
    parser.add_argument(
        "--verify",
        action="store_true",
        help="render each candidate in the twin; keep the first the detector passes",
    )
    args = parser.parse_args(argv)

    from tlt_ars.config import default_config_path
    from tlt_common.config_schema import load_yaml

    setup = Setup.load(args.mission)
    spec = ViewSpec(margin=args.margin, max_tilt_deg=args.max_tilt)
    twin = None
    if args.verify:
        import tempfile

        from tlt_sim.model.scene import Scene

        twin = Scene(mission=args.mission, out_dir=Path(tempfile.mkdtemp(prefix="coarse_pose_")))
    failed = 0
    try:
        for arm in args.ars or ARMS:
            configured = load_yaml(default_config_path(arm))["poses"]["dispensers"]
            wanted = args.dispenser or list(configured)
            print(f"# {arm}")
            print("dispensers:")
            for dispenser in wanted:
                try:
                    reference = None
                    if args.near_current and "joints" in configured.get(dispenser, {}):
                        reference = configured[dispenser]["joints"]
                    cands = search(setup, arm, dispenser, reference=reference, spec=spec, count=8)
                except NoCoarsePose as exc:
                    print(f"  # {dispenser}: {exc}")
                    failed += 1
                    continue
                chosen, note = None, ""
                for c in cands:
                    if twin is None:
                        chosen = c
                        break
                    checks = verify_in_twin(twin, setup, arm, dispenser, c.q)
                    if all(ch.good(spec.margin) for ch in checks):
                        chosen = c
                        note = "; twin: " + ", ".join(
                            f"{ch.size[0]}x{ch.size[1]} {1000 * ch.position_error:.1f} mm "
                            f"{ch.angle_error_deg:.2f} deg"
                            for ch in checks
                        )
                        break
                if chosen is None:
                    print(f"  # {dispenser}: no candidate passed the twin's detector")
                    failed += 1
                    continue
                print(
                    f"  # {chosen.distance:.2f} m, {chosen.tilt_deg:.0f} deg off the normal, "
                    f"margin {chosen.margin:.2f}{note}"
                )
                print(f"  {dispenser}: {{joints: {_format(chosen.joints())}}}")
    finally:
        if twin is not None:
            twin.close()
    return 1 if failed else 0


__all__ = [
    "Candidate",
    "NoCoarsePose",
    "Setup",
    "TwinCheck",
    "ViewSpec",
    "camera_views",
    "image_margin",
    "main",
    "search",
    "verify_in_twin",
]

if __name__ == "__main__":
    sys.exit(main())
