"""Status codec: round trip, size bound, shape refusal, multi-part split and TreeStatus messages."""

from __future__ import annotations

import subprocess
import sys

import py_trees
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from py_trees.common import Status

from tlt_common.bt import status_codec as sc

STATUS_LIST = [Status.INVALID, Status.RUNNING, Status.SUCCESS, Status.FAILURE]


def make_tree(bays: int = 2, extra_leaf: str | None = None) -> py_trees.behaviour.Behaviour:
    bay_nodes = []
    for n in range(1, bays + 1):
        steps = [py_trees.behaviours.Success(f"Add Member {k}") for k in range(5)]
        if extra_leaf and n == bays:
            steps.append(py_trees.behaviours.Success(extra_leaf))
        bay_nodes.append(py_trees.composites.Sequence(f"Build Bay {n}", memory=True, children=steps))
    gate = py_trees.composites.Selector(
        "Fault?",
        memory=False,
        children=[py_trees.behaviours.Failure("fault"), py_trees.behaviours.Success("ok")],
    )
    return py_trees.composites.Sequence("CRS", memory=False, children=[gate, *bay_nodes])


def set_statuses(shape: sc.TreeShape, statuses: list[Status]) -> None:
    for behaviour, status in zip(shape.behaviours, statuses, strict=True):
        behaviour.status = status


def test_round_trip_after_a_tick():
    root = make_tree()
    root.tick_once()
    shape = sc.TreeShape.of(root)
    parts = sc.encode_bytes(shape, agent="crs", tick_count=41)
    decoded = sc.decode(parts, shape)
    assert decoded.agent == "crs" and decoded.tick_count == 41
    assert decoded.nodes == [(n.path, b.status) for n, b in zip(shape.nodes, shape.behaviours, strict=True)]
    assert decoded.as_dict()["CRS/Fault?/fault"] is Status.FAILURE
    assert decoded.as_dict()["CRS/Build Bay 2/Add Member 4"] is Status.SUCCESS


def test_preorder_and_paths():
    shape = sc.TreeShape.of(make_tree(bays=1))
    assert [n.path for n in shape.nodes[:5]] == [
        "CRS",
        "CRS/Fault?",
        "CRS/Fault?/fault",
        "CRS/Fault?/ok",
        "CRS/Build Bay 1",
    ]
    assert shape.nodes[2].parent == 1 and shape.nodes[4].parent == 0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from(STATUS_LIST), min_size=1, max_size=3000), st.integers(1, 64))
def test_pack_round_trip_any_statuses(statuses, max_bytes):
    packed = sc.pack_statuses(statuses)
    assert len(packed) == (len(statuses) + 3) // 4
    assert sc.unpack_statuses(packed, len(statuses)) == statuses


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 40), st.integers(1, 8), st.randoms(use_true_random=False))
def test_multipart_round_trip(bays, max_bytes, rnd):
    root = make_tree(bays)
    shape = sc.TreeShape.of(root)
    statuses = [rnd.choice(STATUS_LIST) for _ in range(len(shape))]
    set_statuses(shape, statuses)
    parts = sc.encode(shape, agent="ars_x", tick_count=7, max_status_bytes=max_bytes)
    assert len(parts) == -(-len(shape) // (4 * max_bytes))
    assert all(len(p.status) <= max_bytes for p in parts)
    rnd.shuffle(parts)
    decoded = sc.decode([p.to_bytes() for p in parts], shape)
    assert [s for _, s in decoded.nodes] == statuses


def test_size_bound_quarter_byte_per_node_plus_header():
    root = make_tree(bays=200)
    shape = sc.TreeShape.of(root)
    parts = sc.encode_bytes(shape, agent="crs", tick_count=1, max_status_bytes=256)
    header = sc.HEADER_BYTES + len("crs")
    assert sum(len(p) for p in parts) == -(-len(shape) // 4) + len(parts) * header
    assert all(len(p) <= 256 + header for p in parts)


def test_refuses_a_different_shape():
    shape = sc.TreeShape.of(make_tree(bays=2))
    parts = sc.encode_bytes(shape, agent="crs", tick_count=1)
    renamed = sc.TreeShape.of(make_tree(bays=2, extra_leaf="Extra"))
    with pytest.raises(sc.StatusCodecError, match="shape"):
        sc.decode(parts, renamed)
    # Same node count, one name changed: still refused.
    other = make_tree(bays=2)
    other.children[1].children[0].name = "Add Member X"
    with pytest.raises(sc.StatusCodecError, match="this tree definition has shape"):
        sc.decode(parts, sc.TreeShape.of(other))


def test_shape_hash_covers_types_and_structure():
    a = py_trees.composites.Sequence("r", memory=False, children=[py_trees.behaviours.Success("x")])
    b = py_trees.composites.Selector("r", memory=False, children=[py_trees.behaviours.Success("x")])
    c = py_trees.composites.Sequence("r", memory=False, children=[py_trees.behaviours.Failure("x")])
    nested = py_trees.composites.Sequence(
        "r",
        memory=False,
        children=[py_trees.composites.Sequence("s", memory=False), py_trees.behaviours.Success("x")],
    )
    flat = py_trees.composites.Sequence(
        "r",
        memory=False,
        children=[
            py_trees.composites.Sequence("s", memory=False, children=[py_trees.behaviours.Success("x")])
        ],
    )
    hashes = {sc.TreeShape.of(t).hash for t in (a, b, c, nested, flat)}
    assert len(hashes) == 5


def test_shape_hash_is_stable_across_processes():
    code = (
        "import py_trees;from tlt_common.bt.status_codec import TreeShape;"
        "r=py_trees.composites.Sequence('CRS',memory=False,children=[py_trees.behaviours.Success('a')]);"
        "print(TreeShape.of(r).hash)"
    )
    runs = {
        subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        for _ in range(2)
    }
    local = py_trees.composites.Sequence("CRS", memory=False, children=[py_trees.behaviours.Success("a")])
    assert runs == {f"{sc.TreeShape.of(local).hash}\n"}


def test_incomplete_duplicate_and_mixed_parts_refused():
    shape = sc.TreeShape.of(make_tree(bays=10))
    parts = sc.encode(shape, agent="crs", tick_count=3, max_status_bytes=4)
    assert len(parts) > 2
    with pytest.raises(sc.StatusCodecError, match="missing part"):
        sc.decode(parts[:-1], shape)
    with pytest.raises(sc.StatusCodecError, match="given twice"):
        sc.decode([*parts, parts[0]], shape)
    later = sc.encode(shape, agent="crs", tick_count=4, max_status_bytes=4)
    with pytest.raises(sc.StatusCodecError, match="different"):
        sc.decode([*parts[:-1], later[-1]], shape)
    with pytest.raises(sc.StatusCodecError, match="no parts"):
        sc.decode([], shape)


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"\x01\x00", "shorter than"),
        (b"\x02" + bytes(19), "version"),
        (b"\x01" + bytes(17) + b"\x05ab", "truncated"),
    ],
)
def test_malformed_bytes_refused(data, reason):
    with pytest.raises(sc.StatusCodecError, match=reason):
        sc.StatusPart.from_bytes(data)


