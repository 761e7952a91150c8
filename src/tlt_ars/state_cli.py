"""``tlt ars-state``: read an ARS's state file, and settle by hand what the ARS cannot.

The state file (:mod:`tlt_ars.request_data`) is what a restarted ARS resumes from. Most of what it
keeps the ARS settles by itself when the CRS sends the request again; what it cannot is a step left
in doubt (the gun's shot, a cross frame let go of) when the arm has moved since, or a frame that is
still not seen in place: every retry then fails and, while the gripper holds the member, every other
request is refused. An engineer who has looked at the member says what is true, with the ARS
stopped (it reads the file only at start-up, and a running ARS writes over it)::

    tlt ars-state show    runs/ars_x_request.json --ars ars_x --mission missions/two_bay.yaml
    tlt ars-state resolve runs/ars_x_request.json --ars ars_x --mission missions/two_bay.yaml --set
    tlt ars-state clear   runs/ars_x_request.json --ars ars_x --mission missions/two_bay.yaml

``resolve --set``: the member is set (riveted, or the frame stands where it belongs); the request
sent again lets go of it and retreats. ``resolve --not-set``: it is not; the request sent again runs
afresh, a part still held discarded first. ``clear``: the gripper and the gun were emptied by hand;
the ARS starts knowing nothing of them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tlt_ars.request_data import RequestData, RequestFile, RequestFileError
from tlt_common import ros_names
from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission


def describe(data: RequestData) -> list[str]:
    """What the file says, and what the ARS does with it, one line each."""
    request = data.request
    lines = [f"request: {request.request} of '{request.member_id}'"]
    if data.recorded:
        lines.append(f"member {data.recorded}: sent again, the request lets go of it and retreats")
    elif data.setting:
        q = ", ".join(f"{v:.3f}" for v in data.setting_q or ())
        lines.append(
            f"in doubt: the step that sets the member {data.setting} began and was never recorded; sent"
            f" again, the request does it again if the arm still stands at [{q}] rad"
            " (else: tlt ars-state resolve --set or --not-set)"
        )
    if data.holding:
        lines.append(f"holding: a {data.holding} from '{data.dispenser}'")
    if data.rivet_in_gun:
        lines.append("rivet in the gun (seen loaded, not fired since)")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="tlt ars-state", description="Read an ARS's state file; settle a step left in doubt by hand."
    )
    parser.add_argument("action", choices=("show", "resolve", "clear"))
    parser.add_argument("file", type=Path, help="the ARS's state file (its launch set's --state-file)")
    parser.add_argument("--ars", choices=ros_names.ARS_AGENTS, required=True)
    parser.add_argument("--mission", type=Path, required=True, help="the mission file the ARS runs")
    settled = parser.add_mutually_exclusive_group()
    settled.add_argument(
        "--set",
        dest="is_set",
        action="store_true",
        default=None,
        help="resolve: the member is set (riveted, the frame in place)",
    )
    settled.add_argument(
        "--not-set", dest="is_set", action="store_false", help="resolve: the member is not set"
    )
    args = parser.parse_args(argv)
    try:
        file = RequestFile(args.file, load_mission(args.mission), args.ars)
        data = file.load()
    except (ConfigError, RequestFileError, OSError) as exc:
        print(f"tlt ars-state: {exc}", file=sys.stderr)
        return 2
    if data is None:
        print(f"{args.file}: no state file: the ARS holds nothing and starts afresh")
        return 0
    if args.action == "show":
        print("\n".join(describe(data)))
        return 0
    if args.action == "clear":
        file.clear()
        print(f"{args.file} removed: the ARS starts knowing nothing of the gripper and the gun")
        return 0
    if not data.setting:
        print(f"tlt ars-state: nothing in doubt in {args.file}", file=sys.stderr)
        return 2
    if args.is_set is None:
        print("tlt ars-state: resolve needs --set or --not-set", file=sys.stderr)
        return 2
    if args.is_set:
        data.recorded = data.setting
    data.setting, data.setting_q = "", None
    if data.worth_keeping():
        file.save(data)
    else:
        file.clear()
    print("\n".join(describe(data)) if data.worth_keeping() else f"{args.file} removed: nothing left")
    return 0


__all__ = ["describe", "main"]
