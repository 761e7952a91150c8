"""The tree definitions the CRS sends to the ground: its own tree's and each ARS's.

Every agent's status goes to the ground as 2 bits per node and a shape hash; the ground names the
nodes with the shape's definition (:mod:`tlt_common.bt.shape_definition`). The relay sends an agent's
definition as ``tree_definition`` packets when the agent moves to that shape (the CRS's own from
its tree, an ARS's from its ``tree_definition`` topic, which it publishes before the shape's first
status), and again for each agent's current shape when :meth:`TreeDefinitionRelay.resend` runs
(the ground bridge's timer, at the packet's rate), so a ground station started late learns every
tree within one period.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from tlt_common.bt.shape_definition import DEFAULT_MAX_CHUNK_BYTES, DefinitionPart, split_definition
from tlt_common.bt.status_codec import StatusCodecError, TreeShape

_log = logging.getLogger(__name__)


class TreeDefinitionRelay:
    """Sends each agent's tree definitions through ``send(kind, fields)`` (the ground link's
    telemetry, authenticated like every packet); thread-safe."""

    def __init__(
        self, send: Callable[[str, dict[str, Any]], None], max_chunk_bytes: int = DEFAULT_MAX_CHUNK_BYTES
    ) -> None:
        self._send = send
        self.max_chunk_bytes = max_chunk_bytes
        self._current: dict[str, tuple[int, list[DefinitionPart]]] = {}  # agent -> (hash, parts)
        self._lock = threading.Lock()

    def shape(self, agent: str, shape: TreeShape) -> None:
        """``agent`` now ticks ``shape``: its definition goes out now, unless it is the shape the
        agent already had."""
        with self._lock:
            current = self._current.get(agent)
            if current is not None and current[0] == shape.hash:
                return
            try:
                parts = split_definition(shape, agent, self.max_chunk_bytes)
            except StatusCodecError as exc:
                _log.warning("tree definition of %s (shape %08x) not sent: %s", agent, shape.hash, exc)
                return
            self._current[agent] = (shape.hash, parts)
        self._emit(parts)

    def resend(self) -> None:
        """Send every agent's current definition again."""
        with self._lock:
            batches = [parts for _, parts in self._current.values()]
        for parts in batches:
            self._emit(parts)

    def _emit(self, parts: list[DefinitionPart]) -> None:
        for part in parts:
            self._send("tree_definition", part.fields())


__all__ = ["TreeDefinitionRelay"]
