"""Tree shape definition files: written by the robot side, read by the GUI."""

from __future__ import annotations

import json

import pytest

from tlt_common.bt.status_codec import TreeShape
from tlt_common.config_schema import ConfigError
from tlt_gsw.gui.demo_archive import demo_tree
from tlt_gsw.gui.tree_definitions import TreeDefinitionFiles, load_tree_definition, write_tree_definition


def test_round_trip_keeps_the_shape_hash(tmp_path):
    shape = TreeShape.of(demo_tree())
    path = write_tree_definition(shape, tmp_path / "trees" / "crs.json", agent="crs")
    loaded = load_tree_definition(path)
    assert loaded.hash == shape.hash and [n.path for n in loaded.nodes] == [n.path for n in shape.nodes]
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(shape.definition()))
    assert load_tree_definition(bare).hash == shape.hash


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "invalid JSON"),
        ('{"definition": 3}', "expected a list of nodes"),
        ('[{"depth": 0, "children": 2, "kind": "sequence", "type": "Sequence", "name": "R"}]', "ends before"),
    ],
)
def test_bad_files_name_the_file_and_the_reason(tmp_path, content, message):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(ConfigError, match=message) as err:
        load_tree_definition(path)
    assert str(path) in str(err.value)


def test_a_stated_hash_that_does_not_match_is_refused(tmp_path):
    path = write_tree_definition(TreeShape.of(demo_tree()), tmp_path / "crs.json")
    body = json.loads(path.read_text())
    body["shape_hash"] = "00000000"
    path.write_text(json.dumps(body))
    with pytest.raises(ConfigError, match="shape_hash: file says 00000000"):
        load_tree_definition(path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_tree_definition(tmp_path / "missing.json")


def test_definition_files_appear_and_change_while_the_gui_runs(tmp_path):
    full, part = TreeShape.of(demo_tree()), TreeShape.of(demo_tree().children[4])
    files = TreeDefinitionFiles({"crs": tmp_path / "crs.json", "ars_x": tmp_path / "ars_x.json"})
    assert files.load_present() == {}  # neither exists yet: not an error
    with pytest.raises(ConfigError, match="cannot read"):
        files.load_present(required={"ars_x"})
    assert files.changed("crs") is None
    write_tree_definition(full, tmp_path / "crs.json")
    assert files.changed("crs").hash == full.hash
    assert files.changed("crs") is None  # unchanged since read
    (tmp_path / "crs.json").write_text('{"definition": [')  # half written
    assert files.changed("crs") is None
    write_tree_definition(part, tmp_path / "crs.json")
    assert files.changed("crs").hash == part.hash
