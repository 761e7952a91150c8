"""A recorded build's CRS tree statuses, replayed into a fresh tree viewer, show the same states.

The CRS publishes its tree's status as ``TreeStatus`` messages on ``/crs/tree_status``, each tick
split into parts. Here a Fig. 13-shaped CRS tree (the GSW's demo tree) steps through a build;
every tick's parts are recorded as the CRS publishes them. The replay (``RecordingPlayer``, its
node in a context of its own) drives a viewer node holding a fresh ``AgentTrees``, the model the
GSW tree view draws, which knows the tree only from its definition file. Each tick the viewer
decodes must be the tick the tree had, node for node.
"""

from __future__ import annotations

import io
import threading
import time
from pathlib import Path

import rclpy
from py_trees.common import Status
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile

from tlt_common.bt.status_codec import StatusPart, TreeShape, encode
from tlt_common.recording.player import PlayOptions, RecordingPlayer, open_recording
from tlt_common.recording.summary import NS_PER_S
from tlt_gsw.gui.agent_trees import AgentTrees
from tlt_gsw.gui.demo_archive import demo_tree, set_demo_statuses
from tlt_gsw.gui.tree_definitions import load_tree_definition, write_tree_definition

TOPIC = "/crs/tree_status"
TICKS = (3, 11, 14, 22, 27, 35)
TICK_SPACING_NS = NS_PER_S // 10


def build_states(shape: TreeShape) -> tuple[list, dict[int, list[tuple[str, Status]]]]:
    """Recording entries of every tick's parts, and each tick's ``(path, status)`` per node."""
    entries, states = [], {}
    for k, tick in enumerate(TICKS):
        set_demo_statuses(shape, tick)  # the running leaf alternates with the tick
        shape.behaviours[(7 * k + 5) % len(shape)].status = Status.FAILURE  # every tick differs
        states[tick] = [(n.path, b.status) for n, b in zip(shape.nodes, shape.behaviours, strict=True)]
        parts = encode(shape, agent="crs", tick_count=tick, max_status_bytes=4)
        assert len(parts) > 1  # a tick in several messages, reassembled by the viewer
        for i, part in enumerate(parts):
            msg = part.to_msg()
            log_time = NS_PER_S + k * TICK_SPACING_NS + i
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(log_time, NS_PER_S)
            entries.append((TOPIC, "tlt_interfaces/msg/TreeStatus", msg, log_time))
    return entries, states


def test_a_replayed_build_shows_the_same_tree_states_in_a_fresh_viewer(make_recording, tmp_path: Path):
    from tlt_interfaces.msg import TreeStatus

    shape = TreeShape.of(demo_tree())
    entries, states = build_states(shape)
    recording = open_recording(make_recording(entries))
    definition = write_tree_definition(shape, tmp_path / "crs_tree.json", agent="crs")

    viewer = AgentTrees({"crs": load_tree_definition(definition)})
    seen: list[tuple[int, list[tuple[str, Status]]]] = []
    received = [0]

    def on_status(msg: TreeStatus) -> None:
        received[0] += 1
        viewer.apply([(received[0], StatusPart.from_msg(msg))])
        state = viewer.trees["crs"]
        assert state.error is None, state.error
        if state.decoded is not None and (not seen or seen[-1][0] != state.decoded.tick_count):
            seen.append((state.decoded.tick_count, list(state.decoded.nodes)))

    contexts = [rclpy.Context(), rclpy.Context()]
    for context in contexts:
        rclpy.init(context=context)
    viewer_node = rclpy.create_node("tree_viewer", context=contexts[0])
    player_node = rclpy.create_node("tree_replay", context=contexts[1])
    executor = SingleThreadedExecutor(context=contexts[0])
    stop: list[int] = []
    thread = None
    try:
        viewer_node.create_subscription(TreeStatus, TOPIC, on_status, QoSProfile(depth=100))
        executor.add_node(viewer_node)
        player = RecordingPlayer(
            player_node, recording, PlayOptions(wait_for_subscribers=True), io.StringIO()
        )
        assert player.topics == [TOPIC]
        reports = []
        thread = threading.Thread(target=lambda: reports.append(player.play(stop)))
        thread.start()
        deadline = time.monotonic() + 30
        while len(seen) < len(TICKS) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        thread.join(10)
        assert reports and reports[0].published == {TOPIC: len(entries)}
        assert not reports[0].stopped
    finally:
        stop.append(1)
        if thread is not None:
            thread.join(10)
        executor.shutdown()
        viewer_node.destroy_node()
        player_node.destroy_node()
        for context in contexts:
            context.try_shutdown()
    assert [tick for tick, _ in seen] == list(TICKS)
    for tick, nodes in seen:
        assert nodes == states[tick], tick
