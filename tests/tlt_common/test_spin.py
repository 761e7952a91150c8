"""spin_events: a driver node on the events executor runs its sim-time control timer on every
/clock step, and stops when the context shuts down, by a signal too (rclpy's own spin on that
executor hangs there)."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from tlt_common.spin import spin_events


def test_a_sim_time_timer_fires_on_every_clock_step_and_shutdown_ends_the_spin():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node(
        "spin_events_test", context=context, parameter_overrides=[Parameter("use_sim_time", value=True)]
    )
    source = rclpy.create_node("spin_events_clock", context=context)
    fired: list[float] = []
    node.create_timer(0.01, lambda: fired.append(node.get_clock().now().nanoseconds * 1e-9))
    ended: list[BaseException | None] = []

    def spin() -> None:
        try:
            spin_events(node)
            ended.append(None)
        except ExternalShutdownException as exc:
            ended.append(exc)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    pub = source.create_publisher(Clock, "/clock", 10)
    try:
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        msg = Clock()
        for step in range(1, 201):  # 2 s of sim time in 10 ms steps, faster than real time
            msg.clock.sec, msg.clock.nanosec = 100 + step // 100, (step % 100) * 10_000_000
            pub.publish(msg)
            time.sleep(0.004)
        deadline = time.monotonic() + 5
        while (not fired or fired[-1] < 102.0 - 1e-6) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert fired and abs(fired[-1] - 102.0) < 1e-6
        on_time = [t for t in fired if t >= 100.0]
        assert len(on_time) >= 190, f"{len(on_time)} of 200 control cycles"
    finally:
        rclpy.shutdown(context=context)
        spinner.join(timeout=3)
    assert not spinner.is_alive(), "the spin did not end with its context"
    assert len(ended) == 1
    node.destroy_node()
    source.destroy_node()


SPINNER = textwrap.dedent("""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from tlt_common.spin import spin_events
    rclpy.init()
    node = rclpy.create_node("spin_events_signal")
    node.create_timer(0.05, lambda: None)
    print("spinning", flush=True)
    try:
        spin_events(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        print("stopped", flush=True)
""")


def test_sigint_stops_a_process_spinning_on_the_events_executor():
    proc = subprocess.Popen([sys.executable, "-c", SPINNER], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "spinning"
        time.sleep(0.3)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=5) == 0
        assert proc.stdout.read().strip() == "stopped"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
