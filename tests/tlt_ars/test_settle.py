"""Settle: the arm stands still for ``arm.settle_s`` of mission time before the EE camera is used."""

from types import SimpleNamespace

import numpy as np
from py_trees.common import Status

from tlt_ars.motion import Settle


class Arm:
    """Mission clock and joint velocities as the ARS context reads them."""

    def __init__(self) -> None:
        self.now, self.velocity, self.q = 0.0, np.zeros(6), np.zeros(6)
        self.joint_topic = "/ur_x/joint_states"
        self.config = SimpleNamespace(
            arm={"stopped_velocity": 0.01, "settle_s": 1.0}, timeouts={"planning_s": 15.0}
        )

    def clock(self) -> float:
        return self.now

    def arm_velocity(self):
        return self.velocity

    def arm_q(self):
        return self.q


def _tick(b: Settle, arm: Arm, t: float, moving: bool = False) -> Status:
    arm.now = t
    arm.velocity = np.full(6, 0.2 if moving else 0.0)
    b.tick_once()
    return b.status


def test_succeeds_once_the_arm_has_stood_still_for_settle_s():
    arm = Arm()
    b = Settle("Settle", arm)
    assert _tick(b, arm, 0.0, moving=True) == Status.RUNNING
    assert _tick(b, arm, 0.5) == Status.RUNNING  # still since 0.5
    assert _tick(b, arm, 1.2, moving=True) == Status.RUNNING  # moved again: starts over
    assert _tick(b, arm, 1.4) == Status.RUNNING
    assert _tick(b, arm, 2.3) == Status.RUNNING
    assert _tick(b, arm, 2.4) == Status.SUCCESS


def test_fails_when_the_arm_keeps_moving_or_its_state_is_stale():
    arm = Arm()
    b = Settle("Settle", arm)
    assert _tick(b, arm, 0.0, moving=True) == Status.RUNNING
    assert _tick(b, arm, 16.0, moving=True) == Status.FAILURE
    assert "did not settle within 15 s: still moving" in b.feedback_message
    arm.arm_q = lambda: None
    b = Settle("Settle", arm)
    assert _tick(b, arm, 20.0) == Status.RUNNING
    assert _tick(b, arm, 36.0) == Status.FAILURE
    assert "no fresh joint state on '/ur_x/joint_states'" in b.feedback_message


def test_a_gap_in_the_joint_states_is_waited_out_and_restarts_the_stillness():
    arm = Arm()
    b = Settle("Settle", arm)
    assert _tick(b, arm, 0.0) == Status.RUNNING  # still since 0
    fresh = arm.arm_q
    arm.arm_q = lambda: None
    assert _tick(b, arm, 0.8) == Status.RUNNING
    assert b.feedback_message == "waiting for a fresh joint state"
    arm.arm_q = fresh
    assert _tick(b, arm, 1.5) == Status.RUNNING  # still since 1.5, not since 0
    assert _tick(b, arm, 2.5) == Status.SUCCESS


def test_without_velocities_the_positions_tell_whether_the_arm_moves():
    arm = Arm()
    arm.arm_velocity = lambda: None
    b = Settle("Settle", arm)
    for t, q in ((0.0, 0.0), (0.1, 0.05), (0.2, 0.05), (0.7, 0.05), (1.1, 0.05)):
        arm.now, arm.q = t, np.full(6, q)
        b.tick_once()
        assert b.status == Status.RUNNING, t  # first tick: no speed yet; then moving; then still from 0.2
    arm.now = 1.25
    b.tick_once()
    assert b.status == Status.SUCCESS
