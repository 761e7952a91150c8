"""The Fast DDS profile and environment of processes that run in emulated hosts.

The profile (``config/dds/emulated_hosts.xml`` by default) turns shared memory off and discovers
participants by unicast to initial peers. The peers must be the addresses of the hosts of the
running launch set, so the launcher renders a copy of the profile with its ``initialPeersList``
replaced by those addresses and gives every process in a host an environment that selects it.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path

from tlt_common.config_schema import ConfigError

NS = "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"
DDS_CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "dds"
DEFAULT_PROFILE = DDS_CONFIG_DIR / "emulated_hosts.xml"
# Variables that would keep a process in a host on its own loopback, or add peers it cannot reach.
CONFINING_VARIABLES = ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS")


def _q(tag: str) -> str:
    return f"{{{NS}}}{tag}"


def render_profile(template: str | Path, peers: Iterable[str], out: str | Path) -> Path:
    """Write ``template`` to ``out`` with the default participant's initial peers set to ``peers``.

    Raises :class:`ConfigError` (naming the template) when it is not a Fast DDS profiles file with
    a default participant profile that has ``rtps/builtin``.
    """
    template, out = Path(template), Path(out)
    try:
        tree = ET.parse(template)
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(str(template), "", f"cannot read the Fast DDS profile: {exc}") from None
    root = tree.getroot()
    if root.tag != _q("profiles"):
        raise ConfigError(str(template), "profiles", f'expected a <profiles xmlns="{NS}"> root')
    participants = root.findall(_q("participant"))
    default = [p for p in participants if p.get("is_default_profile") == "true"] or participants[:1]
    builtin = default[0].find(f"{_q('rtps')}/{_q('builtin')}") if default else None
    if builtin is None:
        raise ConfigError(
            str(template),
            "participant.rtps.builtin",
            "a default participant profile with <rtps><builtin> is needed for the peers",
        )
    for old in builtin.findall(_q("initialPeersList")):
        builtin.remove(old)
    peers_list = ET.SubElement(builtin, _q("initialPeersList"))
    for address in peers:
        locator = ET.SubElement(peers_list, _q("locator"))
        ET.SubElement(ET.SubElement(locator, _q("udpv4")), _q("address")).text = address
    ET.register_namespace("", NS)
    out.parent.mkdir(parents=True, exist_ok=True)
    tree.write(out, encoding="UTF-8", xml_declaration=True)
    return out


def host_environment(profile: str | Path, environ: dict[str, str]) -> dict[str, str]:
    """``environ`` for a process in a host: the profile selected (Fast DDS 2 and 3 read different
    variables), discovery over the subnet, and nothing that confines it to loopback."""
    env = {k: v for k, v in environ.items() if k not in CONFINING_VARIABLES}
    env["FASTRTPS_DEFAULT_PROFILES_FILE"] = env["FASTDDS_DEFAULT_PROFILES_FILE"] = os.fspath(profile)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    env["RMW_IMPLEMENTATION"] = "rmw_fastrtps_cpp"
    return env
