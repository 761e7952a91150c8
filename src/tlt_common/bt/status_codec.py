"""A behaviour tree's status as a bounded byte string (paper §V.C), and as ``TreeStatus`` messages.

Format of one part (all integers big-endian), see docs/behaviour-trees.md:

====== ===== ==========================================================
offset bytes field
====== ===== ==========================================================
0      1     format version (1)
1      4     shape hash: first 4 bytes of SHA-256 over the tree's shape
5      8     tick count
13     2     node count of the whole tree
15     1     part index (0-based)
16     1     part count
17     2     pre-order index of the first node in this part
19     1     agent name length n (at most 32)
20     n     agent name, UTF-8
20+n   k     status, 2 bits per node, first node in the two high bits of the first byte
====== ===== ==========================================================

Status codes: 0 INVALID, 1 RUNNING, 2 SUCCESS, 3 FAILURE. Unused low bits of the last byte are 0.

The shape is the pre-order list of (depth, child count, node kind, class name, name); its hash is
stable across processes and machines (SHA-256, never Python's ``hash()``), so the ground can check
that it decodes against the same tree definition and refuse when it does not.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import py_trees
from py_trees.common import Status

from tlt_common.bt.nodes import node_kind

FORMAT_VERSION = 1
MAX_AGENT_BYTES = 32
DEFAULT_MAX_STATUS_BYTES = 256
_HEADER = struct.Struct(">BIQHBBHB")
HEADER_BYTES = _HEADER.size  # without the agent name

CODES = {Status.INVALID: 0, Status.RUNNING: 1, Status.SUCCESS: 2, Status.FAILURE: 3}
STATUSES = (Status.INVALID, Status.RUNNING, Status.SUCCESS, Status.FAILURE)


class StatusCodecError(ValueError):
    """Bytes or messages that cannot be decoded against the given tree (with the reason)."""


@dataclass(frozen=True)
class ShapeNode:
    """One node of a tree's shape, in pre-order."""

    index: int
    depth: int
    children: int
    kind: str  # Table 3 kind, see tlt_common.bt.nodes.node_kind
    type_name: str
    name: str
    path: str  # names from the root, joined with "/"
    parent: int  # index of the parent; -1 for the root


def _shape_hash(nodes: Sequence[ShapeNode]) -> int:
    digest = hashlib.sha256()
    for node in nodes:
        # Child counts in pre-order make the structure unambiguous; names are length-prefixed so
        # no name can forge another shape.
        name = node.name.encode("utf-8")
        digest.update(
            f"{node.depth}:{node.children}:{node.kind}:{node.type_name}:{len(name)}:".encode() + name
        )
    return int.from_bytes(digest.digest()[:4], "big")


class TreeShape:
    """The pre-order shape of a tree (and, when taken from a tree, the behaviours it came from).

    ``TreeShape.of(root)`` walks a live tree; encoding reads the statuses of its behaviours. Take
    it again after changing the tree's structure. ``definition()`` / ``from_definition()`` carry
    the shape without the behaviours (JSON-friendly), so the ground can decode a robot's status
    without building the robot's tree.
    """

    def __init__(
        self,
        nodes: list[ShapeNode],
        behaviours: list[py_trees.behaviour.Behaviour] | None = None,
        root: py_trees.behaviour.Behaviour | None = None,
    ) -> None:
        if len(nodes) > 0xFFFF:
            raise StatusCodecError(f"tree has {len(nodes)} nodes; the codec carries at most 65535")
        self.nodes = nodes
        self.behaviours = behaviours or []
        self.root = root
        self.hash = _shape_hash(nodes)

    @classmethod
    def of(cls, root: py_trees.behaviour.Behaviour) -> TreeShape:
        nodes: list[ShapeNode] = []
        behaviours: list[py_trees.behaviour.Behaviour] = []
        stack: list[tuple[py_trees.behaviour.Behaviour, int, str, int]] = [(root, 0, "", -1)]
        while stack:
            behaviour, depth, parent_path, parent = stack.pop()
            index = len(nodes)
            path = f"{parent_path}/{behaviour.name}" if parent_path else behaviour.name
            nodes.append(
                ShapeNode(
                    index, depth, len(behaviour.children), node_kind(behaviour), type(behaviour).__name__,
                    behaviour.name, path, parent,
                )
            )  # fmt: skip
            behaviours.append(behaviour)
            for child in reversed(behaviour.children):
                stack.append((child, depth + 1, path, index))
        return cls(nodes, behaviours, root)

    def definition(self) -> list[dict[str, object]]:
        """The shape as plain data: per node in pre-order its depth, child count, kind, type and name."""
        return [
            {"depth": n.depth, "children": n.children, "kind": n.kind, "type": n.type_name, "name": n.name}
            for n in self.nodes
        ]

    @classmethod
    def from_definition(cls, definition: Sequence[Mapping[str, Any]]) -> TreeShape:
        """Rebuild a shape (without behaviours) from :meth:`definition`; refuses an inconsistent one."""
        nodes: list[ShapeNode] = []
        open_parents: list[list[int]] = []  # [index, children still to come]
        try:
            for i, entry in enumerate(definition):
                depth, children = int(entry["depth"]), int(entry["children"])
                kind, type_name, name = str(entry["kind"]), str(entry["type"]), str(entry["name"])
                while open_parents and open_parents[-1][1] == 0:
                    open_parents.pop()
                if open_parents:
                    parent = open_parents[-1][0]
                    open_parents[-1][1] -= 1
                    expected, path = nodes[parent].depth + 1, f"{nodes[parent].path}/{name}"
                elif i == 0:
                    parent, expected, path = -1, 0, name
                else:
                    raise StatusCodecError(f"definition node {i} ('{name}') lies outside the root")
                if depth != expected or children < 0:
                    raise StatusCodecError(
                        f"definition node {i} ('{name}') has depth {depth}, expected {expected}"
                    )
                nodes.append(ShapeNode(i, depth, children, kind, type_name, name, path, parent))
                if children:
                    open_parents.append([i, children])
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, StatusCodecError):
                raise
            raise StatusCodecError(f"tree definition unreadable: {exc!r}") from exc
        if not nodes or any(remaining for _, remaining in open_parents):
            raise StatusCodecError("tree definition is empty or ends before every child is listed")
        return cls(nodes)

    def __len__(self) -> int:
        return len(self.nodes)

    def statuses(self) -> list[Status]:
        if not self.behaviours:
            raise StatusCodecError("this shape was built from a definition: it has no behaviours to read")
        return [b.status for b in self.behaviours]


