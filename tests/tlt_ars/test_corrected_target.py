"""The correction after a fine-alignment measurement moves the held part, not the tool, onto its
place: vision reports the part's own frame, which for a diagonal is off the tool."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from tlt_interfaces.srv import CheckAlignment

from tlt_ars.behaviours.vision import corrected_target
from tlt_ars.planning.targets import part_in_tool, placement_targets
from tlt_ars.planning.world import load_scene_config
from tlt_common.geometry.transforms import pose_matrix, rpy_matrix
from tlt_common.mission.schema import load_mission

MISSION = load_mission(Path(__file__).resolve().parents[2] / "missions" / "one_bay.yaml")


def _pose_msg(m: np.ndarray):
    from geometry_msgs.msg import Pose

    from tlt_ars.behaviours.vision import pose_to_matrix  # the reading side, to check the round trip

    w, x, y, z = _quaternion(m[:3, :3])
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in m[:3, 3])
    p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z = w, x, y, z
    assert np.allclose(pose_to_matrix(p), m, atol=1e-9)
    return p


def _quaternion(r: np.ndarray) -> tuple[float, float, float, float]:
    w = np.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = np.copysign(np.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return float(w), float(x), float(y), float(z)


@pytest.mark.parametrize("member_id", ["bay1/diagonal/face_x0", "bay1/vertical/x0_y1"])
def test_the_corrected_tool_pose_puts_the_part_seen_off_its_place_on_it(member_id):
    cfg = load_scene_config()
    member = MISSION.member(member_id)
    target = placement_targets(cfg, MISSION, member, member.add_ars)[0]
    in_tool = part_in_tool(MISSION, member.kind)
    q = np.array(cfg.home(member.add_ars), dtype=float)
    tool = cfg.kinematics(member.add_ars).forward(q)
    # The part sits in the jaws 6 mm and 1.5 degrees off where the ARS took it.
    slip = pose_matrix((0.0, 0.004, 0.0045), rpy_matrix((0.0, 0.026, 0.0)))
    part = tool @ in_tool @ slip
    response = CheckAlignment.Response()
    response.pose.certified = True
    response.pose.header.frame_id = "world"
    response.pose.pose = _pose_msg(part)
    ctx = SimpleNamespace(
        data=SimpleNamespace(alignment=response, targets={"place": target}, member=member),
        config=SimpleNamespace(cameras={"world_frame": "world"}),
        scene=cfg, ars=member.add_ars, mission=MISSION, arm_q=lambda: q,
    )  # fmt: skip
    corrected = corrected_target(ctx, "place").pose
    # Moving the tool from where it is to the corrected pose carries the part onto its place.
    moved = corrected @ np.linalg.inv(tool) @ part
    assert np.allclose(moved, target.pose @ in_tool, atol=1e-9)
