"""CRS -> ARS request overhead: from the goal sent to the ARS tree running it, against a bare rclpy
action round trip measured in the same run (issue 9; goal: ratio <= 1.2).

Two server processes in a private ROS domain, each serving AddMember for ``ars_x``:

* the real ARS (``tlt-ars --ars ars_x``; short timeouts so each request, which has no hardware to
  drive, ends quickly): the time is from just before ``send_goal_async`` to the first feedback,
  which the ARS sends once its tree has installed the request's branch and runs a leaf of it;
* a bare rclpy action server that succeeds at once: the time is from just before
  ``send_goal_async`` to its result (goal request and response, result request and response: a
  whole action round trip; a feedback sent that early can reach the client before it knows the goal).

Both are driven alternately by this process, one goal at a time, so load affects both alike.

    .venv/bin/python bench/crs_ars_request.py [--requests 20]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
MEMBER = dict(kind=1, bay=1, member_id="bay1/vertical/x0_y0", position="x0_y0", ars="ars_x")


def serve_bare() -> int:
    """The bare server: accept, succeed."""
    import rclpy
    from rclpy.action import ActionServer
    from tlt_interfaces.action import AddMember

    rclpy.init()
    node = rclpy.create_node("bare_ars")

    def execute(handle):
        handle.succeed()
        return AddMember.Result(success=True)

    ActionServer(node, AddMember, "/bare/add_member", execute)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    return 0


def ars_config(tmp: Path) -> Path:
    raw = yaml.safe_load((ROOT / "config/ars/ars_x.yaml").read_text())
    raw["check_reach"] = False
    raw["timeouts"].update(server_s=0.2, service_s=0.2, stop_s=0.2, sensor_s=0.2, planning_s=0.2)
    raw["mission"] = str(ROOT / raw["mission"])
    raw["scene"] = str(ROOT / raw["scene"])
    path = tmp / "ars_x.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def measure(node, client, n: int, label: str, until_result: bool = False) -> list[float]:
    import rclpy
    from tlt_interfaces.action import AddMember

    assert client.wait_for_server(timeout_sec=60), f"{label}: no action server"
    times: list[float] = []
    for _ in range(n):
        first = threading.Event()
        stamp: list[float] = []

        def feedback(_msg, stamp=stamp, first=first):
            if not first.is_set():
                stamp.append(time.perf_counter())
                first.set()

        t0 = time.perf_counter()
        sent = client.send_goal_async(AddMember.Goal(**MEMBER), feedback_callback=feedback)
        deadline = time.monotonic() + 30
        while not sent.done() and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.001)
        result = sent.result().get_result_async()
        while not (result.done() if until_result else first.is_set()) and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.001)
        if until_result and result.done():
            times.append(time.perf_counter() - t0)
        elif first.is_set():
            times.append(stamp[0] - t0)
        else:
            why = result.result().result.reason if result.done() else "nothing in 30 s"
            raise RuntimeError(f"{label}: no {'result' if until_result else 'feedback'}: {why}")
        while not result.done() and time.monotonic() < deadline + 30:
            rclpy.spin_once(node, timeout_sec=0.01)
    return times


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--requests", type=int, default=20)
    args = p.parse_args(argv)
    if os.environ.get("TLT_BENCH_ROLE") == "bare":
        return serve_bare()

    from tlt_common.ros.isolation import isolate

    env = dict(os.environ)
    isolate(env)
    os.environ.update(
        ROS_DOMAIN_ID=env["ROS_DOMAIN_ID"], ROS_AUTOMATIC_DISCOVERY_RANGE=env["ROS_AUTOMATIC_DISCOVERY_RANGE"]
    )
    import rclpy
    from rclpy.action import ActionClient
    from tlt_interfaces.action import AddMember

    from tlt_common import ros_names

    with tempfile.TemporaryDirectory() as tmp:
        tlt_ars = Path(sys.executable).with_name("tlt-ars")
        procs = [
            subprocess.Popen(
                [str(tlt_ars), "--ars", "ars_x", "--config", str(ars_config(Path(tmp)))],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            ),
            subprocess.Popen(
                [sys.executable, __file__],
                env={**env, "TLT_BENCH_ROLE": "bare"},
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            ),
        ]
        try:
            rclpy.init()
            node = rclpy.create_node("bench_crs")
            ars = ActionClient(node, AddMember, ros_names.ars_action("ars_x", "add_member"))
            # The arms' joint states (standing at home), so the request gets as far as planning.
            from sensor_msgs.msg import JointState

            raw = yaml.safe_load((ROOT / "config/ars/ars_x.yaml").read_text())
            home = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
            states = {
                arm: node.create_publisher(JointState, ros_names.joint_states_topic(arm), 10)
                for arm in ("ur_x", "ur_y")
            }

            def publish_states():
                for arm, pub in states.items():
                    names = [n.replace("ur_x", arm) for n in raw["arm"]["joint_names"]]
                    msg = JointState(name=names, position=home, velocity=[0.0] * 6)
                    msg.header.stamp = node.get_clock().now().to_msg()
                    pub.publish(msg)

            node.create_timer(0.01, publish_states)
            bare = ActionClient(node, AddMember, "/bare/add_member")
            measure(node, bare, 2, "bare", until_result=True)  # warm-up: discovery, first allocations
            measure(node, ars, 2, "ars")
            bare_t, ars_t = [], []
            for _ in range(args.requests):
                bare_t += measure(node, bare, 1, "bare", until_result=True)
                ars_t += measure(node, ars, 1, "ars")
        finally:
            for proc in procs:
                proc.terminate()
            for proc in procs:
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
            rclpy.try_shutdown()

    def line(name: str, t: list[float]) -> str:
        q = sorted(t)
        return (
            f"{name:<28} p50 {statistics.median(t) * 1e3:7.2f} ms   p90 "
            f"{q[int(0.9 * (len(q) - 1))] * 1e3:7.2f} ms   n={len(t)}"
        )

    print(line("bare action, to its result", bare_t))
    print(line("ARS, to its tree running", ars_t))
    ratio = statistics.median(ars_t) / statistics.median(bare_t)
    print(f"ratio ARS / bare (p50): {ratio:.2f}   goal <= 1.2: {'met' if ratio <= 1.2 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
