"""SIGINT and SIGTERM as a request to stop, for processes that shut rclpy down themselves.

rclpy's own handler shuts the context down from the signal, while the process's executor threads,
timers and publishers may be using it, and the process can die of a segmentation fault on SIGINT
(exit status -11). A process that calls :func:`stop_on_signals` before ``rclpy.init(...,
signal_handler_options=SignalHandlerOptions.NO)`` leaves its spin loop when the returned list is
non-empty, stops its work, shuts its executor down and destroys its nodes with the context still
valid, and only then calls ``rclpy.try_shutdown()``.
"""

from __future__ import annotations

import signal


def stop_on_signals() -> list[int]:
    """Install SIGINT and SIGTERM handlers (main thread only) that append the signal's number to
    the returned list; the list is how the process learns it should stop."""
    stop: list[int] = []  # a list append: a signal handler must not take locks
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: stop.append(signum))
    return stop


__all__ = ["stop_on_signals"]
