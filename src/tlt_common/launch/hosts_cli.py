"""``tlt hosts`` (or ``python -m tlt_common.launch.hosts_cli``): look at and act on the emulated
hosts of a running launch set from a shell (tlt_common.launch.hosts)."""

from __future__ import annotations

import argparse
import os
import sys

from tlt_common.launch.hosts import (
    HostsError,
    check_run_name,
    default_run_name,
    namespace_name,
    remove_run,
    run_namespaces,
    set_link,
    unavailable_reason,
)


def main(argv: list[str] | None = None) -> int:
    """``tlt hosts``: look at and act on the emulated hosts of a running launch set.

    ``check`` says whether this machine can create them; ``list`` prints a run's namespaces; ``cut``
    and ``heal`` pull and plug a host's cable; ``remove`` deletes what a run left. Exit 0 on
    success, 1 with the reason on stderr otherwise.
    """
    parser = argparse.ArgumentParser(prog="tlt hosts", description="Emulated hosts of a launch set.")
    parser.add_argument(
        "--run", default=None, help="run name (default: $TLT_HOSTS_RUN, else d<ROS_DOMAIN_ID>)"
    )
    sub = parser.add_subparsers(dest="action", required=True)
    sub.add_parser("check", help="can this machine create network namespaces?")
    sub.add_parser("list", help="the run's namespaces")
    for name, text in (("cut", "pull a host's cable"), ("heal", "plug a host's cable back")):
        sub.add_parser(name, help=text).add_argument("host")
    sub.add_parser("remove", help="delete every namespace of the run (what a crashed run left)")
    args = parser.parse_args(argv)
    run = args.run or default_run_name(os.environ)
    try:
        if args.action == "check":
            reason = unavailable_reason()
            print(f"no: {reason}" if reason else "yes: network namespaces can be created here")
            return 1 if reason else 0
        check_run_name(run)
        if args.action == "list":
            for name in run_namespaces(run):
                print(name)
        elif args.action in ("cut", "heal"):
            present = run_namespaces(run)
            if namespace_name(run, args.host) not in present:
                raise HostsError(
                    f"no host {args.host!r} in run {run!r} (namespaces: {', '.join(present) or 'none'})"
                )
            set_link(run, args.host, args.action == "heal")
            print(f"{args.host}: link {'up' if args.action == 'heal' else 'down'}")
        else:
            removed = remove_run(run)
            print(f"removed {', '.join(removed)}" if removed else f"nothing of run {run!r} to remove")
    except HostsError as exc:
        print(f"tlt hosts: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
