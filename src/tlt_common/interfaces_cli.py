"""``tlt interfaces``: list or show the system's ROS interfaces (there is no ``ros2 interface`` here)."""

from __future__ import annotations

import argparse

from tlt_common.interfaces import describe, iter_interfaces, message_parts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tlt interfaces", description=__doc__)
    parser.add_argument("name", nargs="?", help="show one interface's fields, e.g. LifterState or AddMember")
    args = parser.parse_args(argv)
    found = False
    for kind, name, cls in iter_interfaces():
        if args.name is None:
            print(f"tlt_interfaces/{kind}/{name}")
            continue
        if name != args.name:
            continue
        found = True
        print(f"tlt_interfaces/{kind}/{name}")
        for part, part_cls in message_parts(kind, cls).items():
            if kind != "msg":
                print(f"  {part}:")
            for line in describe(part_cls):
                print(f"    {line}" if kind != "msg" else f"  {line}")
    if args.name is not None and not found:
        print(f"tlt interfaces: no interface named {args.name!r}")
        return 1
    return 0
