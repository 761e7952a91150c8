"""PlanMotion: a stale joint state is waited out (a gap under load is no fault), not failed at once."""

from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import numpy as np
from py_trees.common import Status

from tlt_ars.motion import MotionGoal, PlanMotion, TrajectorySlot


class Arm:
    """What PlanMotion reads of the ARS context: the mission clock, the arm state, the request."""

    def __init__(self) -> None:
        self.now, self.q = 0.0, np.zeros(6)
        self.joint_topic = "/ur_x/joint_states"
        self.config = SimpleNamespace(arm={"stopped_velocity": 0.01}, timeouts={"planning_s": 15.0})
        self.data = SimpleNamespace(member=None, holding=None, targets={})
        self.state = SimpleNamespace(placed=lambda: [])
        self.planning_pool = ThreadPoolExecutor(max_workers=1)

    def clock(self) -> float:
        return self.now

    def arm_q(self):
        return self.q

    def arm_velocity(self):
        return None if self.q is None else np.zeros(6)

    def other_arm_q(self):
        return None

    def ee_width(self):
        return 0.0


class Planner:
    def __init__(self) -> None:
        self.starts: list[np.ndarray] = []

    def plan(self, start, goal, **_):
        self.starts.append(start)
        return SimpleNamespace(duration=1.0, target=None)


def _run(b: PlanMotion, arm: Arm, t: float) -> Status:
    arm.now = t
    b.tick_once()
    if b.status == Status.RUNNING and b._future is not None:
        b._future.result()  # the plan itself is instant here
        b.tick_once()
    return b.status


def test_a_gap_in_the_joint_states_is_waited_out_and_the_plan_starts_from_the_fresh_state():
    arm, planner, slot = Arm(), Planner(), TrajectorySlot()
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), slot)
    arm.q = None
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert b.feedback_message == "waiting for a fresh joint state" and planner.starts == []
    arm.q = np.full(6, 0.3)
    assert _run(b, arm, 2.0) == Status.SUCCESS
    assert np.allclose(planner.starts[0], 0.3) and slot.motion is not None


def test_without_a_fresh_joint_state_within_planning_s_it_fails_naming_the_topic():
    arm = Arm()
    b = PlanMotion("Plan", arm, Planner(), lambda: MotionGoal(joints=np.ones(6)), TrajectorySlot())
    arm.q = None
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert _run(b, arm, 16.0) == Status.FAILURE
    assert "no fresh joint state on '/ur_x/joint_states' within 15 s" in b.feedback_message
