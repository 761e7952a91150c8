"""JointGroupPositionController: commands inside the limits apply, anything else is rejected with a reason."""

from __future__ import annotations

import pytest

from tlt_drivers.controllers.group_position import CommandRejected, JointGroupPositionController


def make(**kw):
    return JointGroupPositionController(["width", "tilt"], {"width": (0.0, 0.2), "tilt": (-1.0, 1.0)}, **kw)


def test_holds_actual_until_commanded_then_applies():
    c = make()
    assert c.update({"width": 0.05, "tilt": 0.1}) == {"width": 0.05, "tilt": 0.1}
    c.set_command([0.1, -0.5])
    assert c.update({"width": 0.05, "tilt": 0.1}) == {"width": 0.1, "tilt": -0.5}


@pytest.mark.parametrize(
    ("values", "words"),
    [
        ([0.3, 0.0], "joint 'width': command 0.3 is above the upper limit 0.2"),
        ([0.1, -1.5], "joint 'tilt': command -1.5 is below the lower limit -1.0"),
        ([0.1], "1 value(s) for 2 joint(s)"),
        ([float("inf"), 0.0], "not a number"),
    ],
)
def test_rejections_name_joint_and_limit_and_keep_previous_command(values, words):
    c = make()
    c.set_command([0.1, 0.2])
    with pytest.raises(CommandRejected, match=words.replace("(", r"\(").replace(")", r"\)")):
        c.set_command(values)
    assert c.update({}) == {"width": 0.1, "tilt": 0.2}
    assert c.rejections == 1 and words in c.last_rejection


def test_motion_gate_rejects():
    c = make(motion_gate=lambda: "width joint is not calibrated")
    with pytest.raises(CommandRejected, match="not calibrated"):
        c.set_command([0.1, 0.0])
