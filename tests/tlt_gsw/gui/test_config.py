"""config/gsw/gui.yaml is validated on load; mistakes name the file and the key."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tlt_common.ccsds.definitions import load_definitions
from tlt_common.config_schema import ConfigError
from tlt_gsw.gui.config import DEFAULT_PATH, load_gui_config

DEFS = load_definitions()


def test_the_project_file_loads():
    conf = load_gui_config(None, DEFS)
    assert conf.refresh_hz == 10.0
    assert ("hk_lifter", "position_0") in conf.plot_fields
    assert conf.mission is not None and conf.mission.exists()


def _write(tmp_path: Path, **changes) -> Path:
    data = yaml.safe_load(DEFAULT_PATH.read_text())
    data.update(changes)
    path = tmp_path / "gui.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"plot_fields": ["hk_lifter.nope"]}, "plot_fields[0]: 'hk_lifter.nope' is not KIND.FIELD"),
        ({"refresh_hz": 0.0}, "refresh_hz"),
        ({"colour": "red"}, "colour: unknown key"),
        ({"packet_rows": "many"}, "packet_rows"),
    ],
)
def test_mistakes_name_file_and_key(tmp_path, changes, message):
    path = _write(tmp_path, **changes)
    with pytest.raises(ConfigError) as err:
        load_gui_config(path, DEFS)
    assert str(path) in str(err.value) and message in str(err.value)


def test_relative_paths_are_relative_to_the_file(tmp_path):
    path = _write(tmp_path, mission="m.yaml", tree_definitions={"crs": "trees/crs.json"})
    conf = load_gui_config(path, DEFS)
    assert conf.mission == tmp_path / "m.yaml"
    assert conf.tree_definitions == {"crs": tmp_path / "trees" / "crs.json"}
