"""Each agent's behaviour tree status as the GSW shows it, from the ``tree_status`` parts in the
archive: the newest tick of each agent, decoded against its tree definition when one is known,
else the count of nodes per status of the parts seen.

A definition is found by the status's shape hash: among the shapes already known, then through
``lookup`` (the archive's ``tree_definition`` packets, which every agent sends: no configuration
needed), then in the agent's definition file when one is configured."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from py_trees.common import Status

from tlt_common.bt.status_codec import (
    DecodedStatus,
    Reassembler,
    StatusCodecError,
    StatusPart,
    TreeShape,
    unpack_statuses,
)
from tlt_gsw.gui.tree_definitions import TreeDefinitionFiles


@dataclass
class TreeState:
    """The newest status an agent sent; ``decoded`` when its shape definition is known."""

    agent: str
    tick: int
    shape_hash: int
    node_count: int
    decoded: DecodedStatus | None = None
    counts: Counter = field(default_factory=Counter)  # Status -> nodes, of the parts seen
    error: str | None = None
    packet_id: int = 0


def status_part(fields: Mapping[str, Any]) -> StatusPart | None:
    """The part a decoded ``tree_status`` packet carries (None when a field is missing or mistyped)."""
    f = fields
    try:
        return StatusPart(
            str(f["agent"]), int(f["shape_hash"]), int(f["tick"]), int(f["node_count"]),
            int(f["part_index"]), int(f["part_count"]), int(f["first_node"]), bytes(f["status"]),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError):
        return None


class AgentTrees:
    """The newest :class:`TreeState` of each agent, and the tree shapes that decode them.

    ``shapes`` (agent -> shape) starts from the configured definitions. An agent whose shape hash
    changes is decoded with the shape of that hash: one seen before, else ``lookup(hash)`` (the
    definitions the agents sent), else, with ``definition_files``, the agent's file read again
    (the agent may have a new tree).
    """

    def __init__(
        self,
        shapes: Mapping[str, TreeShape] | None = None,
        definition_files: TreeDefinitionFiles | None = None,
        lookup: Callable[[int], TreeShape | None] | None = None,
    ) -> None:
        self.shapes = dict(shapes or {})
        self.by_hash = {shape.hash: shape for shape in self.shapes.values()}
        self.definition_files = definition_files
        self.lookup = lookup
        self.reset()

    def _shape_for(self, agent: str, shape_hash: int) -> TreeShape | None:
        """The shape of ``shape_hash`` if known or found; else the agent's changed file's shape."""
        shape = self.by_hash.get(shape_hash)
        if shape is None and self.lookup is not None:
            shape = self.lookup(shape_hash)
        if shape is None and self.definition_files is not None:
            shape = self.definition_files.changed(agent)
        if shape is not None:
            self.by_hash[shape.hash] = shape
        return shape

    def reset(self) -> None:
        """Forget every status (the shapes learned so far are kept)."""
        self.trees: dict[str, TreeState] = {}
        self._reassemblers = {agent: Reassembler(shape) for agent, shape in self.shapes.items()}

    def apply(self, parts: Iterable[tuple[int, StatusPart]]) -> set[str]:
        """Decode the newest tick of each agent among ``parts`` (packet id, part), in packet order
        (older ticks are superseded); return the agents whose state changed."""
        parts = list(parts)
        changed: set[str] = set()
        newest: dict[str, int] = {}
        for _, part in parts:
            newest[part.agent] = max(newest.get(part.agent, -1), part.tick_count)
        # Of the newest tick, the last copy of each part (a resent part replaces the earlier one).
        latest = {(p.agent, p.part_index): (pid, p) for pid, p in parts if p.tick_count == newest[p.agent]}
        for pid, part in sorted(latest.values(), key=lambda item: item[0]):
            state = self.trees.get(part.agent)
            if state is None or part.tick_count > state.tick or part.shape_hash != state.shape_hash:
                state = TreeState(part.agent, part.tick_count, part.shape_hash, part.node_count)
                self.trees[part.agent] = state
            elif part.tick_count < state.tick:
                continue
            state.packet_id = pid
            remaining = part.node_count - part.first_node
            try:
                for status in unpack_statuses(part.status, min(remaining, len(part.status) * 4)):
                    state.counts[status] += 1
            except StatusCodecError as exc:
                state.error = str(exc)
            reassembler = self._reassemblers.get(part.agent)
            if reassembler is None or reassembler.shape.hash != part.shape_hash:
                shape = self._shape_for(part.agent, part.shape_hash)  # the agent may have a new tree
                if shape is not None:
                    self.shapes[part.agent] = shape
                    reassembler = self._reassemblers[part.agent] = Reassembler(shape)
            if reassembler is None:
                state.error = state.error or (
                    f"no tree definition for agent {part.agent!r} (shape {part.shape_hash:08x}, "
                    f"{part.node_count} nodes) received yet: the CRS sends each agent's definition "
                    "when its tree changes and every few seconds"
                )
            else:
                try:
                    decoded = reassembler.add(part)
                except StatusCodecError as exc:
                    state.error = str(exc)
                else:
                    if decoded is not None:
                        state.decoded = decoded
                        state.error = None
            changed.add(part.agent)

        return changed


def status_counts(state: TreeState) -> dict[Status, int]:
    """Nodes per status of an agent's newest tick (decoded when possible, else the parts seen)."""
    if state.decoded is not None:
        return dict(Counter(s for _, s in state.decoded.nodes))
    return dict(state.counts)


__all__ = ["AgentTrees", "TreeState", "status_counts", "status_part"]
