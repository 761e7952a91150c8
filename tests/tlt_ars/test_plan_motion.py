"""PlanMotion and ExecuteTrajectory: a stale joint state is waited out (a gap under load is no fault),
not failed at once."""

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import numpy as np
import pytest
import rclpy
from py_trees.common import Status
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from tlt_ars.motion import ExecuteTrajectory, PlanMotion, TrajectorySlot
from tlt_ars.motion_planner import MotionGoal
from tlt_ars.planning.planner import PlanningFailed


class Arm:
    """What PlanMotion reads of the ARS context: the mission clock, the arm state, the request."""

    def __init__(self) -> None:
        self.now, self.q = 0.0, np.zeros(6)
        self.down: str | None = None  # the UR driver's fault while it is not active
        self.width: float | tuple[float, float] | None = 0.0  # None: uncalibrated; a pair: moving
        self.joint_topic, self.ee_topic = "/ur_x/joint_states", "/ee_x/state"
        self.config = SimpleNamespace(
            arm={"stopped_velocity": 0.01}, timeouts={"planning_s": 15.0, "width_s": 120.0}
        )
        self.data = SimpleNamespace(member=None, holding=None, targets={})
        self.state = SimpleNamespace(placed=lambda: [])
        self.planning_pool = ThreadPoolExecutor(max_workers=1)
        self.node = SimpleNamespace(get_logger=lambda: rclpy.logging.get_logger("ars_x"))

    def clock(self) -> float:
        return self.now

    def arm_q(self):
        return self.q

    def arm_down(self):
        return self.down

    def arm_velocity(self):
        return None if self.q is None else np.zeros(6)

    def other_arm_q(self):
        return None

    def planning_width(self):
        return self.width


class Planner:
    """A search that finds its path only with ``needs`` seconds or more to search."""

    search_time = 2.0

    def __init__(self, blocked_while_moving: bool = False, needs: float = 0.0) -> None:
        self.starts: list[np.ndarray] = []
        self.widths: list = []
        self.search_times: list[float] = []
        self.blocked_while_moving = blocked_while_moving
        self.needs = needs

    def plan(self, start, goal, *, width, search_time, **_):
        self.starts.append(start)
        self.widths.append(width)
        self.search_times.append(search_time)
        if self.blocked_while_moving and isinstance(width, tuple):
            raise PlanningFailed("collision", "gun b's bracket would sweep through the tag post")
        if search_time < self.needs:
            raise PlanningFailed("timeout", f"no path within {search_time:.3f} s")
        return SimpleNamespace(duration=1.0, target=None)


def _run(b: PlanMotion, arm: Arm, t: float, searches: int = 1) -> Status:
    """Tick at mission time ``t`` until ``searches`` plans have ended (or it stops planning)."""
    arm.now = t
    b.tick_once()
    for _ in range(searches):
        if b.status != Status.RUNNING or b._future is None:
            break
        b._future.exception()  # waits: the plan itself is instant here
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


def test_planning_waits_for_a_calibrated_width_and_plans_with_it():
    """A width servo rebooted after a fault reads a wrong width until the EE recalibrates it: the
    plan waits for the calibrated width (gripper b and its gun ride the slide) as long as a width
    move may take, not just a plan's time, or fails naming it."""
    arm, planner, slot = Arm(), Planner(), TrajectorySlot()
    widths = planner.widths
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), slot)
    arm.width = None
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert b.feedback_message == "waiting for a calibrated end-effector width" and widths == []
    arm.width = 0.25
    assert _run(b, arm, 2.0) == Status.SUCCESS and widths == [0.25]
    arm.width = None
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), TrajectorySlot())
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert _run(b, arm, 16.0) == Status.RUNNING  # past planning_s: a recalibration takes longer
    assert _run(b, arm, 136.0) == Status.FAILURE
    assert "no calibrated end-effector width on '/ee_x/state' within 135 s" in b.feedback_message


