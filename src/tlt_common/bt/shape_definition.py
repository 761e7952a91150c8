"""A tree shape's definition, as a document and split into link-sized parts (docs/behaviour-trees.md).

The status codec sends only 2 bits per node and a shape hash; naming the nodes needs the tree's
shape (:meth:`TreeShape.definition`). Each agent therefore sends the definition of every shape it
ticks, once per shape and again periodically (a ground station started late still learns it):

* **document**: ``{"agent", "shape_hash", "definition"}``, the JSON an agent publishes on its
  ``tree_definition`` topic (``std_msgs/String``, transient local) and the GUI's definition files
  hold. :func:`shape_from_document` refuses a document whose definition does not hash to the
  hash it states, so a definition can never name the nodes of another shape.
* **parts**: the definition list as compact JSON, zlib-compressed, cut into chunks of at most
  ``max_chunk_bytes``; one ``tree_definition`` telemetry packet carries one part.
  :class:`DefinitionAssembler` puts parts back together on the ground, bounded in memory and in
  the size a compressed body may expand to.
"""

from __future__ import annotations

import json
import zlib
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from tlt_common.bt.status_codec import StatusCodecError, TreeShape

DEFAULT_MAX_CHUNK_BYTES = 1024
# A definition larger than this once inflated is refused (a node takes about 80 bytes of JSON).
MAX_DEFINITION_BYTES = 8 << 20
MAX_PARTS = 255


def definition_document(shape: TreeShape, agent: str = "") -> dict[str, Any]:
    """``shape`` as the document agents publish and definition files hold."""
    return {"agent": agent, "shape_hash": f"{shape.hash:08x}", "definition": shape.definition()}


def shape_from_document(document: Any) -> TreeShape:
    """The shape of a document (or of a bare definition list); refuses an inconsistent one."""
    definition = document.get("definition") if isinstance(document, dict) else document
    if not isinstance(definition, list):
        raise StatusCodecError("expected a list of nodes (TreeShape.definition())")
    shape = TreeShape.from_definition(definition)
    stated = document.get("shape_hash") if isinstance(document, dict) else None
    if stated is not None and stated != f"{shape.hash:08x}":
        raise StatusCodecError(f"document says shape {stated}, its definition hashes to {shape.hash:08x}")
    return shape


def document_json(shape: TreeShape, agent: str) -> str:
    """:func:`definition_document` as compact JSON text (the ``tree_definition`` topic's message)."""
    return json.dumps(definition_document(shape, agent), separators=(",", ":"))


def parse_document_json(text: str) -> tuple[str, TreeShape]:
    """(agent, shape) of a ``tree_definition`` message's text; raises StatusCodecError."""
    try:
        document = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StatusCodecError(f"tree definition is not JSON: {exc}") from exc
    if not isinstance(document, dict) or not isinstance(document.get("agent"), str):
        raise StatusCodecError("tree definition document names no agent")
    return document["agent"], shape_from_document(document)


@dataclass(frozen=True)
class DefinitionPart:
    """One part of a compressed tree definition, as one ``tree_definition`` packet carries it."""

    agent: str
    shape_hash: int
    node_count: int
    part_index: int
    part_count: int
    chunk: bytes

    def fields(self) -> dict[str, Any]:
        """The packet's fields (config/ccsds/definitions.yaml, ``tree_definition``)."""
        return {
            "agent": self.agent,
            "shape_hash": self.shape_hash,
            "node_count": self.node_count,
            "part_index": self.part_index,
            "part_count": self.part_count,
            "definition": self.chunk,
        }

    @classmethod
    def from_fields(cls, fields: Mapping[str, Any]) -> DefinitionPart | None:
        """The part a decoded packet carries (None when a field is missing or mistyped)."""
        f = fields
        try:
            return cls(
                str(f["agent"]), int(f["shape_hash"]), int(f["node_count"]), int(f["part_index"]),
                int(f["part_count"]), bytes(f["definition"]),
            )  # fmt: skip
        except (KeyError, TypeError, ValueError):
            return None


