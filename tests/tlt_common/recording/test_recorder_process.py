"""``tlt-record`` as a real process against real rclpy publishers: what it records, how it stops.

The publishers live in this test process (own rclpy context); the recorder is a subprocess on the
session's private ROS domain, stopped with real signals. Instead of sleeping, the tests read the
recorder's file while it runs (it flushes every 0.2 s) until the expected messages are there.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
import yaml
from mcap.reader import NonSeekingReader, make_reader
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Int32, String

from tlt_common.recording.cli import main
from tlt_common.recording.reading import read_messages
from tlt_common.recording.recovery import ScanResult, iter_flushed_messages, recover

RECORDER = [sys.executable, "-c", "import sys; from tlt_common.recording.cli import main; sys.exit(main())"]
FAST = ["--discovery-period", "0.2", "--flush-period", "0.2", "--progress-period", "1"]
N = 10
LATE = 5
PREFIX = "/rec_test"


class Recorder:
    """The recorder subprocess, its output going to a file (no pipe to fill up)."""

    def __init__(self, out: Path, *args: str) -> None:
        self.out = out
        self.log_path = out.with_suffix(".log")
        self._log = open(self.log_path, "w")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            [*RECORDER, "--out", str(out), *FAST, *args], stdout=self._log, stderr=subprocess.STDOUT
        )

    @property
    def log(self) -> str:
        return self.log_path.read_text()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self._log.close()


def wait_until(condition: Callable[[], bool], what: str, timeout: float = 40.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def flushed_counts(path: Path) -> Counter[str]:
    if not path.exists():
        return Counter()
    return Counter(channel.topic for _, channel, _ in iter_flushed_messages(path))


@pytest.fixture(scope="module")
def ros_node() -> Iterator[rclpy.node.Node]:
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("recording_test_publisher", context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        context.try_shutdown()


@pytest.fixture(scope="module")
def recording(ros_node, tmp_path_factory) -> dict:
    """One recorder run seeing every kind of topic; the tests below each check one aspect."""
    from tlt_interfaces.action import AddMember
    from tlt_interfaces.msg import LifterState

    node = ros_node
    latched = node.create_publisher(
        String, f"{PREFIX}/latched", QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    latched.publish(String(data="latched-before-recorder"))
    image = node.create_publisher(Image, f"{PREFIX}/cam/image_raw", 10)
    rgb = node.create_publisher(Image, f"{PREFIX}/cam/rgb", 10)  # an image by its type only
    noise = node.create_publisher(String, f"{PREFIX}/noise", 10)
    chatter = node.create_publisher(String, f"{PREFIX}/chatter", 10)
    joints = node.create_publisher(JointState, f"{PREFIX}/joint_states", 10)
    lifter = node.create_publisher(LifterState, f"{PREFIX}/lifter/state", 10)
    feedback = node.create_publisher(
        AddMember.Impl.FeedbackMessage, f"{PREFIX}/add_member/_action/feedback", 10
    )
    mixed_reliable = node.create_publisher(String, f"{PREFIX}/mixed", 10)
    out = tmp_path_factory.mktemp("rec") / "recording.mcap"
    recorder = Recorder(out, "--exclude", f"{PREFIX}/noise")
    mixed_lossy = None
    try:
        for pub in (latched, chatter, joints, lifter, feedback, mixed_reliable):
            wait_until(
                lambda pub=pub: pub.get_subscription_count() > 0,
                f"the recorder to subscribe to {pub.topic_name}",
            )
        for i in range(N):
            chatter.publish(String(data=f"c{i}"))
            js = JointState(name=["j"], position=[i * 0.5])
            js.header.stamp.sec = 100 + i
            js.header.stamp.nanosec = 7
            joints.publish(js)
            ls = LifterState(state=i % 4, encoder_counts=[i, i + 1, i + 2, i + 3], fault=f"f{i}")
            lifter.publish(ls)
            fb = AddMember.Impl.FeedbackMessage()
            fb.feedback.step = f"s{i}"
            fb.feedback.progress = i / N
            feedback.publish(fb)
            image.publish(Image(height=1, width=1, encoding="mono8", step=1, data=[i]))
            rgb.publish(Image(height=1, width=1, encoding="mono8", step=1, data=[i]))
            noise.publish(String(data="excluded"))
        late = node.create_publisher(Int32, f"{PREFIX}/late", 10)  # after the recorder started
        wait_until(lambda: late.get_subscription_count() > 0, "the recorder to find the late topic")
        for i in range(LATE):
            late.publish(Int32(data=1000 + i))
        # A best-effort publisher joining a topic the recorder reads reliably: it cannot match
        # until the recorder subscribes again, best effort.
        mixed_lossy = node.create_publisher(
            String, f"{PREFIX}/mixed", QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        )
        wait_until(
            lambda: mixed_lossy.get_subscription_count() > 0, "the recorder to re-subscribe best effort"
        )

        def lossy_recorded() -> bool:
            mixed_lossy.publish(String(data="from best effort"))
            return flushed_counts(out)[f"{PREFIX}/mixed"] >= 1

        wait_until(lossy_recorded, "a best-effort message to reach the file")
        expected = {
            f"{PREFIX}/chatter": N,
            f"{PREFIX}/joint_states": N,
            f"{PREFIX}/lifter/state": N,
            f"{PREFIX}/add_member/_action/feedback": N,
            f"{PREFIX}/late": LATE,
            f"{PREFIX}/latched": 1,
        }
        wait_until(
            lambda: all(flushed_counts(out)[t] >= n for t, n in expected.items()),
            "every published message to reach the file",
        )
        subscribers_of_excluded = sum(p.get_subscription_count() for p in (image, rgb, noise))
        time.sleep(2.5)  # progress is logged every second (FAST): let a loaded machine log one
        returncode = recorder.stop(signal.SIGINT)
    finally:
        recorder.stop(signal.SIGKILL)
        for pub in (
            latched,
            image,
            rgb,
            noise,
            chatter,
            joints,
            lifter,
            feedback,
            mixed_reliable,
            mixed_lossy,
        ):
            if pub is not None:
                node.destroy_publisher(pub)
    return {
        "path": out,
        "returncode": returncode,
        "log": recorder.log,
        "subscribers_of_excluded": subscribers_of_excluded,
    }


def messages_by_topic(path: Path) -> dict[str, list]:
    by_topic: dict[str, list] = defaultdict(list)
    for item in read_messages(path):
        by_topic[item.channel.topic].append(item)
    return by_topic


def test_sigint_exits_0_and_leaves_a_complete_file(recording):
    assert recording["returncode"] == 0, recording["log"]
    with open(recording["path"], "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics.message_count > 0
    with open(recording["path"], "rb") as stream:  # every chunk and the data section check out
        count = sum(1 for _ in NonSeekingReader(stream, validate_crcs=True).iter_messages())
    assert count == summary.statistics.message_count
    assert "tlt-record: wrote" in recording["log"]


def test_each_topic_is_recorded_in_order_with_its_values(recording):
    by_topic = messages_by_topic(recording["path"])
    assert [m.decoded_message.data for m in by_topic[f"{PREFIX}/chatter"]] == [f"c{i}" for i in range(N)]
    joints = by_topic[f"{PREFIX}/joint_states"]
    assert [list(m.decoded_message.position) for m in joints] == [[i * 0.5] for i in range(N)]
    lifter = by_topic[f"{PREFIX}/lifter/state"]
    assert [list(m.decoded_message.encoder_counts) for m in lifter] == [
        [i, i + 1, i + 2, i + 3] for i in range(N)
    ]
    assert [m.decoded_message.fault for m in lifter] == [f"f{i}" for i in range(N)]
    assert [m.decoded_message.state for m in lifter] == [i % 4 for i in range(N)]
    feedback = by_topic[f"{PREFIX}/add_member/_action/feedback"]
    assert [m.decoded_message.feedback.step for m in feedback] == [f"s{i}" for i in range(N)]
    for messages in by_topic.values():
        assert [m.message.sequence for m in messages] == list(range(1, len(messages) + 1))
        log_times = [m.message.log_time for m in messages]
        assert log_times == sorted(log_times)


def test_schemas_are_the_ros2msg_definitions_of_the_types(recording):
    schemas = {m.channel.topic: m.schema for m in read_messages(recording["path"])}
    assert schemas[f"{PREFIX}/lifter/state"].name == "tlt_interfaces/msg/LifterState"
    assert schemas[f"{PREFIX}/joint_states"].name == "sensor_msgs/msg/JointState"
    feedback = schemas[f"{PREFIX}/add_member/_action/feedback"]
    assert feedback.name == "tlt_interfaces/action/AddMember_FeedbackMessage"
    assert {s.encoding for s in schemas.values()} == {"ros2msg"}
    assert "MSG: std_msgs/Header" in schemas[f"{PREFIX}/lifter/state"].data.decode()


def test_publish_time_is_the_header_stamp_when_there_is_one(recording):
    by_topic = messages_by_topic(recording["path"])
    joints = by_topic[f"{PREFIX}/joint_states"]
    assert [m.message.publish_time for m in joints] == [(100 + i) * 10**9 + 7 for i in range(N)]
    for m in by_topic[f"{PREFIX}/chatter"]:
        assert m.message.publish_time == m.message.log_time
    lifter = by_topic[f"{PREFIX}/lifter/state"]  # a Header left unset: receive time
    assert all(m.message.publish_time == m.message.log_time for m in lifter)


def test_latched_message_published_before_the_recorder_started_is_captured(recording):
    latched = messages_by_topic(recording["path"])[f"{PREFIX}/latched"]
    assert [m.decoded_message.data for m in latched] == ["latched-before-recorder"]
    offered = yaml.safe_load(latched[0].channel.metadata["offered_qos_profiles"])
    assert [p["durability"] for p in offered] == ["transient_local"]
    assert latched[0].channel.metadata["topic_type_hash"].startswith("RIHS01_")


def test_topic_created_after_the_recorder_started_is_recorded(recording):
    late = messages_by_topic(recording["path"])[f"{PREFIX}/late"]
    assert [m.decoded_message.data for m in late] == [1000 + i for i in range(LATE)]


def test_a_best_effort_publisher_joining_later_is_matched_by_subscribing_again(recording):
    mixed = messages_by_topic(recording["path"])[f"{PREFIX}/mixed"]
    assert {m.decoded_message.data for m in mixed} == {"from best effort"}
    offered = yaml.safe_load(mixed[0].channel.metadata["offered_qos_profiles"])
    assert [p["reliability"] for p in offered] == ["reliable"]  # what was offered at first
    assert f"re-subscribed {PREFIX}/mixed (best_effort, volatile)" in recording["log"]


def test_image_and_excluded_topics_are_neither_subscribed_nor_recorded(recording):
    topics = set(messages_by_topic(recording["path"]))
    assert f"{PREFIX}/cam/image_raw" not in topics
    assert f"{PREFIX}/cam/rgb" not in topics
    assert f"{PREFIX}/noise" not in topics
    assert recording["subscribers_of_excluded"] == 0


def test_progress_is_logged(recording):
    assert "topics," in recording["log"] and "messages written" in recording["log"]
    assert f"recording {PREFIX}/late (std_msgs/msg/Int32, reliable, volatile)" in recording["log"]


def test_sigkill_keeps_the_flushed_messages_and_recover_completes_the_file(ros_node, tmp_path: Path):
    topic = f"{PREFIX}/killed"
    pub = ros_node.create_publisher(String, topic, 10)
    out = tmp_path / "killed.mcap"
    recorder = Recorder(out, "--topics", topic)
    try:
        wait_until(lambda: pub.get_subscription_count() > 0, "the recorder to subscribe")
        for i in range(N):
            pub.publish(String(data=f"k{i}"))
        wait_until(lambda: flushed_counts(out)[topic] == N, "the messages to be flushed")
        assert recorder.stop(signal.SIGKILL) == -signal.SIGKILL
    finally:
        recorder.stop(signal.SIGKILL)
        ros_node.destroy_publisher(pub)
    scan = ScanResult()
    assert [m.data for _, _, m in iter_flushed_messages(out, scan)]
    assert not scan.complete  # no footer: the process never finished the file
    report = recover(out, tmp_path / "recovered.mcap")
    assert report.messages == N and not report.complete
    recovered = [m.decoded_message.data for m in read_messages(tmp_path / "recovered.mcap")]
    assert recovered == [f"k{i}" for i in range(N)]


def test_sigterm_finishes_the_file_sim_time_stamps_it_and_an_earlier_file_is_kept(ros_node, tmp_path: Path):
    from rosgraph_msgs.msg import Clock

    out = tmp_path / "recording.mcap"
    out.write_bytes(b"an earlier run")
    topic = f"{PREFIX}/term"
    pub = ros_node.create_publisher(String, topic, 10)
    clock = ros_node.create_publisher(Clock, "/clock", 10)
    sim_now = Clock()
    sim_now.clock.sec = 42
    recorder = Recorder(out, "--topics", topic, "/clock", "--ros-args", "-p", "use_sim_time:=true")
    try:
        wait_until(lambda: pub.get_subscription_count() > 0, "the recorder to subscribe")

        def clock_recorded() -> bool:
            clock.publish(sim_now)
            return flushed_counts(out)["/clock"] >= 3

        wait_until(clock_recorded, "sim time to reach the recorder")
        pub.publish(String(data="t"))
        wait_until(lambda: flushed_counts(out)[topic] == 1, "the message to be flushed")
        assert recorder.stop(signal.SIGTERM) == 0, recorder.log
    finally:
        recorder.stop(signal.SIGKILL)
        ros_node.destroy_publisher(pub)
        ros_node.destroy_publisher(clock)
    assert (tmp_path / "recording.1.mcap").read_bytes() == b"an earlier run"
    recorded = list(read_messages(out, topics=[topic]))
    assert [m.decoded_message.data for m in recorded] == ["t"]
    assert recorded[0].message.log_time == 42 * 10**9  # the node clock runs on /clock


def test_bad_options_exit_2_before_touching_ros(tmp_path: Path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--out", str(tmp_path / "x.mcap"), "--exclude", "("])
    assert exit_info.value.code == 2
    assert "is not a regular expression" in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["--out", str(blocker / "x.mcap")]) == 2
    assert "cannot write" in capsys.readouterr().err
    assert not rclpy.ok()  # the default context was never initialised


def test_sigint_while_messages_pour_in_still_leaves_a_complete_file(ros_node, tmp_path: Path):
    """The signal lands while the recorder is writing (tiny chunks, so nearly every message writes
    one): the file must still close with its summary, readable by a seeking reader."""
    import threading

    topic = f"{PREFIX}/flood"
    pub = ros_node.create_publisher(String, topic, 100)
    payload = "x" * 4000
    pouring = threading.Event()
    pouring.set()

    def pour() -> None:
        # About 2000 messages a second, each writing a chunk: a flood for the recorder. Unpaced,
        # the publishing thread held the interpreter and the file grew faster than the test could
        # read it back (a 2-core CI machine spent the test's whole 600 s there).
        while pouring.is_set():
            pub.publish(String(data=payload))
            time.sleep(0.0005)

    def flushed_200(out: Path) -> bool:
        # Stops reading at the 200th message: the whole file is re-read on every poll.
        if not out.exists():
            return False
        return any(i >= 199 for i, _ in enumerate(iter_flushed_messages(out)))

    pourer = threading.Thread(target=pour, daemon=True)
    try:
        for attempt in range(2):
            out = tmp_path / f"flood{attempt}.mcap"
            recorder = Recorder(out, "--topics", topic, "--chunk-size", "1024")
            try:
                wait_until(lambda: pub.get_subscription_count() > 0, "the recorder to subscribe")
                if not pourer.is_alive():
                    pourer.start()
                wait_until(lambda out=out: flushed_200(out), "messages to be flushed")
                assert recorder.stop(signal.SIGINT) == 0, recorder.log
            finally:
                recorder.stop(signal.SIGKILL)
            recorded = list(read_messages(out, topics=[topic]))
            assert len(recorded) >= 200 and all(m.decoded_message.data == payload for m in recorded)
            wait_until(lambda: pub.get_subscription_count() == 0, "the recorder to leave the graph")
    finally:
        pouring.clear()
        if pourer.is_alive():
            pourer.join(timeout=5)
        ros_node.destroy_publisher(pub)


def test_a_signal_as_soon_as_the_file_exists_still_completes_it(tmp_path: Path):
    """A launch set stopped while the recorder is still starting (a restart just before the
    stop): the file it created must still get its summary and footer."""
    for attempt in range(3):
        out = tmp_path / f"early{attempt}.mcap"
        recorder = Recorder(out, "--topics", f"{PREFIX}/nothing")
        try:
            wait_until(out.exists, "the recorder to create its file", timeout=30.0)
            assert recorder.stop(signal.SIGINT) == 0, recorder.log
        finally:
            recorder.stop(signal.SIGKILL)
        assert list(read_messages(out)) == [], recorder.log
