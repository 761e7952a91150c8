"""``tlt record play``: a recording published back into the graph, as a real process.

The recording is written with the project's writer; the listener lives in this test process (own
rclpy context) on the session's private ROS domain; the player is a subprocess stopped with a real
SIGINT. Timing is checked loosely (order and content exactly).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Int32, String

from tlt_common.recording.player import open_recording
from tlt_common.recording.record_command import main
from tlt_common.recording.summary import NS_PER_S

PLAYER = [
    sys.executable,
    "-c",
    "import sys; from tlt_common.recording.record_command import main; sys.exit(main())",
]
START_S = 5.0  # sim-time log times: the recording's first message
SPACING_NS = NS_PER_S // 2


class Listener:
    """Subscribes in its own context and keeps ``(topic, value, receipt time)`` of each message."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("play_test_listener", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.got: list[tuple[str, object, float]] = []

    def listen(self, msg_type: type, topic: str) -> None:
        def keep(msg, topic=topic) -> None:
            value = msg.clock.sec * NS_PER_S + msg.clock.nanosec if msg_type is Clock else msg.data
            self.got.append((topic, value, time.monotonic()))

        self.node.create_subscription(msg_type, topic, keep, QoSProfile(depth=1000))

    def values(self, topic: str) -> list:
        return [v for t, v, _ in self.got if t == topic]

    def spin_until(self, condition: Callable[[], bool], timeout: float = 40.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, "timed out waiting for the replay"
            self.executor.spin_once(timeout_sec=0.02)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def listener() -> Iterator[Listener]:
    listener = Listener()
    yield listener
    listener.close()


def start_player(path: Path, *args: str) -> tuple[subprocess.Popen, Path]:
    log = path.with_suffix(".log")
    with open(log, "w") as stream:
        proc = subprocess.Popen([*PLAYER, "play", str(path), *args], stdout=stream, stderr=subprocess.STDOUT)
    return proc, log


def recorded_run() -> list:
    t0 = int(START_S * NS_PER_S)
    entries = [
        ("/play/a", "std_msgs/msg/String", String(data=f"a{i}"), t0 + i * SPACING_NS) for i in range(5)
    ]
    entries += [
        ("/play/b", "std_msgs/msg/Int32", Int32(data=i), t0 + i * SPACING_NS + SPACING_NS // 2)
        for i in range(4)
    ]
    entries += [("/play/other", "std_msgs/msg/String", String(data="not played"), t0 + 1)]
    recorded_clock = Clock()
    recorded_clock.clock.sec = 1000  # outside the run: a replayed recorded /clock would show
    entries += [("/clock", "rosgraph_msgs/msg/Clock", recorded_clock, t0 + 2)]
    return sorted(entries, key=lambda e: e[3])


def test_play_publishes_each_topic_in_order_at_the_recorded_timing_with_a_clock(make_recording, listener):
    path = make_recording(recorded_run())
    for msg_type, topic in (
        (String, "/play/a"),
        (Int32, "/play/b"),
        (String, "/play/other"),
        (Clock, "/clock"),
    ):
        listener.listen(msg_type, topic)
    rate = 4.0
    proc, log = start_player(
        path, "--rate", str(rate), "--clock", "--clock-hz", "50", "--wait-for-subscribers", "--delay", "0",
        "--topics", "/play/[ab]", "/clock",
    )  # fmt: skip
    try:
        listener.spin_until(lambda: len(listener.values("/play/a")) == 5 and proc.poll() is not None)
        assert proc.wait(10) == 0, log.read_text()
        listener.executor.spin_once(timeout_sec=0.2)  # the last /clock
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    output = log.read_text()
    assert listener.values("/play/a") == [f"a{i}" for i in range(5)]
    assert listener.values("/play/b") == [0, 1, 2, 3]
    assert listener.values("/play/other") == []
    played = [(t, v) for t, v, _ in listener.got if t != "/clock"]
    assert played == [p for i in range(5) for p in [("/play/a", f"a{i}"), ("/play/b", i)]][:9]

    # 2 recorded seconds at rate 4: 0.5 s, the messages spread over it, not sent at once.
    times = {v: at for t, v, at in listener.got if t == "/play/a"}
    elapsed = times["a4"] - times["a0"]
    assert 0.75 * 2.0 / rate <= elapsed < 2.0 * 0.9, elapsed

    clock = listener.values("/clock")
    assert len(clock) >= 5
    assert clock == sorted(clock)
    assert all(
        START_S * NS_PER_S <= c <= (START_S + 2.0) * NS_PER_S for c in clock
    )  # not the recorded 1000 s
    assert clock[0] == START_S * NS_PER_S and clock[-1] == (START_S + 2.0) * NS_PER_S
    assert "not playing /clock: the replay publishes its own clock" in output
    assert "2 topics, 2.0 s at rate 4, publishing /clock" in output
    assert "done: 2.0 / 2.0 s, 9 messages" in output


def test_ctrl_c_stops_a_replay_between_messages(make_recording, listener):
    entries = [
        ("/play/slow", "std_msgs/msg/String", String(data=f"s{i}"), i * 30 * NS_PER_S) for i in range(2)
    ]
    path = make_recording(entries)
    listener.listen(String, "/play/slow")
    proc, log = start_player(path, "--wait-for-subscribers", "--delay", "0", "--progress-period", "0.2")
    try:
        listener.spin_until(lambda: listener.values("/play/slow") == ["s0"])
        listener.spin_until(lambda: "played 0." in log.read_text())  # the progress line
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0, log.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    output = log.read_text()
    assert "played 0." in output and "/ 30.0 s" in output
    assert "stopped: 0.0 / 30.0 s, 1 messages" in output
    assert listener.values("/play/slow") == ["s0"]


def test_a_cut_recording_is_played_up_to_the_cut(make_recording):
    entries = [("/c", "std_msgs/msg/String", String(data=str(i)), (i + 1) * NS_PER_S) for i in range(10)]
    recording = open_recording(make_recording(entries, flush_every=4, close=False))
    assert not recording.complete
    assert [c.topic for c in recording.channels.values()] == ["/c"]
    assert recording.type_names == {1: "std_msgs/msg/String"}
    assert (recording.start_ns, recording.end_ns) == (NS_PER_S, 8 * NS_PER_S)
    assert [m.log_time for _, m in recording.messages([1])] == [(i + 1) * NS_PER_S for i in range(8)]


def test_a_complete_recording_plays_in_log_time_order(make_recording):
    # Written out of order (two chunks): replayed by log time.
    entries = [("/c", "std_msgs/msg/String", String(data=str(t)), t * NS_PER_S) for t in (3, 4, 1, 2)]
    recording = open_recording(make_recording(entries, flush_every=2))
    assert recording.complete and recording.duration_s == 3.0
    assert [m.log_time // NS_PER_S for _, m in recording.messages([1])] == [1, 2, 3, 4]


def test_bad_options_and_unreadable_files_are_exit_2(tmp_path: Path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["play", str(tmp_path / "x.mcap"), "--rate", "0"])
    assert exc.value.code == 2
    assert main(["play", str(tmp_path / "x.mcap")]) == 2
    assert f"tlt record play: cannot read {tmp_path / 'x.mcap'}" in capsys.readouterr().err