@dataclass(frozen=True)
class StatusPart:
    """One part of an encoded tree status, as carried by one telemetry packet or TreeStatus message."""

    agent: str
    shape_hash: int
    tick_count: int
    node_count: int
    part_index: int
    part_count: int
    first_node: int
    status: bytes

    def to_bytes(self) -> bytes:
        agent = self.agent.encode("utf-8")
        if len(agent) > MAX_AGENT_BYTES:
            raise StatusCodecError(f"agent name {self.agent!r} longer than {MAX_AGENT_BYTES} bytes")
        header = _HEADER.pack(
            FORMAT_VERSION,
            self.shape_hash,
            self.tick_count,
            self.node_count,
            self.part_index,
            self.part_count,
            self.first_node,
            len(agent),
        )
        return header + agent + self.status

    @classmethod
    def from_bytes(cls, data: bytes) -> StatusPart:
        if len(data) < HEADER_BYTES:
            raise StatusCodecError(
                f"status part of {len(data)} bytes is shorter than its {HEADER_BYTES}-byte header"
            )
        version, shape_hash, tick, count, index, parts, first, agent_len = _HEADER.unpack_from(data)
        if version != FORMAT_VERSION:
            raise StatusCodecError(f"status format version {version}, expected {FORMAT_VERSION}")
        end = HEADER_BYTES + agent_len
        if agent_len > MAX_AGENT_BYTES or len(data) < end:
            raise StatusCodecError("status part truncated inside the agent name")
        try:
            agent = bytes(data[HEADER_BYTES:end]).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise StatusCodecError(f"agent name is not UTF-8: {exc}") from exc
        return cls(agent, shape_hash, tick, count, index, parts, first, bytes(data[end:]))

    def to_msg(self):  # -> tlt_interfaces.msg.TreeStatus
        from tlt_interfaces.msg import TreeStatus

        msg = TreeStatus()
        msg.agent = self.agent
        msg.shape_hash = self.shape_hash
        msg.tick_count = self.tick_count
        msg.node_count = self.node_count
        msg.part_index = self.part_index
        msg.part_count = self.part_count
        msg.first_node = self.first_node
        msg.status = list(self.status)
        return msg

    @classmethod
    def from_msg(cls, msg) -> StatusPart:
        return cls(
            msg.agent,
            int(msg.shape_hash),
            int(msg.tick_count),
            int(msg.node_count),
            int(msg.part_index),
            int(msg.part_count),
            int(msg.first_node),
            bytes(msg.status),
        )


