"""The twin renderer of the vision training images: one MuJoCo twin scene, built once, that
:meth:`TwinRenderer.sample` sets up and renders for image ``i`` (RGB-D, instance masks, classes,
poses); :mod:`tlt_tools.vision_training.render_dataset` writes them.

Each image is drawn from its own generator seeded by ``(seed, image index)``, so a seed gives the
same images whatever ``--count`` is, and it sets everything it randomises, so it does not depend on
the images before it:

* **the scene** (``scenes`` weights in the settings): ``held`` - one strut or cross frame across the
  view 0.3-1.8 m ahead, tilted and turned, as a ZED or an EE D405 inspects a held part;
  ``presented`` - a strut seated in an ARS's grasp (the arm near its inspection pose, the jaws and
  rivet guns beside the tube and fittings, as the CRS's ZED sees a part presented for inspection)
  seen from 0.4-1.6 m, aimed anywhere along it; ``scatter``
  - two to five parts at random rotations (uniform on SO(3)) 0.4-2.5 m ahead anywhere in the view;
  ``bay`` - bay 1 built (every member at its mission place, from parts drawn at random), seen from
  0.8-2.5 m or from 0.3-0.6 m at one of its joints; ``feeder`` - a rivet feeder's tray from
  0.25-0.6 m above it, as the D405 picking a rivet. Whatever else is in view (the racks with their
  parts, the payload frame, the machine) is in the image and labelled as well.
* **the camera**: the ZED's (70 deg vertical field of view) or the D405's (58 deg) optics, chosen by
  the viewing distance, at a random place and orientation (roll too), looking into the scene.
* **appearance**: the part classes' material colours (brightness 0.6-1.2 x and a tint around the
  twin's colours), specularity and shininess, the floor's grey, the light's direction, position and
  intensity and the headlight's. The twin has no other textures to vary.
* **defects**: the scene is built with a share of each strut dispenser's parts defective (a missing
  end fitting, either end, or a tube bent by 3-15 deg; the twin's own defect model,
  :mod:`tlt_sim.model.scenario`), and each strut put in view is a defective one with probability
  ``--defective-fraction``. Every instance of a defective part (its tube and remaining fitting)
  carries the defect kind (``missing_end_fitting`` or ``bent_tube``) in ``defects``; the defective
  parts, with the end and bend, are listed in the index's settings.

Instances are the twin's (:class:`tlt_sim.model.cameras.GeomLabels`, as
:class:`tlt_vision.segmentation_source.TwinLabels` uses them): a strut's tube and each end fitting,
each side and each corner joint of a cross frame, a rivet. Only those of the vision classes with at
least ``min_pixels`` visible pixels are kept. Masks and depth come from an exact (not
multisampled) render (``Scene.render``); RGB from the multisampled render the detectors see
(``--no-antialias``: plain). Depth is metres along the optical axis, 0 where nothing was hit.

**Poses** (``poses[i]``, 4x4): the transform from the CAD model's frame
(:mod:`tlt_vision.cad.models`: origin at the part's centre, z along a strut's axis, a cross frame in
its xy plane) to the camera's optical frame (x right, y down, z forward; ``intrinsics`` projects it):

* ``strut_tube``: the ``strut_tube/<vertical|diagonal>`` model at the middle of the strut, z along
  the strut from end a to end b, x and y the strut body's. For a bent tube this is the pose of the
  straight tube it should be (the strut body's, as the twin's tests fit it), not of either half.
* ``end_fitting``, ``corner_joint``, ``rivet``: the pose of the twin's geom, which is the model's
  (cylinders along their geom z; a corner cube turned with its frame); a bent strut's fitting b
  lies along the bent half.
* ``cross_frame`` (each side is its own instance): the pose of the whole ``cross_frame`` model
  (the square's centre, the frame's own axes), the same for the four sides of one frame; the
  pipeline merges the sides before it estimates that pose.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.config_schema import load_yaml
from tlt_tools.vision_training.dataset import Sample
from tlt_vision.cad.views import random_rotation
from tlt_vision.segmentation.config import CLASSES

REPO_ROOT = Path(__file__).resolve().parents[3]
DEFAULT_MISSION = REPO_ROOT / "missions" / "one_bay.yaml"
ZED, D405 = "zed_1", "ars_x/d405_a"  # the cameras whose optics (field of view) an image uses
ARMS = ("ars_x", "ars_y")
SCENES = ("held", "presented", "scatter", "bay", "feeder")


@dataclass(frozen=True)
class RenderSettings:
    """Everything that decides the images; written into the index's ``settings``."""

    width: int = 640
    height: int = 480
    seed: int = 0
    mission: str = str(DEFAULT_MISSION)
    defective_fraction: float = 0.2
    min_pixels: int = 40  # fewer visible pixels: the instance is dropped
    antialias: bool = True
    scenes: dict[str, float] = field(
        default_factory=lambda: {"held": 0.2, "presented": 0.15, "scatter": 0.25, "bay": 0.3, "feeder": 0.1}
    )
    presented_jitter_rad: float = 0.12  # each arm joint about its inspection pose (normal, sd)
    close_below: float = 0.7  # m: nearer views use the D405's optics, further ones the ZED's
    bend_deg: tuple[float, float] = (3.0, 15.0)  # range of a bent tube's kink
    # The twin's camera models (config/twin/cameras.yaml) the images are taken through; "" for the
    # exact render.
    cameras: str = ""
    # A preset of config/twin/lighting.yaml every image is lit by instead of the random lights
    # (lunar: a low, hard sun); "" for the random lights.
    lighting: str = ""


