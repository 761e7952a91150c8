"""``tlt twin``: the digital twin's commands."""

from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "run": ("tlt_sim.twin.main", "run the twin as a ROS process behind the drivers' links"),
    "render": ("tlt_sim.model.render_png", "render the EDU scene to a PNG"),
    "urdf": ("tlt_sim.model.urdf", "write the EDU's URDF (robot description), read off the twin model"),
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in COMMANDS:
        print("usage: tlt twin <command> [args...]\n\ncommands:")
        for name, (_, text) in COMMANDS.items():
            print(f"  {name:<10} {text}")
        return 0 if argv[:1] in (["-h"], ["--help"]) else 2
    return int(importlib.import_module(COMMANDS[argv[0]][0]).main(argv[1:]) or 0)
