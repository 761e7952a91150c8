"""How long a thread may hold Python's interpreter lock while another waits for it.

Our nodes run numeric work (pose estimation, motion planning) on one thread beside an executor's
threads that take /clock, joint states and images at tens to hundreds of hertz. Every torch or
numpy call gives the lock up and takes it back; with a busy executor thread about, taking it back
waits up to the switch interval, 5 ms by default. A part inspection makes thousands of such calls:
in the vision node's tests it took 1 s with the executor idle and up to 60 s with it busy. Half a
millisecond keeps that wait small and costs the executor little (measured: every inspection ~1.3 s).
"""

from __future__ import annotations

import sys

SWITCH_INTERVAL_S = 0.0005


def share_the_interpreter_quickly() -> None:
    """Set this process's switch interval to :data:`SWITCH_INTERVAL_S` (process-wide)."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)


__all__ = ["SWITCH_INTERVAL_S", "share_the_interpreter_quickly"]
