"""MJCF of the EDU, generated from ``config/twin/edu.yaml``, a mission and a scenario.

:func:`build_model` writes ``edu.xml`` and the AprilTag PNG textures into an output folder and
returns a :class:`ModelInfo` describing what it made (parts, their local geometry, the cross frames
that grippers and rivets can hold). Nothing is compiled here; :mod:`tlt_sim.model.scene` does that.

World frame: z up, floor at z = 0, the mission's "base" frame at ``site.base_origin``. The tower
frame (corner x0_y0 of the payload's cross frame, mission ``bay0``) starts at
``(0, 0, build_level + bay_height)``; bay n's bottom cross frame is at ``-n * bay_height`` in it.

Collision filtering (contype/conaffinity): the arms (bit 2) touch the floor, posts, pedestals and
dispensers; a part that falls (bit 4, set when it drops) touches only the floor and the foundation
pads (a cross frame released at the build level rests on them, the arms pass them); nothing else
collides.
Assembly is by equality constraints (see :mod:`tlt_sim.model.assembly`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.geometry import ur10e
from tlt_common.geometry.transforms import rot_x, rot_y, rot_z, rotation_to_mujoco_quat, rpy_matrix
from tlt_common.mission.schema import Mission
from tlt_sim.model import names
from tlt_sim.model.apriltag import write_tag_png
from tlt_sim.model.geometry import fmt, look_at_xyaxes
from tlt_sim.model.scenario import NOMINAL, Defect, Scenario

ARM_BIT, PART_BIT = 2, 4
# Rivet gun body of the end effector (half extents, m) and how far it sits outboard of the grasp
# line, across the bar: a gun hangs over each end of whatever side of a part is grasped.
GUN_HALF, GUN_OUTBOARD = (0.025, 0.025, 0.04), 0.06
# Rack uprights: half width of their square section, and the gap kept between a cross-frame
# upright and a rivet gun over the corner it stands by (the fine approach's error budget).
UPRIGHT_HALF, UPRIGHT_GUN_GAP = 0.015, 0.03
HIDDEN_GROUP, RIVET_GROUP = 5, 2
CLASS_COLOURS = {
    "strut_tube": "0.78 0.80 0.83 1",
    "end_fitting": "0.95 0.55 0.10 1",
    "cross_frame": "0.55 0.70 0.85 1",
    "corner_joint": "0.15 0.35 0.75 1",
    "rivet": "0.90 0.10 0.10 1",
}


@dataclass
class PartInfo:
    """A loose part: where its features lie in its own body frame."""

    name: str  # <dispenser>/<index>
    body: str
    kind: str  # cross_frame, vertical, diagonal
    dispenser: str
    index: int
    length: float
    ends: dict[str, np.ndarray]  # strut: 'a', 'b'; cross frame: corner numbers as str
    grasps: list[tuple[np.ndarray, np.ndarray]]  # (point, axis) in the body frame
    slot_pos: np.ndarray
    slot_quat: np.ndarray
    defect: Defect | None = None
    # Half the length of tube along each grasp line, either side of its point: jaws close on it there.
    grasp_span: float = 0.0


@dataclass
class ModelInfo:
    xml_path: Path
    out_dir: Path
    edu: dict[str, Any]
    mission: Mission
    scenario: Scenario
    parts: dict[str, PartInfo] = field(default_factory=dict)
    cross_frames: list[str] = field(default_factory=list)  # bodies with corners: payload + cross frames
    top_level: float = 0.0
    tower_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    dispenser_tags: dict[str, int] = field(default_factory=dict)
    post_xy: list[np.ndarray] = field(default_factory=list)

    @property
    def struts(self) -> list[str]:
        return [p.body for p in self.parts.values() if p.kind != "cross_frame"]


def _sub(parent: ET.Element, tag: str, **attrs: Any) -> ET.Element:
    el = ET.SubElement(parent, tag)
    for key, value in attrs.items():
        if value is None:
            continue
        key = key.rstrip("_")
        el.set(key, value if isinstance(value, str) else fmt(value))
    return el


class _Builder:
    def __init__(self, edu: dict[str, Any], mission: Mission, scenario: Scenario, out_dir: Path) -> None:
        self.edu, self.mission, self.scenario, self.out = edu, mission, scenario, out_dir
        self.w, self.h = mission.bay_width, mission.bay_height
        site = edu["site"]
        self.build_level = site["build_level"]
        self.top_level = self.build_level + self.h
        self.base_origin = np.asarray(site["base_origin"], dtype=float)
        self.info = ModelInfo(out_dir / "edu.xml", out_dir, edu, mission, scenario, top_level=self.top_level)
        self.info.tower_origin = np.array([0.0, 0.0, self.top_level])
        self.root = ET.Element("mujoco", model=f"tlt_edu_{mission.name}")
        self.corner_xy = [np.array([i * self.w, j * self.w]) for i, j in names.CORNER_XY]
        centre = np.array([self.w / 2, self.w / 2])
        # Direction from each corner to its post: along a side, turning around the square (a
        # pinwheel), so no post stands on the diagonal where the arms reach in to the corners.
        self.outward = [np.array(v, dtype=float) for v in ((0, -1), (1, 0), (0, 1), (-1, 0))]
        self.diagonal = [(c - centre) / np.linalg.norm(c - centre) for c in self.corner_xy]
        off = edu["lifter"]["post_offset"]
        self.post_xy = [c + off * d for c, d in zip(self.corner_xy, self.diagonal, strict=True)]
        self.info.post_xy = self.post_xy

    # -- document skeleton -------------------------------------------------------------------
    def build(self) -> ModelInfo:
        phys = self.edu["physics"]
        _sub(self.root, "compiler", angle="radian", autolimits="true")
        _sub(self.root, "option", timestep=phys["timestep"], integrator="implicitfast", cone="elliptic")
        _sub(self.root, "statistic", extent=4.0, center=(0.4, 0.4, 0.9))
        visual = _sub(self.root, "visual")
        _sub(visual, "global", offwidth=1280, offheight=960)
        # Coarser tessellation of round geoms: CPU rendering cost is mostly their triangles.
        _sub(visual, "quality", shadowsize=2048, numslices=14, numstacks=6, numquads=1)
        _sub(visual, "map", znear=0.004, zfar=12.0)
        _sub(visual, "headlight", ambient=(0.35, 0.35, 0.35), diffuse=(0.55, 0.55, 0.55))
        self.asset = _sub(self.root, "asset")
        _sub(
            self.asset,
            "texture",
            name="grid",
            type="2d",
            builtin="checker",
            rgb1=(0.32, 0.34, 0.36),
            rgb2=(0.28, 0.30, 0.32),
            width=256,
            height=256,
        )
        _sub(self.asset, "material", name="floor", texture="grid", texrepeat=(8, 8), reflectance=0.0)
        for cls, rgba in CLASS_COLOURS.items():
            _sub(self.asset, "material", name=cls, rgba=rgba, specular=0.4)
        self._defaults()
        self.world = _sub(self.root, "worldbody")
        _sub(
            self.world,
            "light",
            name="sun",
            pos=(0.4, 0.4, 5.0),
            dir=(0.1, 0.1, -1.0),
            directional="true",
            diffuse=(0.6, 0.6, 0.6),
            castshadow="false",
        )
        _sub(
            self.world,
            "geom",
            name="floor",
            type="plane",
            size=(6, 6, 0.1),
            material="floor",
            contype=1,
            conaffinity=1 | ARM_BIT | PART_BIT,
        )
        self.contact = _sub(self.root, "contact")
        self.actuators = _sub(self.root, "actuator")
        self.equality = _sub(self.root, "equality")
        self._foundation()
        self._lifter()
        self._payload()
        for arm in names.ARMS:
            self._arm(arm)
        self._dispensers()
        self._equalities()
        ET.indent(self.root)
        self.out.mkdir(parents=True, exist_ok=True)
        ET.ElementTree(self.root).write(self.info.xml_path, encoding="unicode")
        return self.info

    def _defaults(self) -> None:
        d = _sub(self.root, "default")
        env = _sub(d, "default", class_="env")
        _sub(env, "geom", contype=0, conaffinity=ARM_BIT, rgba=(0.45, 0.47, 0.5, 1))
        mech = _sub(d, "default", class_="mech")
        _sub(mech, "geom", contype=0, conaffinity=0, rgba=(0.25, 0.25, 0.28, 1))
        arm = _sub(d, "default", class_="arm")
        _sub(arm, "geom", contype=ARM_BIT, conaffinity=0, rgba=(0.55, 0.65, 0.75, 1))
        part = _sub(d, "default", class_="part")
        # Parts collide with nothing until they fall (the scene then sets contype to PART_BIT):
        # a hundred resting parts would otherwise cost most of each step's collision search.
        _sub(part, "geom", contype=0, conaffinity=0, condim=3)
        deco = _sub(d, "default", class_="deco")
        _sub(deco, "geom", contype=0, conaffinity=0, mass=0)

    def _actuator(self, joint: str, kp: float, kv: float, force: float, span: tuple[float, float]) -> None:
        # An integrated-velocity servo: ctrl is the setpoint's velocity and MuJoCo integrates the
        # setpoint (act, kept within span) every step, so Python only sets velocities at the
        # control rate (see Scene.step).
        _sub(
            self.actuators,
            "intvelocity",
            name=joint,
            joint=joint,
            kp=kp,
            kv=kv,
            forcerange=(-force, force),
            actrange=span,
        )

    # -- static machine ----------------------------------------------------------------------
    def _foundation(self) -> None:
        top = self.edu["site"]["foundation_top"]
        body = _sub(self.world, "body", name="foundation")
        for i, c in enumerate(self.corner_xy):
            _sub(
                body,
                "geom",
                name=f"foundation/pad_{i}",
                class_="env",
                # Falling parts land on the pads as on the floor: a cross frame the ARS lets go of
                # at the build level rests on them until the Active Grippers latch it (as on the EDU).
                # The arms do not touch them: a rivet gun at a corner joint reaches just above a
                # pad, and the ARS planning scene does not model the pads either.
                conaffinity=PART_BIT,
                type="box",
                size=(0.035, 0.035, top / 2),
                pos=(c[0], c[1], top / 2),
                rgba=(0.35, 0.3, 0.25, 1),
            )

    def _lifter(self) -> None:
        lf, ag, tg, cm = (self.edu[k] for k in ("lifter", "active_grippers", "top_grippers", "camera_mounts"))
        r, height = lf["post_radius"], lf["post_height"]
        frame = _sub(self.world, "body", name="lifter")
        for i, p in enumerate(self.post_xy):
            _sub(
                frame,
                "geom",
                name=f"lifter/post_{i}",
                class_="env",
                type="cylinder",
                size=(r, height / 2),
                pos=(p[0], p[1], height / 2),
            )
            # Bracing only at the foot: a ring at the top would stand in the arms' way.
            q = self.post_xy[(i + 1) % 4]
            _sub(
                frame,
                "geom",
                name=f"lifter/beam_{i}",
                class_="env",
                type="capsule",
                size=(r * 0.7,),
                fromto=(p[0], p[1], 0.05, q[0], q[1], 0.05),
            )
            self._top_gripper(frame, i, tg)
        for i, p in enumerate(self.post_xy):
            self._carriage(i, p, lf, ag)
        for n, corner in enumerate(names.ZED_CORNERS):
            self._camera_mount(frame, n, corner, cm)

    def _top_gripper(self, frame: ET.Element, i: int, tg: dict[str, Any]) -> None:
        c, o = self.corner_xy[i], self.outward[i]
        half = self.edu["parts"]["corner_size"] / 2
        tip_engaged = c + o * half
        base = tip_engaged + o * tg["stroke"]  # pin tip when retracted (joint at zero)
        bracket_end = self.post_xy[i] - o * self.edu["lifter"]["post_radius"]
        z = self.top_level
        _sub(
            frame,
            "geom",
            name=f"top_gripper_{i}/bracket",
            class_="mech",
            type="box",
            size=(0.03, 0.03, 0.02),
            pos=(
                (base[0] + bracket_end[0]) / 2 + o[0] * 0.02,
                (base[1] + bracket_end[1]) / 2 + o[1] * 0.02,
                z + 0.05,
            ),
        )
        pin = _sub(frame, "body", name=names.top_gripper(i), pos=(base[0], base[1], z))
        joint = names.top_gripper(i)
        _sub(
            pin,
            "joint",
            name=joint,
            type="slide",
            axis=(-o[0], -o[1], 0.0),
            range=(0.0, tg["stroke"]),
            armature=0.5,
            damping=5.0,
        )
        _sub(
            pin,
            "geom",
            class_="mech",
            type="capsule",
            size=(0.008,),
            fromto=(0, 0, 0, o[0] * 0.12, o[1] * 0.12, 0.0),
            mass=0.1,
            rgba=(0.8, 0.75, 0.2, 1),
        )
        _sub(pin, "site", name=f"{joint}/tip", size=(0.006,))
        self._actuator(joint, 5000.0, 200.0, 120.0, (0.0, tg["stroke"]))

    def _carriage(self, i: int, p: np.ndarray, lf: dict[str, Any], ag: dict[str, Any]) -> None:
        c, o = self.corner_xy[i], self.outward[i]
        z0 = self.build_level - lf["build_position"]
        body = _sub(self.world, "body", name=f"lifter_carriage_{i}", pos=(p[0], p[1], z0))
        joint = names.lifter_joint(i)
        _sub(
            body,
            "joint",
            name=joint,
            type="slide",
            axis=(0, 0, 1),
            range=lf["travel"],
            armature=5.0,
            damping=200.0,
        )
        _sub(
            body,
            "geom",
            class_="mech",
            type="box",
            size=(0.06, 0.06, 0.05),
            mass=lf["carriage_mass"],
            rgba=(0.2, 0.2, 0.22, 1),
        )
        f = ag["finger_length"]
        hinge = c + o * f
        rel = hinge - p
        _sub(
            body,
            "geom",
            class_="mech",
            type="capsule",
            size=(0.015,),
            fromto=(0, 0, 0, rel[0], rel[1], 0),
            mass=0.2,
        )
        self._actuator(joint, lf["kp"], 2.0 * math.sqrt(lf["kp"] * 60.0), 8000.0, lf["travel"])
        latch = _sub(body, "body", name=names.active_gripper(i), pos=(rel[0], rel[1], 0.0))
        ajoint = names.active_gripper(i)
        _sub(
            latch,
            "joint",
            name=ajoint,
            type="hinge",
            axis=(0, 0, 1),
            range=ag["range"],
            armature=0.05,
            damping=0.5,
        )
        inward = -o
        v0 = np.array([inward[1], -inward[0]])  # rotated +90 deg about z this points inward
        _sub(
            latch,
            "geom",
            class_="mech",
            type="capsule",
            size=(0.012,),
            fromto=(0, 0, 0, v0[0] * f, v0[1] * f, 0),
            mass=0.15,
            rgba=(0.1, 0.4, 0.8, 1),
        )
        _sub(latch, "site", name=f"{ajoint}/tip", pos=(v0[0] * f, v0[1] * f, 0.0), size=(0.006,))
        self._actuator(ajoint, 40.0, 2.0, 8.4, ag["range"])

    def _camera_mount(self, frame: ET.Element, n: int, corner: int, cm: dict[str, Any]) -> None:
        p, o = self.post_xy[corner], self.diagonal[corner]
        z = self.top_level + cm["height"]
        pos = p + o * 0.06
        _sub(
            frame,
            "geom",
            name=f"{names.camera_mount(n)}/arm",
            class_="mech",
            type="box",
            size=(0.03, 0.03, 0.02),
            pos=(p[0] + o[0] * 0.03, p[1] + o[1] * 0.03, z - 0.04),
        )
        mount = _sub(frame, "body", name=names.camera_mount(n), pos=(pos[0], pos[1], z))
        joint = names.camera_mount(n)
        _sub(
            mount,
            "joint",
            name=joint,
            type="hinge",
            axis=(0, 0, 1),
            range=cm["range"],
            armature=0.05,
            damping=0.3,
        )
        # At inward_angle the camera looks at the tower axis; the mount turns it by (q - inward_angle).
        pitch = math.radians(cm["pitch_deg"])
        heading = math.atan2(-o[1], -o[0]) - cm["inward_angle"]
        flat = np.array([math.cos(heading), math.sin(heading)]) * math.cos(pitch)
        look = np.array([flat[0], flat[1], -math.sin(pitch)])
        _sub(
            mount,
            "geom",
            class_="mech",
            type="box",
            size=(0.03, 0.09, 0.015),
            mass=0.17,
            quat=rotation_to_mujoco_quat(rot_z(heading)),
            rgba=(0.1, 0.1, 0.1, 1),
        )
        _sub(
            mount,
            "camera",
            name=names.zed_camera(n),
            pos=tuple(look * 0.04),
            xyaxes=look_at_xyaxes(look),
            fovy=self.edu["cameras"]["zed_fovy_deg"],
        )
        self._actuator(joint, 30.0, 1.5, 8.4, tuple(cm["range"]))

    # -- payload and parts -------------------------------------------------------------------
    def _cross_frame_geoms(
        self, body: ET.Element, prefix: str, mass: float
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        parts = self.edu["parts"]
        w, half, r = self.w, parts["corner_size"] / 2, parts["tube_radius"] * 1.2
        corners = [np.array([x * w, y * w, 0.0]) for x, y in names.CORNER_XY]
        grasps = []
        side_mass = mass * 0.8 / 4
        for i, c in enumerate(corners):
            d = corners[(i + 1) % 4] - c
            u = d / np.linalg.norm(d)
            a, b = c + u * half, corners[(i + 1) % 4] - u * half
            _sub(
                body,
                "geom",
                name=f"{prefix}/side_{i}",
                class_="part",
                type="capsule",
                size=(r,),
                fromto=(*a, *b),
                material="cross_frame",
                mass=side_mass,
            )
            grasps.append((c + d / 2, u))
        for i, c in enumerate(corners):
            _sub(
                body,
                "geom",
                name=f"{prefix}/corner_{i}",
                class_="part",
                type="box",
                size=(half,) * 3,
                pos=c,
                material="corner_joint",
                mass=mass * 0.2 / 4,
            )
            _sub(body, "site", name=names.corner_site(prefix, i), pos=c, size=(0.005,))
        return grasps

    def _payload(self) -> None:
        pl = self.edu["payload"]
        body = _sub(self.world, "body", name="payload", pos=self.info.tower_origin)
        _sub(body, "freejoint", name="payload")
        self._cross_frame_geoms(body, "payload", self.edu["parts"]["cross_frame_mass"])
        sx, sy, sz = pl["size"]
        _sub(
            body,
            "geom",
            name="payload/box",
            class_="mech",
            type="box",
            size=(sx / 2, sy / 2, sz / 2),
            pos=(self.w / 2, self.w / 2, 0.04 + sz / 2),
            mass=pl["mass"],
            rgba=(0.85, 0.82, 0.7, 1),
        )
        self.info.cross_frames.append("payload")

    def _strut_geoms(
        self,
        body: ET.Element,
        prefix: str,
        length: float,
        defect: Defect | None,
    ) -> dict[str, np.ndarray]:
        p = self.edu["parts"]
        half, fl, mass = p["corner_size"] / 2, p["fitting_length"], p["strut_mass"]
        ends = {"a": np.zeros(3), "b": np.array([0.0, 0.0, length])}
        tube_a, tube_b = np.array([0, 0, half + fl]), np.array([0, 0, length - half - fl])
        tube_mass = mass * 0.7
        if defect is not None and defect.kind == "bent_tube":
            # A kink at mid-length: the second half turns by bend_deg about x, carrying end b with it.
            mid = np.array([0.0, 0.0, length / 2])
            bend = rot_x(math.radians(defect.bend_deg))
            ends["b"] = mid + bend @ (ends["b"] - mid)
            tube_b = mid + bend @ (tube_b - mid)
            _sub(
                body,
                "geom",
                name=f"{prefix}/tube",
                class_="part",
                type="capsule",
                size=(p["tube_radius"],),
                fromto=(*tube_a, *mid),
                material="strut_tube",
                mass=tube_mass / 2,
            )
            _sub(
                body,
                "geom",
                name=f"{prefix}/tube#1",
                class_="part",
                type="capsule",
                size=(p["tube_radius"],),
                fromto=(*mid, *tube_b),
                material="strut_tube",
                mass=tube_mass / 2,
            )
        else:
            _sub(
                body,
                "geom",
                name=f"{prefix}/tube",
                class_="part",
                type="capsule",
                size=(p["tube_radius"],),
                fromto=(*tube_a, *tube_b),
                material="strut_tube",
                mass=tube_mass,
            )
        axis_b = (ends["b"] - tube_b) / np.linalg.norm(ends["b"] - tube_b)
        spans = {
            "a": (ends["a"] + [0, 0, half], ends["a"] + [0, 0, half + fl]),
            "b": (ends["b"] - axis_b * half, ends["b"] - axis_b * (half + fl)),
        }
        for end, (s0, s1) in spans.items():
            if defect is not None and defect.kind == "missing_end_fitting" and defect.end == end:
                continue
            _sub(
                body,
                "geom",
                name=f"{prefix}/fitting_{end}",
                class_="part",
                type="cylinder",
                size=(p["fitting_radius"],),
                fromto=(*s0, *s1),
                material="end_fitting",
                mass=mass * 0.15,
            )
            rivet = s0 + (s1 - s0) * 0.5 + np.array([p["fitting_radius"], 0, 0])
            _sub(
                body,
                "geom",
                name=f"{prefix}/rivet_{end}",
                class_="deco",
                type="sphere",
                size=(p["rivet_radius"],),
                pos=rivet,
                material="rivet",
                group=HIDDEN_GROUP,
            )
        return ends

    def _dispensers(self) -> None:
        d_cfg = self.edu["dispensers"]
        for tag_id, (name, disp) in enumerate(self.mission.dispensers.items()):
            self.info.dispenser_tags[name] = tag_id
            rot = rpy_matrix(disp.rpy)
            pos = self.base_origin + np.asarray(disp.position, dtype=float)
            quat = rotation_to_mujoco_quat(rot)
            body = _sub(self.world, "body", name=f"dispenser/{name}", pos=pos, quat=quat)
            count = 0 if name in self.scenario.empty else disp.count
            extent = self._dispenser_extent(disp.part_kind)
            top = d_cfg["first_slot_height"] + max(count - 1, 0) * d_cfg["slot_pitch"]
            if disp.part_kind == "rivet":
                # A feeder column on the dispenser's frame; rivets wait in a tray at its top.
                lift = d_cfg["rivet_pickup_height"]
                _sub(
                    body,
                    "geom",
                    name=f"dispenser/{name}/column",
                    class_="env",
                    type="cylinder",
                    size=(0.02, (pos[2] + lift) / 2),
                    pos=(0, 0, (lift - pos[2]) / 2 - 0.03),
                )
                _sub(
                    body,
                    "geom",
                    name=f"dispenser/{name}/box",
                    class_="env",
                    type="box",
                    size=(0.04, 0.04, 0.03),
                    pos=(0, 0, lift),
                )
                for k in range(min(count, 9)):
                    _sub(
                        body,
                        "geom",
                        name=f"dispenser/{name}/rivet_{k}",
                        class_="deco",
                        type="cylinder",
                        size=(0.006, 0.012),
                        pos=(-0.025 + 0.025 * (k % 3), -0.025 + 0.025 * (k // 3), lift + 0.042),
                        material="rivet",
                    )
                _sub(body, "site", name=f"dispenser/{name}/pickup", pos=(0, 0, lift + 0.05), size=(0.01,))
                top = lift
            else:
                self._rack(body, name, extent, top)
            self._tag(body, name, tag_id, extent, top)
            if disp.part_kind != "rivet":
                for index in range(count):
                    z = d_cfg["first_slot_height"] + (count - 1 - index) * d_cfg["slot_pitch"]
                    self._part(name, disp.part_kind, index, pos, rot, z)

    def _dispenser_extent(self, kind: str) -> float:
        if kind == "cross_frame":
            return self.w
        if kind == "rivet":
            return 0.08
        return self.mission.strut_lengths[kind]

    def _rack(self, body: ET.Element, name: str, extent: float, top: float) -> None:
        height = top + 0.05
        uprights = rack_uprights(name.startswith("cross"), extent, self.w, self.edu)
        for sx, sy, x, y in uprights:
            _sub(
                body,
                "geom",
                name=f"dispenser/{name}/upright_{sx}_{sy}".replace("-", "m"),
                class_="env",
                type="box",
                size=(UPRIGHT_HALF, UPRIGHT_HALF, height / 2),
                pos=(x, y, height / 2),
            )
        x, y = abs(uprights[0][2]), abs(uprights[0][3])
        _sub(
            body,
            "geom",
            name=f"dispenser/{name}/base",
            class_="env",
            type="box",
            size=(x + 0.02, y + 0.02, 0.01),
            pos=(0, 0, 0.01),
        )

    def _tag(self, body: ET.Element, name: str, tag_id: int, extent: float, top: float) -> None:
        size = self.edu["dispensers"]["tag_size"]
        png = write_tag_png(tag_id, self.out / f"tag36h11_{tag_id}.png")
        _sub(self.asset, "texture", name=f"tag_{tag_id}", type="2d", file=str(png.resolve()))
        _sub(
            self.asset,
            "material",
            name=f"tag_{tag_id}",
            texture=f"tag_{tag_id}",
            specular=0.0,
            rgba=(1, 1, 1, 1),
        )
        x = -(extent / 2 + 0.15 + size / 2)
        z = top + 0.06
        _sub(
            body,
            "geom",
            name=f"dispenser/{name}/tag_post",
            class_="env",
            type="box",
            size=(0.015, 0.015, z / 2),
            pos=(x, 0, z / 2),
        )
        _sub(
            body,
            "geom",
            name=f"dispenser/{name}/tag",
            class_="deco",
            type="box",
            size=(size / 2, size / 2, 0.002),
            pos=(x, 0, z + 0.002),
            material=f"tag_{tag_id}",
        )
        _sub(body, "site", name=f"dispenser/{name}/tag", pos=(x, 0, z + 0.004), size=(0.005,))

    def _part(
        self, dispenser: str, kind: str, index: int, dpos: np.ndarray, drot: np.ndarray, z: float
    ) -> None:
        pname = f"{dispenser}/{index}"
        bname = names.part_body(dispenser, index)
        defect = self.scenario.defects.get(pname)
        if kind == "cross_frame":
            local_pos, local_rot = np.array([-self.w / 2, -self.w / 2, z]), np.eye(3)
        else:
            length = self.mission.strut_lengths[kind]
            local_pos, local_rot = np.array([-length / 2, 0.0, z]), rot_y(math.pi / 2)
        wpos, wrot = dpos + drot @ local_pos, drot @ local_rot
        wquat = rotation_to_mujoco_quat(wrot)
        body = _sub(self.world, "body", name=bname, pos=wpos, quat=wquat, gravcomp=1)
        _sub(body, "freejoint", name=bname)
        half = self.edu["parts"]["corner_size"] / 2
        if kind == "cross_frame":
            grasps = self._cross_frame_geoms(body, bname, self.edu["parts"]["cross_frame_mass"])
            span = self.w / 2 - half
            ends = {
                str(i): np.array([x * self.w, y * self.w, 0.0]) for i, (x, y) in enumerate(names.CORNER_XY)
            }
            length = self.w
            self.info.cross_frames.append(bname)
        else:
            ends = self._strut_geoms(body, bname, length, defect)
            grasps = [(np.array([0.0, 0.0, length / 2]), np.array([0.0, 0.0, 1.0]))]
            span = length / 2 - half - self.edu["parts"]["fitting_length"]
        self.info.parts[pname] = PartInfo(
            pname, bname, kind, dispenser, index, length, ends, grasps, wpos, wquat, defect, span
        )

    # -- arms and end effectors --------------------------------------------------------------
    def _arm(self, arm: str) -> None:
        cfg, arms = self.edu["arms"][arm], self.edu["arms"]
        base = np.asarray(cfg["base"], dtype=float)
        ped = cfg["pedestal_height"]
        parent = _sub(
            self.world,
            "body",
            name=f"{arm}/base",
            pos=(base[0], base[1], base[2] + ped),
            quat=rotation_to_mujoco_quat(rot_z(math.radians(cfg["yaw_deg"]))),
        )
        if ped > 0:  # in the base body, so the first link (its child) never collides with it
            _sub(
                parent,
                "geom",
                name=f"{arm}/pedestal",
                class_="env",
                type="cylinder",
                size=(0.09, ped / 2),
                pos=(0, 0, -ped / 2),
            )
        _sub(parent, "geom", class_="arm", type="cylinder", size=(0.095, 0.03), pos=(0, 0, 0.03), mass=2.0)
        # The base is welded to the world, so MuJoCo's parent filter does not spare the first link.
        _sub(self.contact, "exclude", body1=f"{arm}/base", body2=f"{arm}/link_1")
        pos, quat = np.zeros(3), np.array([1.0, 0, 0, 0])
        for i in range(6):
            link = _sub(parent, "body", name=f"{arm}/link_{i + 1}", pos=pos, quat=quat, gravcomp=1)
            joint = names.arm_joint(arm, i)
            _sub(
                link,
                "joint",
                name=joint,
                type="hinge",
                axis=(0, 0, 1),
                range=(-ur10e.POSITION_LIMIT, ur10e.POSITION_LIMIT),
                armature=arms["armature"],
                damping=2.0,
            )
            _sub(
                link,
                "inertial",
                pos=ur10e.COM[i],
                mass=ur10e.MASS[i],
                diaginertia=(ur10e.MASS[i] * 0.01,) * 3,
            )
            radius = ur10e.LINK_RADIUS[i]
            end = np.array([ur10e.A[i], 0.0, ur10e.D[i]])
            _sub(link, "geom", class_="arm", type="cylinder", size=(radius, radius * 0.9), mass=0)
            if np.linalg.norm(end) > 1e-6:
                _sub(
                    link,
                    "geom",
                    name=f"{arm}/link_{i + 1}/capsule",
                    class_="arm",
                    type="capsule",
                    size=(radius * 0.8,),
                    fromto=(0, 0, 0, *end),
                    mass=0,
                )
            self._actuator(
                joint,
                arms["kp"],
                arms["kv"],
                ur10e.TORQUE_LIMIT[i],
                (-ur10e.POSITION_LIMIT, ur10e.POSITION_LIMIT),
            )
            parent = link
            pos, quat = end, rotation_to_mujoco_quat(rot_x(ur10e.ALPHA[i]))
        flange = _sub(parent, "body", name=names.ee_body(arm), pos=pos, quat=quat, gravcomp=1)
        _sub(flange, "site", name=f"{arm}/flange", size=(0.01,))
        self._end_effector(arm, flange)

    def _end_effector(self, arm: str, ee: ET.Element) -> None:
        e = self.edu["end_effector"]
        s, depth, g = e["grip_spacing"], e["grasp_depth"], e["rivet_gun_offset"]
        _sub(
            ee,
            "geom",
            name=f"{arm}/ee/hub",
            class_="arm",
            type="cylinder",
            size=(0.045, 0.02),
            pos=(0, 0, 0.02),
            mass=0.4,
        )
        _sub(
            ee,
            "geom",
            name=f"{arm}/ee/bar",
            class_="arm",
            type="box",
            size=(e["bar_length"] / 2, 0.03, 0.02),
            pos=(0, 0, 0.06),
            mass=1.5,
            rgba=(0.3, 0.3, 0.32, 1),
        )
        _sub(ee, "site", name=f"{arm}/ee/grasp_centre", pos=(0, 0, depth), size=(0.006,))
        grip_a = _sub(ee, "body", name=f"{arm}/gripper_a", pos=(-s / 2, 0, 0), gravcomp=1)
        self._gripper(arm, "a", grip_a, -1.0, depth, g, e)
        grip_b = _sub(ee, "body", name=f"{arm}/gripper_b", pos=(s / 2, 0, 0), gravcomp=1)
        wjoint = names.width_joint(arm)
        _sub(
            grip_b,
            "joint",
            name=wjoint,
            type="slide",
            axis=(1, 0, 0),
            range=(0.0, e["width_travel"]),
            armature=1.0,
            damping=20.0,
        )
        self._actuator(wjoint, 8000.0, 300.0, 300.0, (0.0, e["width_travel"]))
        self._gripper(arm, "b", grip_b, 1.0, depth, g, e)
        _sub(ee, "site", name=f"{arm}/limit_switch", pos=(s / 2, 0.035, 0.06), size=(0.006,))

    def _gripper(
        self, arm: str, side: str, body: ET.Element, sign: float, depth: float, g: float, e: dict[str, Any]
    ) -> None:
        _sub(
            body,
            "geom",
            name=f"{arm}/gripper_{side}/body",
            class_="arm",
            type="box",
            size=(0.025, 0.03, (depth - 0.08) / 2),
            pos=(0, 0, 0.08 + (depth - 0.08) / 2 - 0.02),
            mass=0.6,
            rgba=(0.2, 0.2, 0.22, 1),
        )
        _sub(body, "site", name=f"{arm}/grip_{side}", pos=(0, 0, depth), size=(0.006,))
        _sub(
            body,
            "geom",
            name=f"{arm}/gripper_{side}/finger",
            class_="arm",
            type="box",
            size=(0.012, 0.006, 0.03),
            pos=(0, 0.032, depth),
            mass=0.05,
        )
        # The jaw is a finger on a Dynamixel hinge along the grasp line (as ee_x.yaml: rad); at
        # jaw_contact its tip meets a tube lying on the line.
        hinge = np.array([0.0, -0.045, depth - 0.045])
        tip = np.array([0.0, -self.edu["parts"]["tube_radius"], depth])
        reach = float(np.linalg.norm(tip - hinge))
        finger = rot_x(-e["jaw_contact"]) @ ((tip - hinge) / reach)  # its direction at angle 0
        jaw = _sub(body, "body", name=f"{arm}/jaw_{side}", pos=hinge, gravcomp=1)
        joint = names.grasp_joint(arm, side)
        _sub(
            jaw,
            "joint",
            name=joint,
            type="hinge",
            axis=(1, 0, 0),
            range=e["jaw_range"],
            armature=0.02,
            damping=0.1,
        )
        _sub(
            jaw,
            "geom",
            class_="arm",
            type="capsule",
            size=(0.007,),
            fromto=(0, 0, 0, *(finger * reach)),
            mass=0.05,
            rgba=(0.8, 0.2, 0.2, 1),
        )
        self._actuator(joint, 20.0, 0.5, 8.4, tuple(e["jaw_range"]))
        gx = sign * g
        _sub(
            body,
            "geom",
            name=f"{arm}/rivet_gun_{side}/body",
            class_="arm",
            type="box",
            size=GUN_HALF,
            pos=(gx, -GUN_OUTBOARD, depth - 0.05),
            mass=0.8,
            rgba=(0.9, 0.75, 0.1, 1),
        )
        _sub(
            body,
            "geom",
            name=f"{arm}/rivet_gun_{side}/bracket",
            class_="arm",
            type="box",
            size=(abs(gx) / 2 + 0.02, 0.01, 0.01),
            pos=(gx / 2, -GUN_OUTBOARD, depth - 0.1),
            mass=0.1,
        )
        _sub(body, "site", name=names.rivet_gun_site(arm, side), pos=(gx, 0, depth), size=(0.008,))
        # The rivet in the gun's muzzle: drawn (and seen by the D405) only while the gun is loaded;
        # the assembly physics shows and hides it (alpha), it touches nothing.
        _sub(
            body,
            "geom",
            name=names.loaded_rivet_geom(arm, side),
            class_="deco",
            type="cylinder",
            size=(0.006, 0.012),
            pos=(gx, 0, depth),
            rgba=(0.9, 0.1, 0.1, 0.0),
        )
        cam_pos = np.array([sign * 0.06, 0.075, 0.07])
        tilt = math.radians(self.edu["cameras"]["d405_tilt_deg"])
        target = np.array([gx - sign * depth * math.tan(tilt), 0.0, depth])
        look = target - cam_pos
        _sub(
            body,
            "geom",
            name=f"{arm}/d405_{side}/housing",
            class_="arm",
            type="box",
            size=(0.021, 0.021, 0.0115),
            pos=cam_pos - [0, 0, 0.015],
            mass=0.06,
            rgba=(0.15, 0.15, 0.15, 1),
        )
        _sub(
            body,
            "camera",
            name=names.d405_camera(arm, side),
            pos=cam_pos,
            xyaxes=look_at_xyaxes(look, up=(sign, 0.0, 0.0)),
            fovy=self.edu["cameras"]["d405_fovy_deg"],
        )

    # -- equality constraints (all inactive; the scene turns them on) ------------------------
    def _equalities(self) -> None:
        phys = self.edu["physics"]
        holders = [("top", "lifter"), ("active", None), ("foundation", "foundation")]
        for cf in self.info.cross_frames:
            for i in range(4):
                anchor = np.array([names.CORNER_XY[i][0] * self.w, names.CORNER_XY[i][1] * self.w, 0.0])
                for kind, other in holders:
                    body2 = other or f"lifter_carriage_{i}"
                    _sub(
                        self.equality,
                        "connect",
                        name=f"{kind}/{i}/{cf}",
                        body1=cf,
                        body2=body2,
                        anchor=anchor,
                        active="false",
                        solref=phys["hold_solref"],
                    )
        for strut in self.info.struts:
            for cf in self.info.cross_frames:
                _sub(
                    self.equality,
                    "weld",
                    name=f"rivet/{strut}/{cf}",
                    body1=strut,
                    body2=cf,
                    active="false",
                    solref=phys["rivet_solref"],
                )
        for arm in names.ARMS:
            for part in self.info.parts.values():
                _sub(
                    self.equality,
                    "weld",
                    name=f"grasp/{arm}/{part.body}",
                    body1=names.ee_body(arm),
                    body2=part.body,
                    active="false",
                    solref=phys["grasp_solref"],
                )


def rack_uprights(
    cross_frame: bool, extent: float, bay_width: float, edu: dict[str, Any]
) -> list[tuple[int, int, float, float]]:
    """The four uprights of a part rack, ``(sx, sy, x, y)`` in the dispenser's frame.

    ``extent`` is the parts' length along the rack's x. A grasp puts the EE's rivet guns over both
    ends of the grasped bar, outboard of it: strut racks keep their uprights beyond the strut ends,
    and cross-frame racks (whose frames may be taken by any side) stand theirs diagonally out from
    each corner, a gun's half length plus a gap beyond it both ways, so that no side's guns meet
    them (an upright by a corner stopped the EE short of every frame below the top one).
    """
    if cross_frame:
        out = GUN_HALF[0] + UPRIGHT_HALF + UPRIGHT_GUN_GAP
        half_x, half_y = extent / 2 + out, bay_width / 2 + out
    else:
        half_x = extent / 2 + edu["end_effector"]["rivet_gun_offset"] * 0.9
        # Close to the strut's axis: beyond the strut ends they need no width, and wider they
        # stood where a rivet gun picks a rivet from the feeder beside the rack.
        half_y = 0.02
    return [(sx, sy, sx * half_x, sy * half_y) for sx in (-1, 1) for sy in (-1, 1)]


def build_model(
    edu: dict[str, Any], mission: Mission, out_dir: str | Path, scenario: Scenario = NOMINAL
) -> ModelInfo:
    """Write ``edu.xml`` and the tag textures into ``out_dir``; return what was built."""
    return _Builder(edu, mission, scenario, Path(out_dir)).build()


__all__ = ["CLASS_COLOURS", "ModelInfo", "PartInfo", "build_model"]
