"""The ground station's part of the several-hosts system test, run inside the ground host:
``several_hosts_ground.py LINK_YAML COMMAND [KEY VALUE]`` sends one authenticated ground command
to the CRS over CCSDS/UDP (tlt_gsw.link) and prints its final acknowledgement as
``ack <stage> <reason> <detail>``. Telemetry is taken only from the CRS address of LINK_YAML
(``gsw.accept_from`` as loaded). Exit 0 when the command completed, 1 when it was refused or failed, 2 when
no final acknowledgement came within 20 s (the command is sent again every 2 s until one does)."""

from __future__ import annotations

import sys
import time

import yaml

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.link_config import load_link_config
from tlt_gsw.link import GswLink, accepted_sources


def main() -> int:
    link = load_link_config(sys.argv[1])
    command = sys.argv[2]
    params = {"key": sys.argv[3], "value": yaml.safe_load(sys.argv[4])} if len(sys.argv) > 4 else None
    gsw_conf = link["gsw"]
    with GswLink(
        load_definitions(),
        KeyRing.load(link["key_file"]),
        link["key_id"],
        (gsw_conf["crs_host"], gsw_conf["crs_port"]),
        bind=(gsw_conf["bind_host"], 0),
        accept_from=accepted_sources(gsw_conf),
    ) as gsw:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            ack = gsw.wait_ack(gsw.send_command(command, params), final=True, timeout=2.0)
            if ack is not None:
                print(f"ack {ack.stage.name} {ack.reason.name} {ack.detail}", flush=True)
                return 0 if ack.stage.name == "COMPLETED" else 1
    print("no final acknowledgement", flush=True)
    return 2


if __name__ == "__main__":
    sys.exit(main())
