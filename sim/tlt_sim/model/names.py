"""Stable names of the twin's joints, actuators, cameras, bodies and equality constraints.

Every actuated joint has a position actuator of the same name. Emulators bind to these names, so
they change only together with docs/twin.md.

Corners are numbered around the bay square: 0 = x0_y0, 1 = x1_y0, 2 = x1_y1, 3 = x0_y1 (the
lifter posts, carriages, Active and Top Grippers follow the same numbering). Joint names follow the
hardware maps in ``config/hardware/``: the lifter's joints count from 0 (``lifter_joint_0..3``, as
lifter.yaml), the servos from 1 (``active_gripper_1..4``, ``top_gripper_1..4``,
``camera_mount_1..2``, as their servo ids); the functions below take the 0-based index.
"""

from __future__ import annotations

from tlt_common.geometry import ur10e

CORNERS = ("x0_y0", "x1_y0", "x1_y1", "x0_y1")
CORNER_XY = ((0, 0), (1, 0), (1, 1), (0, 1))
ARMS = ("ars_x", "ars_y")
ZED_CORNERS = (1, 3)  # the ZED mounts stand on the posts of the far corners x1_y0 and x0_y1


def lifter_joint(i: int) -> str:
    return f"lifter_joint_{i}"


def active_gripper(i: int) -> str:
    return f"active_gripper_{i + 1}"


def top_gripper(i: int) -> str:
    return f"top_gripper_{i + 1}"


def camera_mount(i: int) -> str:
    return f"camera_mount_{i + 1}"


def zed_camera(i: int) -> str:
    return f"zed_{i + 1}"


def arm_joint(arm: str, i: int) -> str:
    return f"{arm}/{ur10e.JOINT_NAMES[i]}_joint"


def arm_joints(arm: str) -> list[str]:
    return [arm_joint(arm, i) for i in range(6)]


def grasp_joint(arm: str, side: str) -> str:
    return f"{arm}/grasp_{side}"


def loaded_rivet_geom(arm: str, side: str) -> str:
    """The rivet drawn in gun ``side`` of ``arm`` while it is loaded (vision class ``rivet``)."""
    return f"{arm}/rivet_gun_{side}/rivet_loaded"


def width_joint(arm: str) -> str:
    return f"{arm}/width"


def d405_camera(arm: str, side: str) -> str:
    return f"{arm}/d405_{side}"


def rivet_gun_site(arm: str, side: str) -> str:
    return f"{arm}/rivet_gun_{side}"


def ee_body(arm: str) -> str:
    return f"{arm}/ee"


def part_body(dispenser: str, index: int) -> str:
    return f"part/{dispenser}/{index}"


def corner_site(cross_frame_body: str, corner: int) -> str:
    return f"{cross_frame_body}/corner_{CORNERS[corner]}"


def all_actuated_joints() -> list[str]:
    """Every joint with an actuator, in a fixed order."""
    names = [lifter_joint(i) for i in range(4)]
    names += [active_gripper(i) for i in range(4)]
    names += [top_gripper(i) for i in range(4)]
    names += [camera_mount(i) for i in range(len(ZED_CORNERS))]
    for arm in ARMS:
        names += arm_joints(arm)
        names += [grasp_joint(arm, "a"), grasp_joint(arm, "b"), width_joint(arm)]
    return names


def optical_frame(camera: str) -> str:
    """Frame id of a camera's optical frame (x right, y down, z forward), as its images name it."""
    return f"{camera}_optical"


def cameras() -> list[str]:
    names = [zed_camera(i) for i in range(len(ZED_CORNERS))]
    for arm in ARMS:
        names += [d405_camera(arm, "a"), d405_camera(arm, "b")]
    return names
