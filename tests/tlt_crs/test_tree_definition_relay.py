"""The CRS's tree definition relay: a definition goes out when an agent moves to a shape, and
every agent's current one again on each resend."""

from __future__ import annotations

import py_trees

from tlt_common.bt.shape_definition import DefinitionAssembler, DefinitionPart
from tlt_common.bt.status_codec import TreeShape
from tlt_crs.tree_definition_relay import TreeDefinitionRelay


def shape_of(*leaves: str) -> TreeShape:
    children = [py_trees.behaviours.Success(name) for name in leaves]
    return TreeShape.of(py_trees.composites.Sequence("ARS", memory=False, children=children))


def test_a_definition_goes_out_on_each_change_of_shape_and_on_each_resend():
    sent: list[tuple[str, dict]] = []
    relay = TreeDefinitionRelay(lambda kind, fields: sent.append((kind, fields)), max_chunk_bytes=40)
    idle, request = shape_of("idle"), shape_of("idle", "Approach Dispenser", "Grasp Part")
    relay.shape("ars_x", idle)
    first = len(sent)
    assert first >= 2 and {kind for kind, _ in sent} == {"tree_definition"}
    relay.shape("ars_x", idle)
    assert len(sent) == first, "the same shape again: nothing new to say"
    relay.shape("ars_x", request)
    relay.shape("crs", idle)
    assembler = DefinitionAssembler()
    shapes = [s for _, f in sent if (s := assembler.add(DefinitionPart.from_fields(f)))]
    assert [s.hash for s in shapes] == [idle.hash, request.hash, idle.hash]
    before = len(sent)
    relay.resend()
    again = [DefinitionPart.from_fields(f) for _, f in sent[before:]]
    assert {(p.agent, p.shape_hash) for p in again} == {("ars_x", request.hash), ("crs", idle.hash)}
