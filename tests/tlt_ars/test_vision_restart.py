"""A question of the ARS to vision while the vision process is killed (``kill -9``) and restarted,
against stand-in vision processes: the question that got no response is asked again once the new
vision says ready on ``/vision/status``, and the behaviour succeeds instead of faulting."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

import rclpy
from py_trees.common import Status
from rclpy.executors import MultiThreadedExecutor

from tlt_ars.behaviours.vision import LocateDispenser
from tlt_common import ros_names
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.readiness import ReadinessWatch
from tlt_common.ros.spin_loop import spin

# A vision process's share of LocateTag: it says its readiness as vision does (a reason while it
# cannot place its cameras, then ready), and either never answers (it is about to be killed) or
# answers with the tag in the world frame. It prints each request it takes.
VISION = """
import sys, threading, time
import rclpy
from tlt_interfaces.srv import LocateTag
from tlt_common import ros_names
from tlt_common.ros.readiness import ReadinessPublisher

mode = sys.argv[1]
rclpy.init()
node = rclpy.create_node("vision")
readiness = ReadinessPublisher(node, ros_names.VISION_STATUS, "vision")
readiness.say("no joint state for ur_x_shoulder_pan_joint yet")

def locate(request, response):
    print("request", request.dispenser, flush=True)
    if mode == "forget":
        threading.Event().wait()
    response.found = True
    response.pose.header.frame_id = "world"
    response.pose.pose.position.x = 1.5
    response.pose.pose.orientation.w = 1.0
    return response

node.create_service(LocateTag, ros_names.VISION_LOCATE_TAG, locate)
time.sleep(0.3)
readiness.say("")
print("ready", flush=True)
from rclpy.executors import MultiThreadedExecutor
executor = MultiThreadedExecutor()
executor.add_node(node)
executor.spin()
"""


class VisionProcess:
    def __init__(self, mode: str) -> None:
        self.lines: list[str] = []
        self.process = subprocess.Popen(
            [sys.executable, "-c", VISION, mode], stdout=subprocess.PIPE, text=True, env=os.environ.copy()
        )
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line.strip())

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=10.0)


def wait_for(predicate, what: str, tick=None, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        if tick is not None:
            tick()
        time.sleep(0.02)


def test_a_tag_question_lost_with_a_killed_vision_is_asked_again_of_the_restarted_one():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("ars_x", context=context)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    stop = threading.Event()
    thread = threading.Thread(target=spin, args=(executor, context, stop.is_set), daemon=True)
    thread.start()
    visions = [VisionProcess("forget")]
    try:
        ctx = SimpleNamespace(
            node=node,
            clock=time.monotonic,
            vision_status=ReadinessWatch(node, ros_names.VISION_STATUS),
            data=SimpleNamespace(located={}),
            config=SimpleNamespace(
                cameras={"end_effector": "d405_x", "world_frame": "world"},
                timeouts={"server_s": 20.0, "service_s": 60.0, "vision_back_s": 60.0},
                raw={"vision_retries": 2},
            ),
        )
        wait_for(lambda: "ready" in visions[0].lines, "the first vision")
        wait_for(lambda: ctx.vision_status.not_ready() == "", "vision's ready word")
        locate = LocateDispenser("Locate Strut Dispenser", ctx, "vertical_dispenser_x")
        wait_for(lambda: "request vertical_dispenser_x" in visions[0].lines, "the question", locate.tick_once)
        visions[0].kill()  # kill -9 with the question in it; the launcher starts a new vision
        visions.append(VisionProcess("answer"))
        wait_for(lambda: locate.status != Status.RUNNING, "the answer", locate.tick_once)
        assert locate.status == Status.SUCCESS, locate.feedback_message
        assert ctx.data.located["vertical_dispenser_x"][0, 3] == 1.5
        assert visions[1].lines.count("request vertical_dispenser_x") == 1
    finally:
        for vision in visions:
            vision.kill()
        stop.set()
        thread.join(timeout=5.0)
        executor.shutdown(timeout_sec=2.0)
        destroy_node(node)
        rclpy.shutdown(context=context)
