"""What a node's view of the ROS graph lists for one action server, for a message when it is not found.

An action client calls its server ready only when, for each of the action's three services, the
graph lists as many request readers as response writers (rmw_fastrtps) and the client has matched
them. A server that stays "not ready" is explained by those lists: none listed (not discovered), or
unequal counts (a server half-discovered, or a stale one left by a participant still alive).
"""

from __future__ import annotations

from typing import Any

_SERVICES = ("send_goal", "cancel_goal", "get_result")
_TOPICS = ("status", "feedback")


def _owners(infos: list[Any]) -> str:
    names = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos)
    return f"{len(names)} ({', '.join(names)})" if names else "0"


def describe_action_server_graph(node: Any, action: str) -> str:
    """One line: for action ``action`` (fully qualified, e.g. ``/ars_x/add_member``), the request
    readers and response writers of each service and the writers of each topic that ``node``'s
    graph lists, each with its node ("_NODE_NAME_UNKNOWN_" until the node's participant said)."""
    base = action.lstrip("/")
    parts = []
    for service in _SERVICES:
        topic = f"{base}/_action/{service}"
        readers = node.get_subscriptions_info_by_topic(f"rq/{topic}Request", no_mangle=True)
        writers = node.get_publishers_info_by_topic(f"rr/{topic}Reply", no_mangle=True)
        parts.append(f"{service}: request readers {_owners(readers)}, response writers {_owners(writers)}")
    for name in _TOPICS:
        writers = node.get_publishers_info_by_topic(f"rt/{base}/_action/{name}", no_mangle=True)
        parts.append(f"{name} writers {_owners(writers)}")
    return f"{action} as {node.get_name()} sees it: " + "; ".join(parts)


__all__ = ["describe_action_server_graph"]