def test_wrong_status_length_refused():
    shape = sc.TreeShape.of(make_tree(bays=1))
    part = sc.encode(shape, agent="crs", tick_count=1)[0]
    broken = sc.StatusPart(**{**part.__dict__, "status": part.status + b"\x00"})
    with pytest.raises(sc.StatusCodecError, match="cannot hold"):
        sc.decode([broken], shape)


def test_reassembler_streams_parts():
    shape = sc.TreeShape.of(make_tree(bays=10))
    assembler = sc.Reassembler(shape)
    first = sc.encode(shape, agent="crs", tick_count=1, max_status_bytes=4)
    second = sc.encode(shape, agent="crs", tick_count=2, max_status_bytes=4)
    assert assembler.add(first[0]) is None
    # A newer tick discards the partial older one; a late older part is dropped.
    for part in second[:-1]:
        assert assembler.add(part) is None
    assert assembler.add(first[1]) is None
    decoded = assembler.add(second[-1].to_bytes())
    assert decoded is not None and decoded.tick_count == 2


def test_tree_status_message_round_trip():
    root = make_tree(bays=3)
    root.tick_once()
    shape = sc.TreeShape.of(root)
    messages = [p.to_msg() for p in sc.encode(shape, agent="ars_y", tick_count=2**40, max_status_bytes=2)]
    assert messages[0].agent == "ars_y" and messages[0].tick_count == 2**40
    assert messages[1].first_node == 8 and messages[0].part_count == len(messages)
    decoded = sc.decode([sc.StatusPart.from_msg(m) for m in messages], shape)
    assert [s for _, s in decoded.nodes] == shape.statuses()


def test_apply_to_a_ground_copy():
    robot = make_tree(bays=2)
    robot.tick_once()
    ground = make_tree(bays=2)
    robot_shape, ground_shape = sc.TreeShape.of(robot), sc.TreeShape.of(ground)
    sc.apply_to_tree(sc.decode(sc.encode(robot_shape, agent="crs", tick_count=1), ground_shape), ground_shape)
    assert ground_shape.statuses() == robot_shape.statuses()


def test_long_agent_name_refused():
    shape = sc.TreeShape.of(make_tree(bays=1))
    with pytest.raises(sc.StatusCodecError, match="longer than"):
        sc.encode_bytes(shape, agent="x" * 40, tick_count=1)


def test_definition_round_trip_decodes_without_the_tree():
    """The ground can decode with the shape's JSON definition alone, no robot behaviours needed."""
    import json

    root = make_tree(bays=3)
    root.tick_once()
    shape = sc.TreeShape.of(root)
    ground = sc.TreeShape.from_definition(json.loads(json.dumps(shape.definition())))
    assert ground.hash == shape.hash
    assert [n.path for n in ground.nodes] == [n.path for n in shape.nodes]
    assert [n.parent for n in ground.nodes] == [n.parent for n in shape.nodes]
    decoded = sc.decode(sc.encode_bytes(shape, agent="crs", tick_count=5), ground)
    assert [s for _, s in decoded.nodes] == shape.statuses()
    with pytest.raises(sc.StatusCodecError, match="no behaviours"):
        sc.encode(ground, agent="crs", tick_count=1)


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda d: d[1].update(depth=3), "expected 1"),
        (lambda d: d[0].update(children=9), "ends before every child"),
        (lambda d: d[0].update(children=1), "outside the root"),
        (lambda d: d[2].pop("name"), "unreadable"),
        (lambda d: d.clear(), "empty"),
    ],
)
def test_inconsistent_definition_refused(edit, reason):
    definition = sc.TreeShape.of(make_tree(bays=1)).definition()
    edit(definition)
    with pytest.raises(sc.StatusCodecError, match=reason):
        sc.TreeShape.from_definition(definition)
