"""A tree's status published as ``tlt_interfaces/TreeStatus`` messages, at most once a period, and
the definition of each shape it has (so the ground can name the nodes without configuration)."""

from __future__ import annotations

import py_trees
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from tlt_common.bt.ros.clock import node_clock
from tlt_common.bt.shape_definition import document_json
from tlt_common.bt.status_codec import DEFAULT_MAX_STATUS_BYTES, TreeShape, encode


class TreeStatusPublisher:
    """Publishes a tree's encoded status as ``tlt_interfaces/TreeStatus`` messages (one per part).

    With ``period_s`` a status goes out at most once per period, after the first tick due (on the
    node's clock): the tree ticks faster than anyone watches it, and each status costs an encoding
    here and a message at every subscriber. ``publish_due(shape, tick_count)`` is that, for a tree
    ticked by hand; ``attach(tree)`` calls it after every tick of a
    ``py_trees.trees.BehaviourTree``, with tick count ``tree.count + 1`` (the first tick is 1).
    Call ``refresh()`` after changing the attached tree's structure so the shape hash and node list
    follow it.

    With ``definition_topic``, the first status of every shape is preceded by the shape's
    definition (:func:`tlt_common.bt.shape_definition.document_json`) as a ``std_msgs/String`` on
    that topic, reliable and transient local: a subscriber that joins later (a restarted CRS)
    still receives the definition of the shape being ticked.
    """

    DEFINITION_QOS = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )

    def __init__(
        self,
        node: Node,
        agent: str,
        *,
        topic: str = "tree_status",
        definition_topic: str | None = None,
        period_s: float = 0.0,
        max_status_bytes: int = DEFAULT_MAX_STATUS_BYTES,
        qos: QoSProfile | int = 10,
    ) -> None:
        from tlt_interfaces.msg import TreeStatus

        self.node = node
        self.agent = agent
        self.period_s = period_s
        self.max_status_bytes = max_status_bytes
        self.publisher = node.create_publisher(TreeStatus, topic, qos)
        self.definition_publisher = None
        if definition_topic is not None:
            from std_msgs.msg import String

            self._definition_message = String
            self.definition_publisher = node.create_publisher(String, definition_topic, self.DEFINITION_QOS)
        self._defined_hash: int | None = None
        self._shape: TreeShape | None = None
        self._stale = False
        self._root: py_trees.behaviour.Behaviour | None = None
        self._seconds = node_clock(node)
        self._due = float("-inf")

    def publish(self, shape: TreeShape, tick_count: int) -> int:
        """Publish every part of ``shape``'s current status (after its definition, the first time
        this shape is published); return how many status parts were sent."""
        if self.definition_publisher is not None and shape.hash != self._defined_hash:
            self.definition_publisher.publish(self._definition_message(data=document_json(shape, self.agent)))
            self._defined_hash = shape.hash
        stamp = self.node.get_clock().now().to_msg()
        parts = encode(shape, agent=self.agent, tick_count=tick_count, max_status_bytes=self.max_status_bytes)
        for part in parts:
            msg = part.to_msg()
            msg.header.stamp = stamp
            self.publisher.publish(msg)
        return len(parts)

    def publish_due(self, shape: TreeShape, tick_count: int) -> int:
        """:meth:`publish` when a period has passed since the last one, else nothing (0)."""
        return self.publish(shape, tick_count) if self._take_due() else 0

    def _take_due(self) -> bool:
        now = self._seconds()
        # A clock that went back (sim time restarted) starts the period again.
        if now < self._due and self._due - now <= self.period_s:
            return False
        self._due = now + self.period_s
        return True

    @property
    def shape(self) -> TreeShape | None:
        """The attached tree's shape (None before ``attach``)."""
        if self._stale and self._root is not None:
            self._shape = TreeShape.of(self._root)
            self._stale = False
        return self._shape

    def refresh(self) -> None:
        # Worked out when next asked for, not here: the ARS installs a request's branch on the
        # tick that answers the CRS, and walking a hundred behaviours is a millisecond of it.
        self._stale = True

    def attach(self, tree: py_trees.trees.BehaviourTree) -> None:
        """Publish (when due) after every tick of ``tree``."""
        self._root = tree.root
        self.refresh()

        def publish_after_tick(t: py_trees.trees.BehaviourTree) -> None:
            if self._take_due():
                shape = self.shape
                assert shape is not None  # the root was set above
                self.publish(shape, t.count + 1)

        tree.add_post_tick_handler(publish_after_tick)


__all__ = ["TreeStatusPublisher"]
