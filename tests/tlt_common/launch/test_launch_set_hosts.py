"""Launch sets with emulated hosts: ``hosts:``, ``host:`` and ``placement:`` are checked before
anything starts, and the Fast DDS profile for the hosts is rendered with their addresses and
accepted by the Fast DDS of the venv. Nothing here needs network namespaces."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tlt_common.config_schema import ConfigError
from tlt_common.launch import load_launch_set
from tlt_common.launch.dds_profile import (
    DDS_CONFIG_DIR,
    DEFAULT_PROFILE,
    NS,
    host_environment,
    render_profile,
)

ROOT = Path(__file__).resolve().parents[3]
LAUNCH = ROOT / "config" / "launch"


def write(tmp_path: Path, body: str, name: str = "set.yaml") -> Path:
    path = tmp_path / name
    path.write_text(body)
    return path


HOSTS = textwrap.dedent("""
    hosts:
      - {name: crs, address: 10.77.0.11/24}
      - {name: ars_x, address: 10.77.0.12/24, extra_addresses: [10.77.0.21/24]}
""")


def test_processes_are_placed_on_declared_hosts(tmp_path):
    path = write(
        tmp_path,
        HOSTS
        + textwrap.dedent("""
    processes:
      - {name: server, executable: python, host: ars_x}
      - {name: client, executable: python, host: crs}
      - {name: local, executable: python}
    """),
    )
    launch_set = load_launch_set(path)
    assert [(p.name, p.host) for p in launch_set.processes] == [
        ("server", "ars_x"),
        ("client", "crs"),
        ("local", None),
    ]
    assert [(h.name, h.ip, h.extra_addresses) for h in launch_set.hosts] == [
        ("crs", "10.77.0.11", ()),
        ("ars_x", "10.77.0.12", ("10.77.0.21/24",)),
    ]
    assert launch_set.dds_profile == str(DEFAULT_PROFILE)
    assert launch_set.host_multicast is False


def test_placement_puts_included_processes_on_hosts(tmp_path):
    write(
        tmp_path,
        textwrap.dedent("""
    processes:
      - {name: driver, executable: python}
      - {name: agent, executable: python}
    """),
        name="inner.yaml",
    )
    path = write(
        tmp_path,
        HOSTS
        + textwrap.dedent("""
    include: [inner.yaml]
    placement: {driver: crs, agent: ars_x}
    dds_profile: profile.xml
    """),
    )
    (tmp_path / "profile.xml").write_text(DEFAULT_PROFILE.read_text())
    launch_set = load_launch_set(path)
    assert {p.name: p.host for p in launch_set.processes} == {"driver": "crs", "agent": "ars_x"}
    assert launch_set.dds_profile == str(tmp_path / "profile.xml")


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            HOSTS + "processes: [{name: a, executable: python, host: ars_y}]",
            "processes[0].host: no host 'ars_y' declared under hosts (hosts: crs, ars_x)",
        ),
        (
            "processes: [{name: a, executable: python, host: crs}]",
            "processes[0].host: no host 'crs' declared under hosts (hosts: none)",
        ),
        (
            HOSTS + "placement: {b: crs}\nprocesses: [{name: a, executable: python}]",
            "placement.b: no process 'b' in this set",
        ),
        (
            HOSTS + "placement: {a: ars_x}\nprocesses: [{name: a, executable: python, host: crs}]",
            "placement.a: a already runs on host 'crs'",
        ),
        (
            "hosts: [{name: a, address: 10.77.0.1/24}, {name: b, address: 10.77.0.1/24}]\n"
            "processes: [{name: p, executable: python}]",
            "hosts: host 'b': 10.77.0.1 is already the address of 'a'",
        ),
        (
            "hosts: [{name: a, address: 10.77.0.1/24}, {name: b, address: 10.78.0.2/24}]\n"
            "processes: [{name: p, executable: python}]",
            "hosts: host 'b': 10.78.0.2/24 is not on 10.77.0.0/24, the hosts' network",
        ),
        (
            "hosts: [{name: a, address: 10.77.0.300/24}]\nprocesses: [{name: p, executable: python}]",
            "hosts: host 'a': '10.77.0.300/24' is not an IPv4 address",
        ),
        (
            "hosts: [{name: a, address: 10.77.0.1}]\nprocesses: [{name: p, executable: python}]",
            "hosts: host 'a': '10.77.0.1' needs a prefix length, e.g. 10.77.0.1/24",
        ),
        (
            "hosts: [{name: a, address: 10.77.0.1/24}, {name: a, address: 10.77.0.2/24}]\n"
            "processes: [{name: p, executable: python}]",
            "hosts[1].name: duplicate host name 'a'",
        ),
        (
            "hosts: [{name: a_very_long_name, address: 10.77.0.1/24}]\n"
            "processes: [{name: p, executable: python}]",
            "a host name has at most 13 characters",
        ),
        (
            "hosts: [{name: switch, address: 10.77.0.1/24}]\nprocesses: [{name: p, executable: python}]",
            "'switch' is the name of the emulated network's switch",
        ),
        (
            HOSTS + "dds_profile: nowhere.xml\nprocesses: [{name: p, executable: python}]",
            "dds_profile: no Fast DDS profile at",
        ),
    ],
)
def test_a_bad_host_declaration_refuses_the_set(tmp_path, body, message):
    path = write(tmp_path, body)
    with pytest.raises(ConfigError) as caught:
        load_launch_set(path)
    assert message in str(caught.value)
    assert str(path) in str(caught.value)


def test_only_the_top_level_set_declares_hosts(tmp_path):
    inner = write(tmp_path, HOSTS + "processes: [{name: p, executable: python}]", name="inner.yaml")
    outer = write(tmp_path, "include: [inner.yaml]\n")
    with pytest.raises(ConfigError) as caught:
        load_launch_set(outer)
    assert f"{inner}: hosts: only the top-level launch set may declare hosts" in str(caught.value)


def test_the_profile_is_rendered_with_the_hosts_addresses(tmp_path):
    out = render_profile(DEFAULT_PROFILE, ["10.77.0.11", "10.77.0.12"], tmp_path / "p.xml")
    root = ET.parse(out).getroot()
    q = lambda tag: f"{{{NS}}}{tag}"  # noqa: E731
    participant = root.find(q("participant"))
    assert participant is not None and participant.get("is_default_profile") == "true"
    rtps = participant.find(q("rtps"))
    peers = [a.text for a in rtps.iter(q("address"))]
    assert peers == ["10.77.0.11", "10.77.0.12"]
    # Shared memory stays off, UDPv4 is the only transport.
    assert rtps.find(q("useBuiltinTransports")).text == "false"
    types = [t.text for t in root.iter(q("type"))]
    assert types == ["UDPv4"]
    # The default namespace is kept (Fast DDS reads the tags by their plain names).
    assert "ns0:" not in out.read_text()


def test_a_template_without_a_participant_is_refused(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text(f'<profiles xmlns="{NS}"><data_writer profile_name="w"/></profiles>')
    with pytest.raises(ConfigError, match="default participant profile"):
        render_profile(bad, ["10.77.0.1"], tmp_path / "out.xml")
    bad.write_text("<profiles")
    with pytest.raises(ConfigError, match="cannot read the Fast DDS profile"):
        render_profile(bad, ["10.77.0.1"], tmp_path / "out.xml")


def test_a_process_in_a_host_is_not_confined_to_loopback():
    env = host_environment(
        "/x/p.xml",
        {
            "ROS_LOCALHOST_ONLY": "1",
            "ROS_STATIC_PEERS": "127.0.0.1",
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_DOMAIN_ID": "7",
        },
    )
    assert env == {
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
        "ROS_DOMAIN_ID": "7",
        "FASTRTPS_DEFAULT_PROFILES_FILE": "/x/p.xml",
        "FASTDDS_DEFAULT_PROFILES_FILE": "/x/p.xml",
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
    }


def _fast_dds_complaints(profile: Path) -> str:
    """What Fast DDS prints while a node starts with ``profile`` as its default profiles file."""
    env = {
        **os.environ,
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(profile),
        "FASTDDS_DEFAULT_PROFILES_FILE": str(profile),
    }
    code = "import rclpy; rclpy.init(); rclpy.create_node('profile_check'); print('node up')"
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert "node up" in result.stdout, result.stderr
    # Fast DDS logs to stdout.
    output = result.stdout + result.stderr
    return "\n".join(line for line in output.splitlines() if "XMLPARSER" in line)


def test_fast_dds_accepts_every_profile_and_rejects_a_bad_one(tmp_path):
    rendered = render_profile(DEFAULT_PROFILE, ["10.77.0.11"], tmp_path / "rendered.xml")
    # The rendered copy stands for its template (test_the_profile_is_rendered_with_the_hosts_addresses).
    for profile in (DDS_CONFIG_DIR / "multi_jetson.xml", rendered):
        assert _fast_dds_complaints(profile) == "", profile
    bad = tmp_path / "bad.xml"
    bad.write_text(rendered.read_text().replace("<rtps>", "<rtps><leaseDuration/>"))
    assert "Invalid element found into 'rtpsParticipantAttributesType'" in _fast_dds_complaints(bad)


@pytest.mark.parametrize("name", ["system_hosts_twin", "host_crs", "host_ars_x", "host_ars_y"])
def test_the_project_host_sets_load(name):
    launch_set = load_launch_set(LAUNCH / f"{name}.yaml")
    assert launch_set.processes


def test_the_twin_on_hosts_places_every_process_like_the_edu():
    hosts_set = load_launch_set(LAUNCH / "system_hosts_twin.yaml")
    single = load_launch_set(LAUNCH / "system_twin.yaml")
    assert [p.name for p in hosts_set.processes] == [p.name for p in single.processes]
    placed = {p.name: p.host for p in hosts_set.processes}
    # A process system_twin.yaml gains must be placed too: outside the hosts it would hear none of them.
    assert [name for name, host in placed.items() if host is None] == []
    assert placed["twin"] == "twin"
    # ground_key makes a key for one twin run; on the EDU the key is provisioned (docs/deployment.md).
    run_only = {"ground_key"}
    for host in ("crs", "ars_x", "ars_y"):
        real = {p.name for p in load_launch_set(LAUNCH / f"host_{host}.yaml").processes}
        assert real == {name for name, h in placed.items() if h == host} - run_only, host
    # The arms' controllers answer on the twin host, where the drivers on the ARS hosts reach them.
    twin = next(h for h in hosts_set.hosts if h.name == "twin")
    ur_x = next(p for p in hosts_set.processes if p.name == "ur_x")
    host_arg = ur_x.argv[ur_x.argv.index("--host") + 1]
    assert f"{host_arg}/24" in twin.extra_addresses
    # The template's peers are the addresses of this set's hosts.
    template_peers = {a.text for a in ET.parse(DEFAULT_PROFILE).getroot().iter(f"{{{NS}}}address")}
    assert template_peers == {h.ip for h in hosts_set.hosts}
