"""Link settings: the project's file validates; mistakes name file, key and reason."""

from __future__ import annotations

import pytest

from tlt_common.ccsds.link_config import DEFAULT_PATH, expand_path, load_link_config
from tlt_common.config_schema import ConfigError


def test_project_link_settings_load():
    conf = load_link_config()
    assert conf["crs"]["bind_port"] == conf["gsw"]["crs_port"]
    assert (conf["crs"]["gsw_host"], conf["crs"]["gsw_port"]) == (
        conf["gsw"]["bind_host"],
        conf["gsw"]["bind_port"],
    )
    assert not expand_path(conf["crs"]["replay_state"]).is_relative_to(DEFAULT_PATH.parents[2])


def test_paths_expand_home_and_variables(monkeypatch, tmp_path):
    monkeypatch.setenv("TLT_TEST_DIR", str(tmp_path))
    assert expand_path("$TLT_TEST_DIR/x.json") == tmp_path / "x.json"
    assert "~" not in str(expand_path("~/a"))


def test_mistakes_are_named(tmp_path):
    bad = tmp_path / "link.yaml"
    bad.write_text(DEFAULT_PATH.read_text().replace("bind_port: 52001", "bind_port: 70000"))
    with pytest.raises(ConfigError) as info:
        load_link_config(bad)
    assert (info.value.key, info.value.reason) == ("crs.bind_port", "expected at most 65535, got 70000")
