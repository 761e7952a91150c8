"""Link settings: the project's file validates; mistakes name file, key and reason."""

from __future__ import annotations

from pathlib import Path

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


def test_port_overrides_from_the_environment_give_a_run_its_own_link(monkeypatch):
    monkeypatch.setenv("TLT_GROUND_CRS_PORT", "53001")
    monkeypatch.setenv("TLT_GROUND_GSW_PORT", "53002")
    conf = load_link_config(DEFAULT_PATH.with_name("link_twin.yaml"))
    assert conf["crs"]["bind_port"] == conf["gsw"]["crs_port"] == 53001
    assert conf["crs"]["gsw_port"] == conf["gsw"]["bind_port"] == 53002
    monkeypatch.setenv("RUN", "/tmp/run-x")
    assert expand_path(conf["key_file"]) == Path("/tmp/run-x/ground.key")
    monkeypatch.setenv("TLT_GROUND_CRS_PORT", "http")
    with pytest.raises(ConfigError, match=r"\$TLT_GROUND_CRS_PORT: 'http' is not a UDP port"):
        load_link_config()


def test_address_overrides_put_each_end_on_its_own_host(monkeypatch):
    monkeypatch.setenv("TLT_GROUND_CRS_HOST", "10.77.0.11")
    monkeypatch.setenv("TLT_GROUND_GSW_HOST", "10.77.0.14")
    conf = load_link_config(DEFAULT_PATH.with_name("link_twin.yaml"))
    assert conf["crs"]["bind_host"] == conf["gsw"]["crs_host"] == "10.77.0.11"
    assert conf["crs"]["gsw_host"] == conf["gsw"]["bind_host"] == "10.77.0.14"
    monkeypatch.setenv("TLT_GROUND_GSW_HOST", "ground-laptop")
    with pytest.raises(ConfigError, match=r"\$TLT_GROUND_GSW_HOST: 'ground-laptop' is not an IP address"):
        load_link_config()
