"""One action or service client per node and server name, shared by every behaviour using it."""

from __future__ import annotations

from typing import Any

from rclpy.action import ActionClient
from rclpy.node import Node

from tlt_common.ros.action_client import SerialisedActionClient


def _clients_of(node: Node) -> dict[tuple[str, str], Any]:
    # Kept on the node itself: as values of a module-level WeakKeyDictionary the clients (which
    # hold their node) kept every node, and with it its context, alive for the life of the process.
    clients = getattr(node, "_tlt_shared_clients", None)
    if clients is None:
        clients = {}
        # An attribute of the project's own on rclpy's Node, which does not declare it.
        node._tlt_shared_clients = clients  # type: ignore[attr-defined]
    return clients


def shared_action_client(node: Node, action_type: Any, action_name: str) -> ActionClient:
    """One ActionClient per (node, action name): a CRS tree has a goal behaviour per member, and
    a client each would multiply DDS entities and discovery traffic for nothing."""
    clients = _clients_of(node)
    key = ("action", action_name)
    if key not in clients:
        clients[key] = SerialisedActionClient(node, action_type, action_name)
    return clients[key]


def shared_service_client(node: Node, srv_type: Any, srv_name: str) -> Any:
    """One service client per (node, service name), for the same reason."""
    clients = _clients_of(node)
    key = ("service", srv_name)
    if key not in clients:
        clients[key] = node.create_client(srv_type, srv_name)
    return clients[key]


__all__ = ["shared_action_client", "shared_service_client"]
