"""The EDU's URDF (tlt_sim.model.urdf): well-formed, every joint of the twin in it, and its
kinematics the twin's own, so a viewer that poses its links by /tf and the URDF shows the twin."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
from tlt_sim.model import names, urdf

from tlt_common.geometry.transforms import rpy_matrix

_TYPES = {int(mujoco.mjtJoint.mjJNT_HINGE): "revolute", int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic"}


def _floats(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def _axis_motion(kind: str, axis: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    if kind == "prismatic":
        return axis * q, np.eye(3)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.zeros(3), np.eye(3) + np.sin(q) * k + (1 - np.cos(q)) * k @ k


def _forward_kinematics(doc: ET.Element, q: dict[str, float]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every link's world pose by the URDF's joints alone (parents are listed before children)."""
    poses = {"world": (np.zeros(3), np.eye(3))}
    for joint in doc.findall("joint"):
        pp, pr = poses[joint.find("parent").get("link")]
        origin = joint.find("origin")
        p = pp + pr @ _floats(origin.get("xyz"))
        r = pr @ rpy_matrix(_floats(origin.get("rpy")))
        if joint.get("type") != "fixed":
            dp, dr = _axis_motion(
                joint.get("type"), _floats(joint.find("axis").get("xyz")), q[joint.get("name")]
            )
            p, r = p + r @ dp, r @ dr
        poses[joint.find("child").get("link")] = (p, r)
    return poses


def test_the_urdf_parses_and_names_every_joint_of_the_twin(scene):
    m = scene.model
    doc = ET.fromstring(urdf.urdf(scene.model))
    assert doc.tag == "robot" and doc.get("name") == urdf.ROBOT_NAME
    joints = {j.get("name"): j for j in doc.findall("joint")}
    moving = {
        m.joint(j).name: _TYPES[int(m.jnt_type[j])] for j in range(m.njnt) if int(m.jnt_type[j]) in _TYPES
    }
    assert set(names.all_actuated_joints()) <= set(moving)
    for name, kind in moving.items():
        assert name in joints, f"joint {name} missing from the URDF"
        assert joints[name].get("type") == kind
        lo, hi = m.jnt_range[m.joint(name).id]
        limit = joints[name].find("limit")
        assert float(limit.get("lower")) == np.float32(lo) or abs(float(limit.get("lower")) - lo) < 1e-5
        assert abs(float(limit.get("upper")) - hi) < 1e-5
    # One tree: every link but the world is the child of exactly one joint, whose parent is a link.
    link_names = [link.get("name") for link in doc.findall("link")]
    assert len(link_names) == len(set(link_names))
    children = [j.find("child").get("link") for j in joints.values()]
    assert sorted(children) == sorted(n for n in link_names if n != "world")
    assert all(j.find("parent").get("link") in link_names for j in joints.values())
    # Free bodies (the payload and the parts) are frames of the world, not links of the robot.
    assert "payload" not in link_names and not any(n.startswith("part/") for n in link_names)
    for camera in names.cameras():
        assert names.optical_frame(camera) in link_names
    assert len(doc.findall("link/visual")) > 100


def test_the_urdfs_kinematics_are_the_twins(scene):
    m, d = scene.model, scene.data
    rng = np.random.default_rng(7)
    q = {}
    for j in range(m.njnt):
        if int(m.jnt_type[j]) in _TYPES:
            lo, hi = m.jnt_range[j]
            q[m.joint(j).name] = d.qpos[m.jnt_qposadr[j]] = rng.uniform(lo, hi)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_camlight(m, d)
    poses = _forward_kinematics(ET.fromstring(urdf.urdf(m)), q)
    for b in range(1, m.nbody):
        name = m.body(b).name
        if name in poses:
            assert np.allclose(poses[name][0], d.xpos[b], atol=1e-5), name
            assert np.allclose(poses[name][1], d.xmat[b].reshape(3, 3), atol=1e-5), name
    for camera in names.cameras():
        p, r = scene.camera_pose(camera)
        assert np.allclose(poses[names.optical_frame(camera)][0], p, atol=1e-5), camera
        assert np.allclose(poses[names.optical_frame(camera)][1], r, atol=1e-5), camera
