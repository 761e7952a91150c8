"""Say so when a node on sim time stops receiving ``/clock``.

A node with ``use_sim_time`` whose ``/clock`` stops does nothing at all: every timer, tick and
timeout is on that clock, so it sends no telemetry and logs nothing, and it looks hung. Whether the
twin stopped, or this process stopped hearing it (a CRS restarted after a SIGKILL can hear no
``/clock`` for minutes while the rest of the system runs on), is what an engineer needs to know
first. :func:`watch_sim_clock` starts a thread, on the wall clock and outside the executor, that
logs a warning and every thread's stack when ROS time has stood still for ``stall_s`` seconds of
wall time after the first ``/clock``, and a note when it moves again.
"""

from __future__ import annotations

import faulthandler
import logging
import sys
import time
from collections.abc import Callable
from typing import Any

from tlt_common.ros.watch_thread import WatchThread

_log = logging.getLogger("tlt.sim_clock")


class SimClockWatch(WatchThread):
    """The thread of :func:`watch_sim_clock`; ``stalls`` counts the stalls it reported."""

    def __init__(self, now_ns: Callable[[], int], name: str, stall_s: float, period_s: float) -> None:
        super().__init__(name, "sim-clock", period_s)
        self._now_ns = now_ns
        self.stall_s = stall_s
        self.stalls = 0

    def _run(self) -> None:
        last, since, stalled = 0, time.monotonic(), False
        while self._next_period():
            try:
                now = int(self._now_ns())
            except Exception:  # the node is being destroyed: nothing left to watch
                return
            wall = time.monotonic()
            if now != last:
                if stalled:
                    _log.warning(
                        "%s: sim time moves again (%.3f s) after %.0f s of wall time without /clock",
                        self.name,
                        now * 1e-9,
                        wall - since,
                    )
                last, since, stalled = now, wall, False
            elif now and not stalled and wall - since >= self.stall_s:
                stalled = True
                self.stalls += 1
                _log.warning(
                    "%s: no /clock for %.0f s of wall time (sim time stands at %.3f s): the twin "
                    "has stopped, or this process no longer hears it; its threads follow",
                    self.name,
                    wall - since,
                    now * 1e-9,
                )
                faulthandler.dump_traceback(file=sys.stderr, all_threads=True)


def watch_sim_clock(node: Any, stall_s: float = 20.0, period_s: float = 1.0) -> SimClockWatch | None:
    """Watch ``node``'s ROS time while it runs on sim time (None, and no thread, otherwise)."""
    if not node.get_parameter("use_sim_time").value:
        return None
    clock = node.get_clock()
    return SimClockWatch(lambda: clock.now().nanoseconds, node.get_name(), stall_s, period_s).start()


__all__ = ["SimClockWatch", "watch_sim_clock"]
