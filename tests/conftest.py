"""Test-session set-up shared by every test.

Tests that start ROS processes must not hear other runs on the same machine: the session claims
a ROS domain no other run holds and restricts discovery to localhost before any test starts.
"""

from __future__ import annotations

import os

from tlt_common.ros_isolation import isolate

# Before any test module imports rclpy, so this process and every child it starts use it.
ROS_DOMAIN_ID = isolate(os.environ)