# -- geometry helpers ------------------------------------------------------------------------------
def look_at(position: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """Optical frame axes (columns x right, y down, z forward) of a camera at ``position`` looking
    at ``target``, turned by ``roll`` (rad) about its axis; the image's "up" is the world's z."""
    z = target - position
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-6:  # looking straight up or down: any right will do
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    return np.column_stack([c * x + s * y, -s * x + c * y, z])


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _frame_with_z(z: np.ndarray, spin: float) -> np.ndarray:
    """A rotation whose z axis is ``z``, turned by ``spin`` about it."""
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    base = np.column_stack([x, np.cross(z, x), z])
    return _axis_angle(z, spin) @ base


def _pose(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = rotation, translation
    return t


def inspection_joints() -> dict[str, np.ndarray]:
    """Each arm's ``poses.inspection`` joints (config/ars/<arm>.yaml), where it presents a part."""
    poses = {arm: load_yaml(REPO_ROOT / "config" / "ars" / f"{arm}.yaml")["poses"] for arm in ARMS}
    return {arm: np.asarray(p["inspection"]["joints"], dtype=float) for arm, p in poses.items()}


class RenderError(ValueError):
    """Settings the twin cannot render; the message says why."""


# -- the twin ----------------------------------------------------------------------------------
def defect_table(
    mission: Any, fraction: float, rng: np.random.Generator, bend_deg: tuple[float, float] = (3.0, 15.0)
) -> dict[str, Any]:
    """Which struts of each dispenser the scene builds defective: ``round(fraction x count)`` of
    them, at least one while ``fraction > 0`` and at least one good while ``fraction < 1``, so
    both kinds can be drawn; half missing an end fitting (either end), half with a bent tube."""
    from tlt_sim.model.scenario import Defect

    defects: dict[str, Defect] = {}
    if fraction <= 0:
        return defects
    for name, disp in mission.dispensers.items():
        if disp.part_kind not in ("vertical", "diagonal"):
            continue
        n = disp.count
        k = min(n, max(1, round(fraction * n)))
        if fraction < 1 and n > 1:
            k = min(k, n - 1)
        for index in sorted(rng.choice(n, size=k, replace=False).tolist()):
            if rng.random() < 0.5:
                defects[f"{name}/{index}"] = Defect("missing_end_fitting", str(rng.choice(["a", "b"])))
            else:
                defects[f"{name}/{index}"] = Defect("bent_tube", "b", float(rng.uniform(*bend_deg)))
    return defects


class TwinRenderer:
    """One twin scene built for rendering training images; :meth:`sample` makes image ``i``."""

    def __init__(self, settings: RenderSettings, out_dir: str | Path | None = None) -> None:
        from tlt_sim.model.scenario import Scenario
        from tlt_sim.model.scene import Scene

        from tlt_common.mission.schema import load_mission

        self.settings = settings
        self.sensors = None
        if settings.cameras:
            from tlt_sim.model.camera_sensor import load_camera_sensors

            self.sensors = load_camera_sensors(settings.cameras)
        self.lighting = None
        if settings.lighting:
            from tlt_sim.model.lighting import load_lighting

            self.lighting = load_lighting(name=settings.lighting)
        mission = load_mission(settings.mission)
        rng = np.random.default_rng([settings.seed, 0])
        table = defect_table(mission, settings.defective_fraction, rng, settings.bend_deg)
        scenario = Scenario(name="render_dataset", defects=table)
        self.scene = Scene(mission=settings.mission, scenario=scenario, out_dir=out_dir)
        self.defects = {part: asdict(d) for part, d in table.items()}
        m = self.scene.model
        limit = (m.vis.global_.offwidth, m.vis.global_.offheight)
        if settings.width > limit[0] or settings.height > limit[1]:
            self.scene.close()
            raise RenderError(
                f"{settings.width}x{settings.height} exceeds the twin's offscreen buffer "
                f"{limit[0]}x{limit[1]} (config/twin/edu.yaml)"
            )
        self.parts = self.scene.info.parts
        self.by_body = {p.body: p for p in self.parts.values()}
        self.struts = {
            kind: [p.name for p in self.parts.values() if p.kind == kind] for kind in ("vertical", "diagonal")
        }
        self.frames = [p.name for p in self.parts.values() if p.kind == "cross_frame"]
        self.feeders = [n for n, d in mission.dispensers.items() if d.part_kind == "rivet"]
        self._instances()
        # The twin's appearance, which every image varies from afresh.
        self._mats = {name: m.material(name).id for name in (*CLASSES, "floor") if self._has_mat(name)}
        self._mat_rgba = m.mat_rgba.copy()
        self._light = (m.light_pos.copy(), m.light_diffuse.copy())
        self._cam_ids = {c: m.camera(c).id for c in (ZED, D405)}
        self.scene.reset()
        bay = [self.scene.joint_position_world(j) for j in mission.joints if j.startswith(("bay0/", "bay1/"))]
        self.bay_joints = np.array(bay)
        self.centre = self.bay_joints.mean(axis=0)
        self.inspection_joints = inspection_joints()

    def _has_mat(self, name: str) -> bool:
        try:
            self.scene.model.material(name)
        except KeyError:
            return False
        return True

    def _instances(self) -> None:
        """How to pose each labelled instance of a vision class (see the module docstring)."""
        from tlt_sim.model.cameras import GeomLabels

        m = self.scene.model
        labels = GeomLabels(m)
        w = self.scene.mission.bay_width
        self.recipes: dict[int, tuple[str, int, np.ndarray | None]] = {}  # id -> (how, id, offset)
        for g in range(m.ngeom):
            i = int(labels.geom_instance[g])
            cls = labels.classes[i]
            if cls not in CLASSES or i in self.recipes:
                continue
            body = int(m.geom_bodyid[g])
            if cls == "strut_tube":
                part = self.by_body[m.body(body).name]
                self.recipes[i] = ("body", body, np.array([0.0, 0.0, part.length / 2]))
            elif cls == "cross_frame":
                self.recipes[i] = ("body", body, np.array([w / 2, w / 2, 0.0]))
            else:
                self.recipes[i] = ("geom", g, None)

    def pose_in_world(self, instance: int) -> tuple[np.ndarray, np.ndarray]:
        how, k, offset = self.recipes[instance]
        d = self.scene.data
        if how == "body":
            rot = d.xmat[k].reshape(3, 3).copy()
            return d.xpos[k] + rot @ offset, rot
        return d.geom_xpos[k].copy(), d.geom_xmat[k].reshape(3, 3).copy()

    # -- randomisation ---------------------------------------------------------------------------
    def _appearance(self, rng: np.random.Generator) -> None:
        m = self.scene.model
        for name, k in self._mats.items():
            base = self._mat_rgba[k, :3]
            if name == "floor":
                rgb = np.full(3, rng.uniform(0.45, 1.0))
            else:
                rgb = base * rng.uniform(0.6, 1.2) + rng.normal(0.0, 0.06, 3)
                m.mat_specular[k] = rng.uniform(0.1, 0.8)
                m.mat_shininess[k] = rng.uniform(0.1, 0.9)
            m.mat_rgba[k, :3] = np.clip(rgb, 0.02, 1.0)
        pos, diffuse = self._light
        m.light_pos[:] = pos + rng.uniform([-3, -3, -2], [3, 3, 1], size=pos.shape)
        tilt, azimuth = rng.uniform(0, math.radians(60)), rng.uniform(0, 2 * math.pi)
        direction = [math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), -math.cos(tilt)]
        m.light_dir[:] = direction
        m.light_diffuse[:] = np.clip(diffuse * rng.uniform(0.4, 1.5) + rng.normal(0, 0.03, 3), 0, 1)
        m.light_ambient[:] = rng.uniform(0.0, 0.2)
        m.vis.headlight.ambient[:] = rng.uniform(0.1, 0.45)
        m.vis.headlight.diffuse[:] = rng.uniform(0.2, 0.7)
        if self.lighting is not None:
            from tlt_sim.model.lighting import apply_lighting

            apply_lighting(m, self.lighting)

    def _place_camera(self, name: str, position: np.ndarray, rotation: np.ndarray) -> None:
        """Move camera ``name`` (its optics) to a world pose, in its body's frame."""
        import mujoco

        from tlt_common.geometry.transforms import rotation_to_mujoco_quat

        m, d = self.scene.model, self.scene.data
        cid = self._cam_ids[name]
        body = m.cam_bodyid[cid]
        b_pos, b_rot = d.xpos[body], d.xmat[body].reshape(3, 3)
        mj_rot = rotation @ np.diag([1.0, -1.0, -1.0])  # MuJoCo cameras look along -z, y up
        m.cam_pos[cid] = b_rot.T @ (position - b_pos)
        m.cam_quat[cid] = rotation_to_mujoco_quat(b_rot.T @ mj_rot)
        mujoco.mj_forward(m, d)

    def _camera_around(self, rng: np.random.Generator, target: np.ndarray, near: float, far: float):
        """A camera ``near``-``far`` m from ``target`` (above the floor), looking near it."""
        for _ in range(20):
            distance = rng.uniform(near, far)
            el, az = rng.uniform(math.radians(-10), math.radians(55)), rng.uniform(0, 2 * math.pi)
            pos = target + distance * np.array(
                [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
            )
            if pos[2] > 0.15:
                break
        aim = target + rng.normal(0.0, 0.08 * distance, 3)
        return pos, look_at(pos, aim, rng.normal(0.0, math.radians(10))), distance

    def _optics(self, distance: float) -> str:
        return D405 if distance < self.settings.close_below else ZED

    def _ray(self, name: str, rng: np.random.Generator, margin: float) -> np.ndarray:
        """A unit direction in the camera frame through a random pixel ``margin`` in from the edges."""
        fovy = math.radians(float(self.scene.model.cam_fovy[self._cam_ids[name]]))
        ty = math.tan(fovy / 2)
        tx = ty * self.settings.width / self.settings.height
        u, v = rng.uniform(-1 + margin, 1 - margin, 2)
        ray = np.array([u * tx, v * ty, 1.0])
        return ray / ray[2]

    def _pick(self, rng: np.random.Generator, kind: str, used: set[str]) -> str | None:
        """A part of ``kind`` not yet used; a strut is a defective one with the set's probability."""
        pool = [p for p in (self.frames if kind == "cross_frame" else self.struts[kind]) if p not in used]
        if not pool:
            return None
        if kind != "cross_frame":
            want = rng.random() < self.settings.defective_fraction
            same = [p for p in pool if (self.parts[p].defect is not None) == want]
            pool = same or pool
        part = pool[int(rng.integers(len(pool)))]
        used.add(part)
        return part

    def _put(self, part: str, centre: np.ndarray, rotation: np.ndarray) -> None:
        """Place ``part`` with its CAD model's centre at ``centre`` and its frame at ``rotation``."""
        info = self.parts[part]
        if info.kind == "cross_frame":
            half = np.array([info.length / 2, info.length / 2, 0.0])
        else:
            half = np.array([0.0, 0.0, info.length / 2])
        self.scene.place_part(part, centre - rotation @ half, rotation)

    def _held(self, rng: np.random.Generator) -> str:
        frame = rng.random() < 0.25
        distance = rng.uniform(0.6, 1.8) if frame else rng.uniform(0.3, 1.2)
        name = self._optics(distance)
        pos, rot, _ = self._camera_around(rng, self.centre, 0.8, 2.5)
        self._place_camera(name, pos, rot)
        centre = pos + rot @ (self._ray(name, rng, 0.5) * distance)
        if frame:
            normal = _axis_angle(rng.normal(size=3), rng.uniform(0, math.radians(40))) @ rot[:, 2]
            part = self._pick(rng, "cross_frame", set())
            self._put(part, centre, _frame_with_z(normal, rng.uniform(0, 2 * math.pi)))
        else:
            across = _axis_angle(rot[:, 2], rng.uniform(-math.pi / 2, math.pi / 2)) @ rot[:, 0]
            axis = _axis_angle(rot[:, 1], rng.uniform(-0.6, 0.6)) @ across
            part = self._pick(rng, str(rng.choice(["vertical", "diagonal"])), set())
            self._put(part, centre, _frame_with_z(axis, rng.uniform(0, 2 * math.pi)))
        return name

    def _presented(self, rng: np.random.Generator) -> str:
        arm = str(rng.choice(ARMS))
        joints = self.inspection_joints[arm]
        self.scene.pose_arm(arm, joints + rng.normal(0.0, self.settings.presented_jitter_rad, joints.size))
        part = self._pick(rng, str(rng.choice(["vertical", "diagonal"])), set())
        self.scene.seat_in_grasp(part, arm, rng.uniform(0, 2 * math.pi), rng.uniform(-0.02, 0.02))
        centre, axis = self.scene.assembly.grasp_line(arm)
        target = centre + axis * rng.uniform(-0.5, 0.5) * self.parts[part].length
        pos, rot, distance = self._camera_around(rng, target, 0.4, 1.6)
        name = self._optics(distance)
        self._place_camera(name, pos, rot)
        return name

    def _scatter(self, rng: np.random.Generator) -> str:
        pos, rot, _ = self._camera_around(rng, self.centre, 0.8, 2.5)
        name = self._optics(rng.uniform(0.4, 2.0))
        self._place_camera(name, pos, rot)
        used: set[str] = set()
        for k in range(int(rng.integers(2, 6))):
            strut = str(rng.choice(["vertical", "diagonal"]))
            kind = "cross_frame" if k == 0 and rng.random() < 0.4 else strut
            part = self._pick(rng, kind, used)
            if part is None:
                continue
            distance = rng.uniform(0.8 if kind == "cross_frame" else 0.4, 2.5)
            centre = pos + rot @ (self._ray(name, rng, 0.1) * distance)
            self._put(part, centre, random_rotation(rng))
        return name

    def _bay(self, rng: np.random.Generator) -> str:
        used: set[str] = set()
        for member in self.scene.mission.bay_members(1):
            part = self._pick(rng, self._member_kind(member), used)
            if part is None:
                continue
            position, rotation = self.scene.member_pose(member, self.parts[part].kind)
            self.scene.place_part(part, position, rotation)
        if rng.random() < 0.3:
            joint = self.bay_joints[int(rng.integers(len(self.bay_joints)))]
            pos, rot, distance = self._camera_around(rng, joint, 0.3, 0.6)
        else:
            pos, rot, distance = self._camera_around(rng, self.centre, 0.8, 2.5)
        name = self._optics(distance)
        self._place_camera(name, pos, rot)
        return name

    def _member_kind(self, member: Any) -> str:
        """A member's part kind: its dispenser's."""
        return self.scene.mission.dispensers[member.dispenser].part_kind

    def _feeder(self, rng: np.random.Generator) -> str:
        feeder = self.feeders[int(rng.integers(len(self.feeders)))]
        tray = self.scene.site_position(f"dispenser/{feeder}/pickup") - [0.0, 0.0, 0.01]
        distance = rng.uniform(0.25, 0.6)
        el, az = rng.uniform(math.radians(30), math.radians(85)), rng.uniform(0, 2 * math.pi)
        pos = tray + distance * np.array(
            [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
        )
        rot = look_at(pos, tray + rng.normal(0.0, 0.02, 3), rng.uniform(-math.pi, math.pi))
        self._place_camera(D405, pos, rot)
        return D405

    # -- one image -------------------------------------------------------------------------------
    def sample(self, index: int) -> tuple[Sample, str]:
        """Image ``index`` of the set and its scene kind; the same for the same seed and index."""
        s = self.settings
        rng = np.random.default_rng([s.seed, 1, index])
        self.scene.reset()
        self._appearance(rng)
        kinds = [k for k, w in s.scenes.items() if w > 0 and (k != "feeder" or self.feeders)]
        weights = np.array([s.scenes[k] for k in kinds])
        kind = kinds[int(rng.choice(len(kinds), p=weights / weights.sum()))]
        camera = {
            "held": self._held,
            "presented": self._presented,
            "scatter": self._scatter,
            "bay": self._bay,
            "feeder": self._feeder,
        }[kind](rng)
        return self._capture(camera, rng), kind

    def _capture(self, camera: str, rng: np.random.Generator | None = None) -> Sample:
        """The sample ``camera`` sees now; ``rng`` draws its sensor effects (with ``cameras``)."""
        s = self.settings
        frame = self.scene.render(camera, s.width, s.height, antialias=s.antialias)
        if self.sensors is not None:
            rng = rng if rng is not None else np.random.default_rng([s.seed, 2])
            sensor = self.sensors.for_camera(camera)
            rgb, depth = sensor.apply(frame.rgb, frame.depth, frame.intrinsics.fx, rng)
            frame = dataclasses.replace(frame, rgb=rgb, depth=depth)
        seg = frame.segmentation
        counts = np.bincount(seg[seg >= 0].ravel(), minlength=len(frame.labels.instance_names))
        keep = [int(i) for i in np.flatnonzero(counts >= s.min_pixels) if int(i) in self.recipes]
        cam_pos, cam_rot = frame.position, frame.rotation
        names, labels, poses, defects = [], [], [], []
        for i in keep:
            name = frame.labels.instance_names[i]
            names.append(name)
            labels.append(CLASSES.index(frame.labels.classes[i]) + 1)
            pos, rot = self.pose_in_world(i)
            poses.append(_pose(cam_rot.T @ rot, cam_rot.T @ (pos - cam_pos)))
            part = self.by_body.get(name.rsplit("/", 1)[0])
            defects.append(part.defect.kind if part is not None and part.defect is not None else "")
        n, (h, w) = len(keep), seg.shape
        return Sample(
            rgb=frame.rgb,
            depth=frame.depth.astype(np.float32),
            masks=np.stack([seg == i for i in keep]) if keep else np.zeros((0, h, w), dtype=bool),
            labels=np.array(labels, dtype=np.int64),
            names=np.array(names, dtype=str) if n else np.zeros(0, dtype="<U1"),
            poses=np.array(poses, dtype=np.float64).reshape(n, 4, 4),
            defects=np.array(defects, dtype=str) if n else np.zeros(0, dtype="<U1"),
            intrinsics=frame.intrinsics.matrix.astype(np.float64),
        )

    def close(self) -> None:
        self.scene.close()
