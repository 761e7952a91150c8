"""Tree definitions as documents and as link-sized parts: round trips, refusals, bounds."""

from __future__ import annotations

import json
import random
import zlib

import py_trees
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tlt_common.bt import shape_definition as sd
from tlt_common.bt.status_codec import StatusCodecError, TreeShape, decode, encode


def big_tree(members: int = 120) -> py_trees.behaviour.Behaviour:
    """A tree whose definition needs several parts (distinct names compress poorly)."""
    bays = []
    for bay in range(members // 10):
        noise = random.Random(bay)
        steps = [py_trees.behaviours.Success(f"Place b{bay}_m{k} at {noise.random():.6f}") for k in range(10)]
        bays.append(py_trees.composites.Sequence(f"Construct Bay {bay}", memory=True, children=steps))
    return py_trees.composites.Sequence("CRS", memory=False, children=bays)


def test_parts_in_any_order_and_with_copies_make_the_shape_again():
    shape = TreeShape.of(big_tree())
    parts = sd.split_definition(shape, "crs", max_chunk_bytes=200)
    assert len(parts) >= 3 and all(len(p.chunk) <= 200 for p in parts)
    assert {p.fields()["agent"] for p in parts} == {"crs"}
    shuffled = parts + parts[:2]
    random.Random(1).shuffle(shuffled)
    assembler = sd.DefinitionAssembler()
    shapes = [s for p in shuffled if (s := assembler.add(sd.DefinitionPart.from_fields(p.fields())))]
    assert shapes and shapes[0].hash == shape.hash and shapes[0].definition() == shape.definition()
    # The rebuilt shape decodes the agent's status.
    status = encode(shape, agent="crs", tick_count=7)
    assert decode(status, shapes[0]).as_dict() == decode(status, shape).as_dict()


def test_a_definition_that_does_not_hash_to_the_shape_it_claims_is_refused():
    shape = TreeShape.of(big_tree(20))
    other = TreeShape.of(big_tree(30))
    forged = [
        sd.DefinitionPart("crs", shape.hash, len(other), p.part_index, p.part_count, p.chunk)
        for p in sd.split_definition(other, "crs")
    ]
    with pytest.raises(StatusCodecError, match="hashes to"):
        sd.join_definition(forged)


@pytest.mark.parametrize(
    "chunk, words",
    [
        (b"not zlib at all", "does not inflate"),
        (zlib.compress(b"[1, 2"), "not JSON"),
        (zlib.compress(b"\0" * (sd.MAX_DEFINITION_BYTES + 1)), "too large"),
        (zlib.compress(b'{"definition": 3}'), "list of nodes"),
        (zlib.compress(b"[" * 100_000), "not JSON"),
    ],
)
def test_a_body_that_is_not_a_definition_is_refused_with_the_reason(chunk, words):
    with pytest.raises(StatusCodecError, match=words):
        sd.join_definition([sd.DefinitionPart("ars_x", 1, 1, 0, 1, chunk)])


def test_parts_that_do_not_make_one_whole_are_refused():
    shape = TreeShape.of(big_tree(20))
    parts = sd.split_definition(shape, "crs", max_chunk_bytes=100)
    with pytest.raises(StatusCodecError, match="one whole"):
        sd.join_definition(parts[1:])
    with pytest.raises(StatusCodecError, match="part 3 of 2"):
        sd.DefinitionAssembler().add(sd.DefinitionPart("crs", 1, 1, 3, 2, b""))


def test_the_assembler_keeps_a_bounded_number_of_incomplete_definitions():
    assembler = sd.DefinitionAssembler(max_pending=4)
    for shape_hash in range(100):
        assert assembler.add(sd.DefinitionPart("crs", shape_hash, 5, 0, 2, b"x")) is None
    assert len(assembler._pending) == 4


def test_document_json_round_trip_and_refusals():
    shape = TreeShape.of(big_tree(10))
    agent, back = sd.parse_document_json(sd.document_json(shape, "ars_y"))
    assert agent == "ars_y" and back.hash == shape.hash
    document = sd.definition_document(shape, "ars_y")
    document["shape_hash"] = "00000000"
    with pytest.raises(StatusCodecError, match="hashes to"):
        sd.parse_document_json(json.dumps(document))
    with pytest.raises(StatusCodecError, match="names no agent"):
        sd.parse_document_json(json.dumps({"definition": shape.definition()}))
    with pytest.raises(StatusCodecError, match="not JSON"):
        sd.parse_document_json("{")


def test_a_packet_field_missing_gives_no_part():
    assert sd.DefinitionPart.from_fields({"agent": "crs"}) is None


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 3), st.integers(0, 4), st.integers(1, 4), st.binary(max_size=64)),
        max_size=12,
    )
)
def test_no_sequence_of_parts_raises_anything_but_a_codec_error(parts):
    """Whatever parts arrive (the GSW decodes what the link authenticated, but a bug or a key
    compromise must not crash its displays), the assembler returns a shape, None, or refuses."""
    assembler = sd.DefinitionAssembler(max_pending=3)
    for shape_hash, index, count, chunk in parts:
        try:
            shape = assembler.add(
                sd.DefinitionPart("ars_x", shape_hash, 3, index, count, zlib.compress(chunk))
            )
        except StatusCodecError:
            continue
        assert shape is None or isinstance(shape, TreeShape)
