"""Endpoint and state-file settings of the ground link, from ``config/ccsds/link.yaml``.

Validated with :mod:`tlt_common.config_schema`; paths have ``~`` and ``$VARS`` expanded. Errors name
the file, the key and the reason.
"""

from __future__ import annotations

import ipaddress
import os
import socket
from pathlib import Path
from typing import Any, TypedDict

from tlt_common.ccsds.sources import check_sources
from tlt_common.config_schema import ConfigError, Field, load_validated, opt

DEFAULT_PATH = Path(__file__).resolve().parents[3] / "config" / "ccsds" / "link.yaml"
ENV_PATH = "TLT_CCSDS_LINK_CONFIG"


class _Range(TypedDict):
    minimum: float
    maximum: float


_PORT: _Range = {"minimum": 0, "maximum": 65535}
# The peers a receiver accepts datagrams from: IPv4 addresses, each "address" (any port) or
# "address:port". Absent: the peer the file names (see load_link_config).
_ACCEPT_FROM = opt("list", None, item=Field("str"), min_items=1, check=check_sources)
SCHEMA = {
    "key_file": opt("str", ""),
    "key_id": Field("int", minimum=0, maximum=0xFFFF),
    # The telemetry key id the CRS signs with when it starts (a `tm` line of the key file).
    "tm_key_id": opt("int", 1, minimum=0, maximum=0xFFFF),
    "crs": Field(
        "dict",
        schema={
            "bind_host": Field("str"),
            "bind_port": Field("int", **_PORT),
            "gsw_host": opt("str", ""),
            "gsw_port": opt("int", 0, **_PORT),
            "replay_state": Field("str"),
            "max_rejection_events_per_s": opt("float", 20.0, minimum=0.1),
            "accept_from": _ACCEPT_FROM,
        },
    ),
    "gsw": Field(
        "dict",
        schema={
            "crs_host": Field("str"),
            "crs_port": Field("int", **_PORT),
            "bind_host": Field("str"),
            "bind_port": Field("int", **_PORT),
            "archive": Field("str"),
            "command_state": Field("str"),
            "ack_timeout_s": opt("float", 2.0, minimum=0.01, maximum=600.0),
            # After the first telemetry under a newer key id, older ids stay accepted this long.
            "tm_key_overlap_s": opt("float", 30.0, minimum=0.0, maximum=86400.0),
            "accept_from": _ACCEPT_FROM,
        },
    ),
}


def expand_path(text: str) -> Path:
    return Path(os.path.expandvars(os.path.expanduser(text)))


# Environment overrides of the UDP ports, so that runs side by side (tests, a main job) each have
# their own link without a file apiece: the CRS's command port and the GSW's telemetry port. The
# hosts' addresses likewise, so that one file serves a run on one machine and on emulated hosts.
ENV_CRS_PORT = "TLT_GROUND_CRS_PORT"
ENV_GSW_PORT = "TLT_GROUND_GSW_PORT"
ENV_CRS_HOST = "TLT_GROUND_CRS_HOST"
ENV_GSW_HOST = "TLT_GROUND_GSW_HOST"


def load_link_config(path: str | Path | None = None) -> dict[str, Any]:
    """Load the link settings: ``path``, else ``$TLT_CCSDS_LINK_CONFIG``, else the project's file;
    then ``$TLT_GROUND_CRS_PORT`` / ``$TLT_GROUND_GSW_PORT`` replace the ports, and
    ``$TLT_GROUND_CRS_HOST`` / ``$TLT_GROUND_GSW_HOST`` the addresses (each end's own and the one it
    sends to), when set.

    An absent ``accept_from`` becomes the peer the file names, after those overrides: the CRS
    accepts ``crs.gsw_host`` on any port (``tlt gsw send`` uses a port of its own), or every source
    when that host is empty (telemetry then follows the last authenticated command); the GSW
    accepts ``gsw.crs_host:crs_port``, the socket the CRS sends from."""
    chosen = Path(path or os.environ.get(ENV_PATH) or DEFAULT_PATH)
    conf = load_validated(chosen, SCHEMA)
    for var, keys in (
        (ENV_CRS_PORT, (("crs", "bind_port"), ("gsw", "crs_port"))),
        (ENV_GSW_PORT, (("crs", "gsw_port"), ("gsw", "bind_port"))),
    ):
        text = os.environ.get(var, "")
        if not text:
            continue
        if not text.isdigit() or not 0 < int(text) < 65536:
            raise ConfigError(f"${var}", "", f"{text!r} is not a UDP port")
        for section, key in keys:
            conf[section][key] = int(text)
    for var, keys in (
        (ENV_CRS_HOST, (("crs", "bind_host"), ("gsw", "crs_host"))),
        (ENV_GSW_HOST, (("crs", "gsw_host"), ("gsw", "bind_host"))),
    ):
        text = os.environ.get(var, "").strip()
        if not text:
            continue
        try:
            ipaddress.ip_address(text)
        except ValueError:
            raise ConfigError(f"${var}", "", f"{text!r} is not an IP address") from None
        for section, key in keys:
            conf[section][key] = text
    crs, gsw = conf["crs"], conf["gsw"]
    if crs["accept_from"] is None and crs["gsw_host"]:
        crs["accept_from"] = _peer_addresses(chosen, "crs.gsw_host", crs["gsw_host"])
    if gsw["accept_from"] is None:
        hosts = _peer_addresses(chosen, "gsw.crs_host", gsw["crs_host"])
        gsw["accept_from"] = [f"{host}:{gsw['crs_port']}" for host in hosts]
    return conf


def _peer_addresses(source: Path, key: str, host: str) -> list[str]:
    """The IPv4 addresses of a peer host named in the file (an address, or a name resolved here)."""
    try:
        return [str(ipaddress.IPv4Address(host))]
    except ValueError:
        pass
    try:
        addresses = socket.gethostbyname_ex(host)[2]
    except OSError as exc:
        reason = f"cannot resolve {host!r} for the accepted sources ({exc}); set accept_from"
        raise ConfigError(source, key, reason) from None
    return sorted(set(addresses))


__all__ = ["expand_path", "load_link_config"]
