"""The EDU's robot description (URDF) and its transform tree, read off the compiled twin model.

The twin's MJCF is generated from ``config/twin/edu.yaml`` and the UR10e table the planner uses
(:mod:`tlt_common.geometry.ur10e`), so a URDF read off the compiled model is that same machine:

* a link per body fixed to the world or moved by the EDU's own joints (lifter, carriages, grippers,
  camera mounts, arms, end effectors, dispensers), named as the body (``ars_x/link_3``); the world
  body is ``world``;
* a joint per body: the body's MuJoCo joint (``revolute`` for a hinge, ``prismatic`` for a slide,
  same name, axis and range; effort from its actuator, velocity the rated speed where given),
  or ``fixed`` (``<body>_mount``) for a body without one;
* a fixed link ``<camera>_optical`` per camera (x right, y down, z forward), as the twin's image
  headers name it;
* visuals of the bodies' visible geoms (boxes, cylinders, spheres; a capsule as a cylinder and two
  spheres), in their model colours.

Bodies on a free joint (the payload and every part) are not the robot: they move on their own and
are published as frames of the world (:func:`free_bodies`). A joint the URDF cannot say (a hinge
off its body's origin, two joints in one body) is refused with its name.

    tlt twin urdf -o edu.urdf
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from tlt_sim.model import names
from tlt_sim.model.generate import HIDDEN_GROUP

WORLD = "world"
ROBOT_NAME = "tlt_edu"
# Camera frames in MuJoCo look along -z with y up; optical frames look along +z with y down.
_MUJOCO_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])
_JOINT_TYPES = {int(mujoco.mjtJoint.mjJNT_HINGE): "revolute", int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic"}
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)


@dataclasses.dataclass(frozen=True)
class Link:
    """One URDF link and the joint that carries it: ``joint_type`` ``fixed``, ``revolute`` or
    ``prismatic``; ``body`` the MuJoCo body id (-1 for a camera's optical frame); ``origin`` its
    pose in ``parent`` at joint zero (position, rotation)."""

    name: str
    parent: str
    body: int
    joint: str
    joint_type: str
    origin: tuple[np.ndarray, np.ndarray]
    joint_id: int = -1


def _body_name(model: mujoco.MjModel, b: int) -> str:
    return WORLD if b == 0 else model.body(b).name


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=float))
    return out.reshape(3, 3)


def free_bodies(model: mujoco.MjModel) -> list[int]:
    """Bodies on a free joint (payload, parts): not the robot, frames of the world."""
    return [int(model.jnt_bodyid[j]) for j in range(model.njnt) if model.jnt_type[j] == _FREE]


def _robot_bodies(model: mujoco.MjModel) -> list[int]:
    """Bodies other than the world that no free joint carries, parents before children."""
    free = set(free_bodies(model))
    out: list[int] = []
    kept = {0}
    for b in range(1, model.nbody):
        if b in free or int(model.body_parentid[b]) not in kept:
            continue
        kept.add(b)
        out.append(b)
    return out


def links(model: mujoco.MjModel) -> list[Link]:
    """The URDF's links, parents before children, camera optical frames last."""
    out: list[Link] = []
    for b in _robot_bodies(model):
        name = _body_name(model, b)
        parent = _body_name(model, int(model.body_parentid[b]))
        origin = (model.body_pos[b].copy(), _quat_matrix(model.body_quat[b]))
        n = int(model.body_jntnum[b])
        if n == 0:
            out.append(Link(name, parent, b, f"{name}_mount", "fixed", origin))
            continue
        j = int(model.body_jntadr[b])
        joint = model.joint(j).name
        if n > 1:
            raise ValueError(f"body {name}: {n} joints in one body (a URDF link has one)")
        if int(model.jnt_type[j]) not in _JOINT_TYPES:
            raise ValueError(f"joint {joint}: type {int(model.jnt_type[j])} has no URDF joint")
        if np.linalg.norm(model.jnt_pos[j]) > 1e-9:
            raise ValueError(f"joint {joint}: off its body's origin (the URDF joint frame is the link's)")
        out.append(Link(name, parent, b, joint, _JOINT_TYPES[int(model.jnt_type[j])], origin, j))
    for c in range(model.ncam):
        camera = model.camera(c).name
        rot = _quat_matrix(model.cam_quat[c]) @ _MUJOCO_TO_OPTICAL
        parent = _body_name(model, int(model.cam_bodyid[c]))
        frame = names.optical_frame(camera)
        out.append(Link(frame, parent, -1, f"{frame}_mount", "fixed", (model.cam_pos[c].copy(), rot)))
    return out


def _origin(el: ET.Element, pos: np.ndarray, rot: np.ndarray) -> None:
    with warnings.catch_warnings():  # at pitch +-90 deg any split of roll and yaw is the same rotation
        warnings.simplefilter("ignore", UserWarning)
        rpy = Rotation.from_matrix(rot).as_euler("xyz")  # extrinsic x, y, z: URDF's roll, pitch, yaw
    ET.SubElement(
        el,
        "origin",
        xyz=" ".join(f"{v:.6g}" for v in pos),
        rpy=" ".join(f"{v:.9g}" for v in rpy),
    )


def _visual(link: ET.Element, shape: str, attrs: dict[str, str], pos, rot, rgba: np.ndarray) -> None:
    visual = ET.SubElement(link, "visual")
    _origin(visual, np.asarray(pos), rot)
    geometry = ET.SubElement(visual, "geometry")
    ET.SubElement(geometry, shape, **attrs)
    material = ET.SubElement(visual, "material", name="rgba " + " ".join(f"{v:.3g}" for v in rgba))
    ET.SubElement(material, "color", rgba=" ".join(f"{v:.3g}" for v in rgba))


def _geom_rgba(model: mujoco.MjModel, g: int) -> np.ndarray:
    m = int(model.geom_matid[g])
    return model.mat_rgba[m] if m >= 0 else model.geom_rgba[g]


def visible_geoms(model: mujoco.MjModel, body: int) -> list[int]:
    """The geoms of ``body`` a viewer should draw now: not hidden (a part's rivets until they are
    set, :mod:`tlt_sim.model.assembly`), not clear, not the floor."""
    return [
        g
        for g in range(
            int(model.body_geomadr[body]), int(model.body_geomadr[body] + model.body_geomnum[body])
        )
        if int(model.geom_group[g]) != HIDDEN_GROUP
        and int(model.geom_type[g]) != int(mujoco.mjtGeom.mjGEOM_PLANE)
        and _geom_rgba(model, g)[3] > 0
    ]


def geom_shapes(model: mujoco.MjModel, g: int) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Geom ``g`` as primitive shapes ``(kind, size, position, rotation)`` in its body's frame:
    ``box`` (full extents), ``cylinder`` (diameter, diameter, length along z), ``sphere``
    (diameter x3); a capsule is a cylinder and two spheres."""
    size, pos, rot = model.geom_size[g], model.geom_pos[g].copy(), _quat_matrix(model.geom_quat[g])
    kind = int(model.geom_type[g])
    if kind == int(mujoco.mjtGeom.mjGEOM_BOX):
        return [("box", 2 * size.copy(), pos, rot)]
    if kind == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        return [("sphere", np.full(3, 2 * size[0]), pos, rot)]
    if kind in (int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_CAPSULE)):
        out = [("cylinder", np.array([2 * size[0], 2 * size[0], 2 * size[1]]), pos, rot)]
        if kind == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
            for end in (-1.0, 1.0):
                out.append(("sphere", np.full(3, 2 * size[0]), pos + end * size[1] * rot[:, 2], rot))
        return out
    raise ValueError(f"geom {model.geom(g).name or g}: type {kind} has no primitive shape")


def _add_visuals(model: mujoco.MjModel, link: ET.Element, body: int) -> None:
    for g in visible_geoms(model, body):
        rgba = _geom_rgba(model, g)
        for kind, size, pos, rot in geom_shapes(model, g):
            if kind == "box":
                attrs = {"size": " ".join(f"{v:.6g}" for v in size)}
            elif kind == "sphere":
                attrs = {"radius": f"{size[0] / 2:.6g}"}
            else:
                attrs = {"radius": f"{size[0] / 2:.6g}", "length": f"{size[2]:.6g}"}
            _visual(link, kind, attrs, pos, rot, rgba)


def _effort(model: mujoco.MjModel, joint_id: int) -> float:
    for a in range(model.nu):
        if int(model.actuator_trnid[a, 0]) == joint_id and model.actuator_forcelimited[a]:
            return float(np.max(np.abs(model.actuator_forcerange[a])))
    return 0.0


def urdf(model: mujoco.MjModel, velocities: Mapping[str, float] | None = None, name: str = ROBOT_NAME) -> str:
    """The URDF document of ``model`` (see the module docstring); ``velocities``: joint name ->
    rated speed (rad/s or m/s) for the joints' limits, 0 where not given."""
    velocities = velocities or {}
    robot = ET.Element("robot", name=name)
    ET.SubElement(robot, "link", name=WORLD)
    for link in links(model):
        el = ET.SubElement(robot, "link", name=link.name)
        if link.body >= 0:
            _add_visuals(model, el, link.body)
        joint = ET.SubElement(robot, "joint", name=link.joint, type=link.joint_type)
        ET.SubElement(joint, "parent", link=link.parent)
        ET.SubElement(joint, "child", link=link.name)
        _origin(joint, *link.origin)
        if link.joint_id >= 0:
            j = link.joint_id
            ET.SubElement(joint, "axis", xyz=" ".join(f"{v:.6g}" for v in model.jnt_axis[j]))
            lo, hi = model.jnt_range[j] if model.jnt_limited[j] else (-np.pi, np.pi)
            ET.SubElement(
                joint,
                "limit",
                lower=f"{lo:.6g}",
                upper=f"{hi:.6g}",
                effort=f"{_effort(model, j):.6g}",
                velocity=f"{velocities.get(link.joint, 0.0):.6g}",
            )
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def main(argv: list[str] | None = None) -> int:
    """``tlt twin urdf``: write the EDU's URDF (to a file or stdout). Returns the exit status."""
    from tlt_sim.model.config import DEFAULT_EDU
    from tlt_sim.model.scene import Scene

    p = argparse.ArgumentParser(
        prog="tlt twin urdf", description="write the EDU's URDF, read off the twin model"
    )
    p.add_argument("-o", "--output", type=Path, help="file to write (default: stdout)")
    p.add_argument("--edu", type=Path, default=DEFAULT_EDU, help="machine description (edu.yaml)")
    p.add_argument("--mission", type=Path, help="mission YAML (default: the one edu.yaml names)")
    args = p.parse_args(argv)
    with Scene(args.edu, args.mission) as scene:
        text = urdf(scene.model, {j: scene.max_velocity(j) for j in names.all_actuated_joints()})
    if args.output is None:
        sys.stdout.write(text)
    else:
        args.output.write_text(text)
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = [
    "ROBOT_NAME",
    "WORLD",
    "Link",
    "free_bodies",
    "geom_shapes",
    "links",
    "main",
    "urdf",
    "visible_geoms",
]
