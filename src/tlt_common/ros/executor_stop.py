"""Stop an rclpy executor and wait for the callbacks it is still running, before nodes are destroyed.

rclpy 7.1 (Jazzy) does not wait: ``Executor.shutdown(timeout_sec)`` marks the executor shut down
and then skips its own wait (it tests the flag it has just set), and ``MultiThreadedExecutor``
leaves its worker threads running. A process that then destroys its node pulls the handles from
under callbacks still running on those threads (a service answering, a timer publishing): they
fail with ``InvalidHandle`` ("cannot use Destroyable because destruction was requested"), and
since the executor checks a callback's outcome only when it dispatches the next one, the error
surfaces at exit as "The following exception was never retrieved". Shutting the executor down
first does harm too: it destroys the guard condition that every dispatched callback triggers as it
starts, so a callback queued for a worker thread fails on it (what the vision node printed at the
end of every run). :func:`stop_executor` waits for the dispatched callbacks first, up to a bound,
then shuts the executor down, and hands back what they raised.
"""

from __future__ import annotations

import time
from typing import Any


def stop_executor(executor: Any, timeout_s: float) -> list[BaseException]:
    """Wait up to ``timeout_s`` for the callbacks ``executor`` dispatched to end, shut it down, and
    return the exceptions they raised (retrieved, so none is reported at exit). Call it once the
    spin loop has ended, so that nothing more is dispatched. Callbacks still running after
    ``timeout_s`` are left to run; the caller decides whether to destroy the nodes anyway."""
    # MultiThreadedExecutor keeps each dispatched callback's task here until the next dispatch.
    tasks = list(getattr(executor, "_futures", []))
    deadline = time.monotonic() + timeout_s
    while any(not t.done() for t in tasks) and time.monotonic() < deadline:
        time.sleep(0.01)
    executor.shutdown(timeout_sec=0)
    raised = []
    for task in tasks:
        if task.done() and task.exception() is not None:
            raised.append(task.exception())
    pool = getattr(executor, "_executor", None)
    if pool is not None:
        # Idle workers end; a callback dispatched but not started after the bound never starts.
        pool.shutdown(wait=False, cancel_futures=True)
    return raised


__all__ = ["stop_executor"]
