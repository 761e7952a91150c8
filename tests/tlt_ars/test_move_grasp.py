"""MoveGrasp against an EE trajectory server: while the end effector reports itself uncalibrated
(its driver refuses every motion until the width joint is zeroed on its limit switch, as after
power-up) the jaws' goal waits, and is sent once it is calibrated; an EE that stays uncalibrated
fails the step with that reason, and a faulted one is left to refuse the goal itself."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest
import rclpy
from py_trees.common import Status
from rclpy.action import ActionServer
from rclpy.executors import SingleThreadedExecutor
from tlt_interfaces.action import FollowJointTrajectory

from tlt_ars.behaviours.end_effector import MoveGrasp
from tlt_common import ros_names

EE = {"grasp_joints": ["ee_x_grasp_left", "ee_x_grasp_right"], "grasp_time_s": 0.1,
      "grasp_open": [0.0, 0.0], "grasp_closed": [0.7, 0.7]}  # fmt: skip


class EeState:
    """What the ARS's topic cache holds of ``/ee_x/state``."""

    def __init__(self) -> None:
        self.state = SimpleNamespace(calibrated=False, fault=False)

    def latest(self, topic: str):
        assert topic == "/ee_x/state"
        return self.state, time.monotonic()


@pytest.fixture
def rig():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("move_grasp_test", context=context)
    goals = []

    def execute(handle):
        goals.append(list(handle.request.trajectory.joint_names))
        handle.succeed()
        return FollowJointTrajectory.Result()

    server = ActionServer(
        node, FollowJointTrajectory, ros_names.trajectory_action(ros_names.ee("ars_x")), execute
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.02)

    spinner = threading.Thread(target=spin)
    spinner.start()
    cache = EeState()
    timeouts = {"server_s": 5.0, "trajectory_margin_s": 5.0, "width_s": 30.0}
    ctx = SimpleNamespace(
        node=node, cache=cache, ee_topic="/ee_x/state", ars="ars_x", clock=time.monotonic,
        config=SimpleNamespace(ee=EE, timeouts=timeouts),
    )  # fmt: skip
    yield SimpleNamespace(ctx=ctx, cache=cache, goals=goals)
    stop.set()
    spinner.join(timeout=5)
    server.destroy()
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def tick(step: MoveGrasp, seconds: float) -> Status:
    deadline = time.monotonic() + seconds
    step.tick_once()
    while step.status == Status.RUNNING and time.monotonic() < deadline:
        time.sleep(0.02)
        step.tick_once()
    return step.status


def test_the_jaws_wait_for_a_calibrated_end_effector_then_move(rig):
    step = MoveGrasp("Open Grasp", rig.ctx, close=False)
    assert tick(step, 1.0) == Status.RUNNING
    assert step.feedback_message == "waiting for the end effector to calibrate" and rig.goals == []
    rig.cache.state.calibrated = True
    assert tick(step, 10.0) == Status.SUCCESS, step.feedback_message
    assert rig.goals == [EE["grasp_joints"]]


def test_an_end_effector_that_stays_uncalibrated_fails_the_step_with_that_reason(rig):
    rig.ctx.config.timeouts["width_s"] = 0.3
    step = MoveGrasp("Open Grasp", rig.ctx, close=False)
    assert tick(step, 5.0) == Status.FAILURE
    assert "end effector not calibrated within 0.3 s" in step.feedback_message and rig.goals == []


def test_a_faulted_end_effector_gets_the_goal_to_refuse_with_its_own_reason(rig):
    rig.cache.state.fault = True
    step = MoveGrasp("Close Grasp", rig.ctx, close=True)
    assert tick(step, 10.0) == Status.SUCCESS  # this stand-in server accepts what it gets
    assert rig.goals == [EE["grasp_joints"]]
