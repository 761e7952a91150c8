"""A test session hears only its own ROS traffic: other runs on the machine hold other domains."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading
import time

import rclpy
from rclpy.node import Node
from std_msgs.msg import String

from tlt_common.ros.isolation import claim_domain

CLAIM = (
    "from tlt_common.ros.isolation import claim_domain; import sys, time; "
    "print(claim_domain(sys.argv[1]), flush=True); time.sleep(30)"
)

TALKER = textwrap.dedent("""
    import rclpy, sys, time
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node("isolation_talker")
    pub = node.create_publisher(String, "isolation/chatter", 10)
    end = time.monotonic() + 20
    while time.monotonic() < end:
        pub.publish(String(data=sys.argv[1]))
        time.sleep(0.05)
""")


def test_concurrent_runs_claim_different_domains(tmp_path):
    holders = [
        subprocess.Popen([sys.executable, "-c", CLAIM, str(tmp_path)], stdout=subprocess.PIPE, text=True)
        for _ in range(3)
    ]
    try:
        domains = [int(h.stdout.readline()) for h in holders]
        assert len(set(domains)) == 3
        assert claim_domain(tmp_path) not in domains
    finally:
        for holder in holders:
            holder.kill()
            holder.wait()


def test_the_session_domain_is_local_and_private():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    other_domain = claim_domain()
    assert str(other_domain) != os.environ["ROS_DOMAIN_ID"]
    talkers = [
        subprocess.Popen([sys.executable, "-c", TALKER, "same"]),
        subprocess.Popen(
            [sys.executable, "-c", TALKER, "other"], env={**os.environ, "ROS_DOMAIN_ID": str(other_domain)}
        ),
    ]
    heard: set[str] = set()
    same_heard = threading.Event()
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("isolation_listener", context=context)

    def on_message(msg: String) -> None:
        heard.add(msg.data)
        if msg.data == "same":
            same_heard.set()

    node.create_subscription(String, "isolation/chatter", on_message, 10)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 15
        while not same_heard.is_set() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        # Once the same-domain talker is heard, discovery has had its chance for the other too.
        end = time.monotonic() + 2
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.1)
        assert heard == {"same"}
    finally:
        for talker in talkers:
            talker.kill()
            talker.wait()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
