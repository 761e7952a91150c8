"""Test-session set-up shared by every test.

Tests that start ROS processes must not hear other runs on the same machine: the session claims
a ROS domain no other run holds and restricts discovery to localhost before any test starts.

The test process hosts nodes and stand-ins side by side, as each node's own process would host
them, so it shares the interpreter lock as those processes do (``tlt_common.ros.interpreter_lock``:
with Python's default the CRS tree tests' one-bay build took 24-32 s instead of 3).
"""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Callable, Iterator

import pytest

from tlt_common.ros.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros.isolation import isolate

share_the_interpreter_quickly()

# Before any test module imports rclpy, so this process and every child it starts use it.
ROS_DOMAIN_ID = isolate(os.environ)

import rclpy  # noqa: E402  (after the domain is set)
from rclpy.clock import ROSClock  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402


@pytest.fixture
def wait_for_service():
    """``wait_for_service(proc, srv_type, name, timeout_s=60) -> client``: spins a probe node of its
    own context until child process ``proc`` serves ``name`` (the test fails with the child's
    stderr if it exits first, or after the timeout). ``wait_for_service.executor`` spins the probe
    for the client's calls; everything is torn down after the test."""
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = Node("service_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)

    def wait(proc: subprocess.Popen, srv_type: type, name: str, timeout_s: float = 60.0):
        client = probe.create_client(srv_type, name)
        deadline = time.monotonic() + timeout_s
        while not client.service_is_ready():
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, f"the process never served {name}"
            executor.spin_once(timeout_sec=0.1)
        return client

    wait.executor = executor
    yield wait
    executor.shutdown()
    probe.destroy_node()
    rclpy.try_shutdown(context=context)


@pytest.fixture
def stop_ros_time() -> Iterator[Callable[[Node], None]]:
    """``stop_ros_time(node)``: from now on ``node``'s ROS time stands still, as the system clock
    seems to a timer on it after it was set back (a test cannot set the machine's clock back).
    ROS time runs again after the test."""
    stopped: list[ROSClock] = []

    def stop(node: Node) -> None:
        clock = node.get_clock()
        now = clock.now()
        clock._set_ros_time_is_active(True)
        clock.set_ros_time_override(now)
        stopped.append(clock)

    yield stop
    for clock in stopped:
        clock._set_ros_time_is_active(False)