def split_definition(
    shape: TreeShape, agent: str, max_chunk_bytes: int = DEFAULT_MAX_CHUNK_BYTES
) -> list[DefinitionPart]:
    """``shape``'s definition, compressed, as parts of at most ``max_chunk_bytes`` each."""
    if max_chunk_bytes < 1:
        raise ValueError("max_chunk_bytes must be at least 1")
    body = zlib.compress(json.dumps(shape.definition(), separators=(",", ":")).encode("utf-8"), 9)
    chunks = [body[i : i + max_chunk_bytes] for i in range(0, len(body), max_chunk_bytes)]
    if len(chunks) > MAX_PARTS:
        raise StatusCodecError(
            f"definition of {len(shape)} nodes needs {len(chunks)} parts; at most {MAX_PARTS}"
        )
    return [
        DefinitionPart(agent, shape.hash, len(shape), i, len(chunks), chunk) for i, chunk in enumerate(chunks)
    ]


def join_definition(parts: list[DefinitionPart]) -> TreeShape:
    """The shape of one complete set of parts (any order); raises StatusCodecError."""
    if not parts:
        raise StatusCodecError("no definition parts")
    head = parts[0]
    by_index = {p.part_index: p for p in parts}
    if sorted(by_index) != list(range(head.part_count)) or any(
        (p.shape_hash, p.part_count, p.node_count) != (head.shape_hash, head.part_count, head.node_count)
        for p in parts
    ):
        raise StatusCodecError(f"definition parts of shape {head.shape_hash:08x} do not make one whole")
    inflate = zlib.decompressobj()
    try:
        whole = b"".join(by_index[i].chunk for i in range(head.part_count))
        body = inflate.decompress(whole, MAX_DEFINITION_BYTES)
    except zlib.error as exc:
        raise StatusCodecError(f"definition of shape {head.shape_hash:08x} does not inflate: {exc}") from exc
    if inflate.unconsumed_tail or not inflate.eof:
        raise StatusCodecError(f"definition of shape {head.shape_hash:08x} is truncated or too large")
    try:
        definition = json.loads(body)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise StatusCodecError(f"definition of shape {head.shape_hash:08x} is not JSON: {exc}") from exc
    shape = shape_from_document(definition)
    if shape.hash != head.shape_hash or len(shape) != head.node_count:
        raise StatusCodecError(
            f"definition sent as shape {head.shape_hash:08x} ({head.node_count} nodes) hashes to"
            f" {shape.hash:08x} ({len(shape)} nodes)"
        )
    return shape


class DefinitionAssembler:
    """Collects definition parts as they arrive (any agent, any order, resent copies) and returns
    each shape once complete. At most ``max_pending`` incomplete definitions are kept (the oldest
    is dropped), so parts that never complete cannot grow it without bound."""

    def __init__(self, max_pending: int = 16) -> None:
        self.max_pending = max_pending
        self._pending: OrderedDict[tuple[int, int, int], dict[int, DefinitionPart]] = OrderedDict()

    def add(self, part: DefinitionPart) -> TreeShape | None:
        """The shape once ``part`` completes it, else None; raises StatusCodecError for a
        complete set that does not make the shape it says (the set is dropped)."""
        if not 0 <= part.part_index < part.part_count:
            raise StatusCodecError(f"definition part {part.part_index} of {part.part_count}")
        key = (part.shape_hash, part.node_count, part.part_count)
        parts = self._pending.setdefault(key, {})
        self._pending.move_to_end(key)
        parts[part.part_index] = part
        while len(self._pending) > self.max_pending:
            self._pending.popitem(last=False)
        if len(parts) < part.part_count:
            return None
        del self._pending[key]
        return join_definition(list(parts.values()))


__all__ = [
    "DEFAULT_MAX_CHUNK_BYTES",
    "DefinitionAssembler",
    "DefinitionPart",
    "definition_document",
    "document_json",
    "join_definition",
    "parse_document_json",
    "shape_from_document",
    "split_definition",
]
