"""``tlt-live-bridge``: the ROS graph live in Foxglove (or Lichtblick), over Foxglove's WebSocket
protocol, with the ``foxglove-sdk`` package's server (docs/live-view.md).

Every ``discovery_period_s`` (wall time) the bridge lists the graph's topics; each new topic that
its :class:`~tlt_common.recording.topic_filter.TopicFilter` accepts and that has a publisher
becomes a channel with a ``ros2msg`` schema (the type's full definition, as the MCAP recorder
stores it) and ``cdr`` messages. Nothing is subscribed until a viewer subscribes to a channel:
then a raw subscription (the CDR bytes, never deserialized) with a QoS that matches the
publishers' (latched ones included, so ``/tf_static`` and ``/robot_description`` arrive) forwards
each message, logged at the node's ROS time (sim time under the twin); when the last viewer
unsubscribes the subscription goes. So an idle bridge costs the graph nothing but discovery, and a
camera renders only while someone looks at it.

The server's callbacks come on the SDK's threads; they only queue the change, which the node's
executor applies (rclpy entities are made and destroyed on one thread).

    tlt-live-bridge --port 8765           # then open ws://127.0.0.1:8765 in Foxglove
"""

from __future__ import annotations

import argparse
import queue
import sys
from dataclasses import dataclass

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener, WebSocketServer
from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.subscription import Subscription

from tlt_common.recording.message_definitions import DefinitionNotFound, MessageDefinitionSource
from tlt_common.recording.message_types import UnknownMessageType, import_message_type
from tlt_common.recording.qos_profiles import subscription_qos
from tlt_common.recording.topic_filter import TopicFilter
from tlt_common.ros.lean_node import LeanNode

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
LAYOUT = "config/foxglove/tlt_edu.json"


@dataclass
class _Forwarded:
    type_name: str
    msg_class: type
    channel: foxglove.Channel
    viewers: int = 0
    subscription: Subscription | None = None


class _Listener(ServerListener):
    """The server's subscribe and unsubscribe calls, queued as (topic, +1 or -1)."""

    def __init__(self, changes: queue.SimpleQueue[tuple[str, int]]) -> None:
        self.changes = changes

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.changes.put((channel.topic, 1))

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self.changes.put((channel.topic, -1))


class FoxgloveBridge(LeanNode):
    """Serves the graph's topics to Foxglove viewers on ``host``:``port`` (0: any free port)."""

    def __init__(
        self,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        topic_filter: TopicFilter | None = None,
        discovery_period_s: float = 1.0,
        node_name: str = "live_bridge",
        context: Context | None = None,
    ) -> None:
        super().__init__(node_name, context=context)
        self._filter = topic_filter or TopicFilter(include_images=True)
        self._definitions = MessageDefinitionSource()
        self._forwarded: dict[str, _Forwarded] = {}
        self._skipped: set[str] = set()
        self._changes: queue.SimpleQueue[tuple[str, int]] = queue.SimpleQueue()
        self._fox = foxglove.Context()
        self.server: WebSocketServer = foxglove.start_server(
            name="tlt",
            host=host,
            port=port,
            server_listener=_Listener(self._changes),
            context=self._fox,
        )
        self.host = host
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(discovery_period_s, self.discover, clock=wall)
        self.create_timer(0.05, self.apply_changes, clock=wall)
        self.discover()

    @property
    def address(self) -> str:
        """The address a viewer opens: ``ws://host:port``."""
        return f"ws://{self.host}:{self.server.port}"

    @property
    def topics(self) -> list[str]:
        """The topics offered to viewers so far."""
        return sorted(self._forwarded)

    def discover(self) -> None:
        """Offer every accepted topic that appeared since the last call."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._forwarded or topic in self._skipped or not types:
                continue
            if not self._filter.accepts(topic, types[0]) or not self.get_publishers_info_by_topic(topic):
                continue
            try:
                msg_class = import_message_type(types[0])
                definition = self._definitions.full_text(types[0])
            except (UnknownMessageType, DefinitionNotFound) as exc:
                self._skipped.add(topic)
                self.get_logger().warning(f"not offering {topic}: {exc}")
                continue
            schema = foxglove.Schema(name=types[0], encoding="ros2msg", data=definition.encode())
            channel = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._fox)
            self._forwarded[topic] = _Forwarded(types[0], msg_class, channel)

    def apply_changes(self) -> None:
        """Subscribe to the topics a first viewer asked for; drop those the last viewer left."""
        while True:
            try:
                topic, change = self._changes.get_nowait()
            except queue.Empty:
                return
            forwarded = self._forwarded.get(topic)
            if forwarded is None:
                continue
            forwarded.viewers = max(0, forwarded.viewers + change)
            if forwarded.viewers and forwarded.subscription is None:
                forwarded.subscription = self._subscribe(topic, forwarded)
            elif not forwarded.viewers and forwarded.subscription is not None:
                self.destroy_subscription(forwarded.subscription)
                forwarded.subscription = None

    def _subscribe(self, topic: str, forwarded: _Forwarded) -> Subscription:
        offered = [p.qos_profile for p in self.get_publishers_info_by_topic(topic)]
        channel = forwarded.channel

        def forward(data: bytes) -> None:
            channel.log(data, log_time=self.get_clock().now().nanoseconds)

        return self.create_subscription(
            forwarded.msg_class, topic, forward, subscription_qos(offered), raw=True
        )

    def destroy_node(self) -> None:
        self.server.stop()
        super().destroy_node()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tlt-live-bridge", description=__doc__.splitlines()[0])
    p.add_argument("--host", default=DEFAULT_HOST, help="address to serve on (0.0.0.0: every interface)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="port to serve on (0: any free one)")
    p.add_argument("--topics", nargs="*", help="offer only these topics (default: every topic)")
    p.add_argument("--exclude", nargs="*", default=[], help="regular expressions of topics not to offer")
    return p


def main(argv: list[str] | None = None) -> int:
    """Serve until SIGINT/SIGTERM. Exit status 0, 2 for bad arguments, 1 if it cannot serve."""
    import rclpy

    from tlt_common.ros.rosout_logging import init_rclpy
    from tlt_common.ros.spin_loop import spin_node
    from tlt_common.ros.stop_signals import stop_on_signals

    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(rclpy.utilities.remove_ros_args(["live_bridge", *argv])[1:])
    try:
        topic_filter = TopicFilter(args.topics, args.exclude, include_images=True)
    except ValueError as exc:
        print(f"tlt-live-bridge: {exc}", file=sys.stderr)
        return 2
    stop = stop_on_signals()
    init_rclpy(["live_bridge", *argv], signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    try:
        bridge = FoxgloveBridge(args.host, args.port, topic_filter)
    except RuntimeError as exc:  # the port is taken, the address is not this machine's
        print(f"tlt-live-bridge: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    print(
        f"live view: open {bridge.address} in Foxglove or Lichtblick (Open connection, Foxglove "
        f"WebSocket); layout {LAYOUT}",
        flush=True,
    )
    spin_node(bridge, lambda: bool(stop))
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LAYOUT", "FoxgloveBridge", "main"]