def test_a_motion_planned_while_the_width_moves_is_checked_over_the_move_or_waits_for_it():
    """Extend Width runs beside the approach: the approach is checked with the slide anywhere on
    the rest of its move; when nothing clears that, the plan waits for the slide to stand."""
    arm, slot = Arm(), TrajectorySlot()
    planner = Planner()
    arm.width = (0.05, 0.25)
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), slot)
    assert _run(b, arm, 0.0) == Status.SUCCESS and planner.widths == [(0.05, 0.25)]

    planner = Planner(blocked_while_moving=True)
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), slot)
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert "no path clears the moving width" in b.feedback_message
    assert _run(b, arm, 14.0) == Status.RUNNING and len(planner.widths) == 1
    assert b.feedback_message == "waiting for the end-effector width to stand"
    arm.width = 0.25
    assert _run(b, arm, 16.0) == Status.SUCCESS and planner.widths == [(0.05, 0.25), 0.25]

    arm.width = (0.05, 0.25)  # a slide that never gets there
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), TrajectorySlot())
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert _run(b, arm, 130.0) == Status.RUNNING
    assert _run(b, arm, 136.0) == Status.FAILURE
    assert "the end-effector width did not reach 0.2500 m within 135 s" in b.feedback_message


def test_a_search_out_of_time_is_run_again_from_the_same_start_with_twice_the_time():
    """The search's time is wall-clock: on a loaded machine it gets less CPU. The arm has not
    moved, so the same start is searched again with 4 s, then 8 s, while that fits in planning_s."""
    arm, slot = Arm(), TrajectorySlot()
    planner = Planner(needs=5.0)
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), slot)
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert b.feedback_message == "planning again with 4 s to search"
    arm.q = np.full(6, 0.3)  # a later joint state is not where the first search started
    assert _run(b, arm, 2.0, searches=2) == Status.SUCCESS and slot.motion is not None
    assert planner.search_times == [2.0, 4.0, 8.0]
    assert all(np.allclose(s, 0.0) for s in planner.starts)

    # The next motion starts again from the configured search time.
    assert _run(b, arm, 20.0) == Status.RUNNING
    assert b.feedback_message == "planning again with 4 s to search"
    b._future.exception()  # the second search of this motion has run
    assert planner.search_times[3:] == [2.0, 4.0]

    # No more time than planning_s: 2 s + 4 s searched, 8 s more would end at 14 s of 10.
    arm.config.timeouts["planning_s"] = 10.0
    planner = Planner(needs=100.0)
    b = PlanMotion("Plan", arm, planner, lambda: MotionGoal(joints=np.ones(6)), TrajectorySlot())
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert _run(b, arm, 6.0, searches=2) == Status.FAILURE and planner.search_times == [2.0, 4.0]
    assert b.feedback_message == "planning failed (timeout): no path within 4.000 s"


def test_without_a_fresh_joint_state_within_planning_s_it_fails_naming_the_topic():
    arm = Arm()
    b = PlanMotion("Plan", arm, Planner(), lambda: MotionGoal(joints=np.ones(6)), TrajectorySlot())
    arm.q = None
    assert _run(b, arm, 0.0) == Status.RUNNING
    assert _run(b, arm, 16.0) == Status.FAILURE
    assert "no fresh joint state on '/ur_x/joint_states' within 15 s" in b.feedback_message


class Driver:
    """A FollowJointTrajectory server in the test's own rclpy context, on a spinning thread: the
    goals it received."""

    def __init__(self) -> None:
        from rclpy.action import ActionServer
        from rclpy.executors import SingleThreadedExecutor
        from tlt_interfaces.action import FollowJointTrajectory

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("execute_trajectory_test", context=self.context)
        self.goals: list = []

        def execute(handle):
            self.goals.append(handle.request)
            handle.succeed()
            return FollowJointTrajectory.Result()

        self.server = ActionServer(self.node, FollowJointTrajectory, "/ur_x/follow_joint_trajectory", execute)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=5)  # before the entities its wait set holds are destroyed
        self.server.destroy()
        self.node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def driver():
    d = Driver()
    try:
        yield d
    finally:
        d.close()


