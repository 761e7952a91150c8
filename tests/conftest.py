"""Test-session set-up shared by every test.

Tests that start ROS processes must not hear other runs on the same machine: the session claims
a ROS domain no other run holds and restricts discovery to localhost before any test starts.

The test process hosts nodes and stand-ins side by side, as each node's own process would host
them, so it shares the interpreter lock as those processes do (``tlt_common.interpreter_lock``:
with Python's default the CRS tree tests' one-bay build took 24-32 s instead of 3).
"""

from __future__ import annotations

import os

from tlt_common.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros_isolation import isolate

share_the_interpreter_quickly()

# Before any test module imports rclpy, so this process and every child it starts use it.
ROS_DOMAIN_ID = isolate(os.environ)