def pack_statuses(statuses: Sequence[Status]) -> bytes:
    """2 bits per status, first status in the two high bits of the first byte."""
    out = bytearray((len(statuses) + 3) // 4)
    codes = CODES
    for i, status in enumerate(statuses):
        out[i >> 2] |= codes[status] << (6 - 2 * (i & 3))
    return bytes(out)


def unpack_statuses(data: bytes, count: int) -> list[Status]:
    if len(data) != (count + 3) // 4:
        raise StatusCodecError(f"{len(data)} status bytes cannot hold exactly {count} nodes")
    return [STATUSES[(data[i >> 2] >> (6 - 2 * (i & 3))) & 3] for i in range(count)]


def encode(
    shape: TreeShape,
    *,
    agent: str,
    tick_count: int,
    max_status_bytes: int = DEFAULT_MAX_STATUS_BYTES,
) -> list[StatusPart]:
    """The current status of ``shape``'s tree as parts of at most ``max_status_bytes`` status bytes."""
    if max_status_bytes < 1:
        raise ValueError("max_status_bytes must be at least 1")
    statuses = shape.statuses()
    per_part = max_status_bytes * 4
    count = len(statuses)
    part_count = max(1, (count + per_part - 1) // per_part)
    if part_count > 255:
        raise StatusCodecError(f"{count} nodes need {part_count} parts; at most 255 (raise max_status_bytes)")
    parts = []
    for index in range(part_count):
        first = index * per_part
        chunk = statuses[first : first + per_part]
        parts.append(
            StatusPart(agent, shape.hash, tick_count, count, index, part_count, first, pack_statuses(chunk))
        )
    return parts


def encode_bytes(
    shape: TreeShape, *, agent: str, tick_count: int, max_status_bytes: int = 256
) -> list[bytes]:
    """:func:`encode`, each part as bytes."""
    return [
        p.to_bytes()
        for p in encode(shape, agent=agent, tick_count=tick_count, max_status_bytes=max_status_bytes)
    ]


@dataclass(frozen=True)
class DecodedStatus:
    agent: str
    tick_count: int
    nodes: list[tuple[str, Status]]  # (path from the root, status), pre-order

    def as_dict(self) -> dict[str, Status]:
        return dict(self.nodes)


def decode(parts: Iterable[StatusPart | bytes], shape: TreeShape) -> DecodedStatus:
    """Reassemble one tick's parts and name every node's status with ``shape``.

    Raises :class:`StatusCodecError` when the parts are from a different tree shape, from several
    ticks or agents, incomplete, duplicated or inconsistent.
    """
    decoded = [p if isinstance(p, StatusPart) else StatusPart.from_bytes(p) for p in parts]
    if not decoded:
        raise StatusCodecError("no parts to decode")
    head = decoded[0]
    for p in decoded:
        if p.shape_hash != shape.hash or p.node_count != len(shape):
            raise StatusCodecError(
                f"status of agent '{p.agent}' is for a tree of shape {p.shape_hash:08x}"
                f" with {p.node_count} nodes;"
                f" this tree definition has shape {shape.hash:08x} with {len(shape)} nodes"
            )
        if (p.agent, p.tick_count, p.part_count) != (head.agent, head.tick_count, head.part_count):
            raise StatusCodecError("parts come from different agents, ticks or splits")
    by_index = {}
    for p in decoded:
        if p.part_index in by_index:
            raise StatusCodecError(f"part {p.part_index} given twice")
        by_index[p.part_index] = p
    missing = sorted(set(range(head.part_count)) - set(by_index))
    if missing:
        raise StatusCodecError(f"missing part(s) {missing} of {head.part_count}")
    statuses: list[Status] = []
    for index in range(head.part_count):
        p = by_index[index]
        if p.first_node != len(statuses):
            raise StatusCodecError(f"part {index} starts at node {p.first_node}, expected {len(statuses)}")
        remaining = head.node_count - len(statuses)
        count = min(remaining, len(p.status) * 4)
        if index == head.part_count - 1:
            count = remaining
        statuses.extend(unpack_statuses(p.status, count))
    if len(statuses) != head.node_count:
        raise StatusCodecError(f"parts hold {len(statuses)} nodes, header says {head.node_count}")
    nodes = [(n.path, s) for n, s in zip(shape.nodes, statuses, strict=True)]
    return DecodedStatus(head.agent, head.tick_count, nodes)


class Reassembler:
    """Collects parts arriving one by one (one agent) and returns the decoded status once complete.

    Parts of an older tick than the newest seen are dropped; a newer tick discards a partial one.
    """

    def __init__(self, shape: TreeShape) -> None:
        self.shape = shape
        self._tick = -1
        self._parts: dict[int, StatusPart] = {}

    def add(self, part: StatusPart | bytes) -> DecodedStatus | None:
        part = part if isinstance(part, StatusPart) else StatusPart.from_bytes(part)
        if part.shape_hash != self.shape.hash:
            raise StatusCodecError(
                f"status of agent '{part.agent}' is for tree shape {part.shape_hash:08x},"
                f" not {self.shape.hash:08x}"
            )
        if part.tick_count < self._tick:
            return None
        if part.tick_count > self._tick:
            self._tick = part.tick_count
            self._parts = {}
        self._parts[part.part_index] = part
        if len(self._parts) < part.part_count:
            return None
        decoded = decode(self._parts.values(), self.shape)
        self._parts = {}
        return decoded


def apply_to_tree(decoded: DecodedStatus, shape: TreeShape) -> None:
    """Set the decoded statuses on ``shape``'s behaviours (a ground-side copy, for the viewer)."""
    for behaviour, (_, status) in zip(shape.behaviours, decoded.nodes, strict=True):
        behaviour.status = status


__all__ = [
    "DEFAULT_MAX_STATUS_BYTES",
    "HEADER_BYTES",
    "DecodedStatus",
    "Reassembler",
    "ShapeNode",
    "StatusCodecError",
    "StatusPart",
    "TreeShape",
    "apply_to_tree",
    "decode",
    "encode",
    "encode_bytes",
    "pack_statuses",
    "unpack_statuses",
]
