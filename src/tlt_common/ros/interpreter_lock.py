"""How long a thread may hold Python's interpreter lock while another waits for it.

Our nodes run work on one thread (pose estimation, motion planning, a tree's tick, a serial
reader) beside an executor's threads that take /clock, joint states and images at tens to hundreds
of hertz. A thread that gives the lock up (every torch or numpy call, every blocking read, every
lock or event wait) and wants it back while a busy thread holds it waits up to the switch interval,
5 ms by default. A part inspection makes thousands of such hand-overs, and each goal, result and
service call of a build a few, so with a busy executor those waits come to many times the work
itself. Half a millisecond keeps that wait small and costs the executor little. Every node's ``main`` sets
it, and so does the test session, which hosts nodes side by side.
"""

from __future__ import annotations

import sys

SWITCH_INTERVAL_S = 0.0005


def share_the_interpreter_quickly() -> None:
    """Set this process's switch interval to :data:`SWITCH_INTERVAL_S` (process-wide)."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)


__all__ = ["SWITCH_INTERVAL_S", "share_the_interpreter_quickly"]