def _execute(driver: Driver, arm: Arm) -> ExecuteTrajectory:
    arm.node, arm.ars = driver.node, "ars_x"
    arm.config.timeouts.update(server_s=30.0, trajectory_margin_s=5.0)
    arm.config.arm.update(path_tolerance=0.1, goal_tolerance=0.01, goal_time_tolerance_s=1.0)
    slot = TrajectorySlot()
    slot.motion = SimpleNamespace(
        duration=1.0,
        trajectory=JointTrajectory(
            joint_names=[f"j{i}" for i in range(6)], points=[JointTrajectoryPoint(positions=[0.0] * 6)]
        ),
    )
    return ExecuteTrajectory("Execute", arm, slot)


def _tick_until(b: ExecuteTrajectory, done, seconds: float = 10.0) -> None:
    deadline = time.monotonic() + seconds
    while not done():
        assert time.monotonic() < deadline, b.feedback_message
        b.tick_once()
        time.sleep(0.02)


def test_execute_waits_for_a_fresh_joint_state_before_it_sends_the_goal(driver):
    arm = Arm()
    b = _execute(driver, arm)
    arm.q = None
    for _ in range(20):
        b.tick_once()
        time.sleep(0.01)
    assert b.status == Status.RUNNING
    assert b.feedback_message == "waiting for a fresh joint state to start from" and driver.goals == []
    arm.now, arm.q = 3.0, np.zeros(6)
    _tick_until(b, lambda: b.status == Status.SUCCESS)
    assert len(driver.goals) == 1


def test_execute_without_a_fresh_joint_state_within_planning_s_fails_naming_the_topic(driver):
    arm = Arm()
    b = _execute(driver, arm)
    arm.q = None
    b.tick_once()
    arm.now = 16.0
    _tick_until(b, lambda: b.status == Status.FAILURE)
    assert "no fresh joint state on '/ur_x/joint_states' to start from" in b.feedback_message
    assert driver.goals == []


def test_execute_waits_for_the_arm_to_be_active_again_before_it_sends_the_goal(driver):
    arm = Arm()
    b = _execute(driver, arm)
    arm.down = "read failed: no data from the controller at 127.0.0.2 for 0.61 s"
    for _ in range(20):
        b.tick_once()
        time.sleep(0.01)
    assert b.status == Status.RUNNING and driver.goals == []
    assert b.feedback_message == f"waiting for the arm to be active again ({arm.down})"
    arm.now, arm.down = 1.2, None  # the driver reconnected
    _tick_until(b, lambda: b.status == Status.SUCCESS)
    assert len(driver.goals) == 1


def test_a_pose_goal_whose_candidates_all_ran_out_of_search_time_fails_as_a_timeout():
    """PlanMotion searches again only after a timeout: a pose goal tried over its candidates must
    say so when each of them ran out of time, not that none can be reached."""
    from tlt_ars.motion_planner import MotionPlanner
    from tlt_ars.planning.targets import inspection_targets
    from tlt_ars.planning.world import load_scene_config
    from tlt_common.mission.schema import load_mission

    cfg = load_scene_config()
    planner = MotionPlanner(cfg, "ars_x", load_mission("missions/one_bay.yaml"), [f"j{i}" for i in range(6)],
                            velocity_scale=0.5, sample_period=0.05)  # fmt: skip
    assert planner.search_time == cfg.planning["planning_time_s"]
    # Home to the inspection pose with a vertical held: no straight line, a search is needed.
    goal = MotionGoal(targets=inspection_targets(cfg, "ars_x"))
    kwargs = dict(placed=set(), bay=1, carrying="vertical_dispenser_x", other_q=None)
    with pytest.raises(PlanningFailed) as err:
        planner.plan(cfg.home("ars_x"), goal, search_time=1e-6, **kwargs)
    assert err.value.kind == "timeout" and "none of 2 candidate(s) is usable" in err.value.reason
    assert planner.plan(cfg.home("ars_x"), goal, **kwargs).target.label.startswith("inspection")
