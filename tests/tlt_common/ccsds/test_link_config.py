"""Link settings: the project's file validates; mistakes name file, key and reason."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

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


def test_each_end_accepts_by_default_the_peer_its_file_names():
    conf = load_link_config()
    assert conf["crs"]["accept_from"] == [conf["crs"]["gsw_host"]]  # any port: `send` has its own
    assert conf["gsw"]["accept_from"] == [f"{conf['gsw']['crs_host']}:{conf['gsw']['crs_port']}"]


def test_accepted_peers_follow_the_emulated_hosts_of_the_launch_set(monkeypatch):
    launch = DEFAULT_PATH.parents[1] / "launch" / "system_hosts_twin.yaml"
    env = yaml.safe_load(launch.read_text())["env"]
    hosts = {h["name"]: h["address"].split("/")[0] for h in yaml.safe_load(launch.read_text())["hosts"]}
    assert (env["TLT_GROUND_CRS_HOST"], env["TLT_GROUND_GSW_HOST"]) == (hosts["crs"], hosts["ground"])
    for var in ("TLT_GROUND_CRS_HOST", "TLT_GROUND_GSW_HOST"):
        monkeypatch.setenv(var, env[var])
    conf = load_link_config(DEFAULT_PATH.with_name("link_twin.yaml"))
    assert conf["crs"]["accept_from"] == [hosts["ground"]]
    assert conf["gsw"]["accept_from"] == [f"{hosts['crs']}:{conf['crs']['bind_port']}"]


def test_a_crs_that_sends_to_its_last_commander_accepts_any_source(tmp_path):
    text = DEFAULT_PATH.read_text().replace("  gsw_host: 127.0.0.1\n", '  gsw_host: ""\n')
    (tmp_path / "link.yaml").write_text(text)
    assert load_link_config(tmp_path / "link.yaml")["crs"]["accept_from"] is None


@pytest.mark.parametrize(
    ("accept_from", "reason"),
    [
        ("[127.0.0.1, 10.0.0.300]", "item 1: '10.0.0.300' is not an IPv4 address"),
        ("['10.0.0.1:']", "item 0: '' is not a UDP port (1 ... 65535)"),
        ("[]", "expected at least 1 item(s), got 0"),
        ("10.0.0.1", "expected a list, got str '10.0.0.1'"),
    ],
)
def test_a_bad_accepted_source_is_refused_naming_file_and_key(tmp_path, accept_from, reason):
    text = DEFAULT_PATH.read_text().replace(
        "  tm_key_overlap_s: 30.0\n", f"  tm_key_overlap_s: 30.0\n  accept_from: {accept_from}\n"
    )
    bad = tmp_path / "link.yaml"
    bad.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_link_config(bad)
    assert (info.value.source, info.value.key, info.value.reason) == (str(bad), "gsw.accept_from", reason)
