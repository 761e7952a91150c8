"""``tlt-drivers``: the driver nodes of one computer in one process (docs/deployment.md).

Each ``--driver KIND`` opens a driver and is followed by that driver's own arguments, exactly those
of its one-driver executable (``tlt-<KIND>``)::

    tlt-drivers --driver lifter --port /tmp/tlt-run/lifter --answer-timeout-s 1.0 \\
                --driver top-grippers --port /tmp/tlt-run/top_grippers \\
                --ros-args -p use_sim_time:=true

The ROS arguments apply to every node. Every driver's arguments are checked before any node
starts; a bad one is named and the process exits with code 2. The nodes share the process's DDS
participant but each spins on a thread of its own (:mod:`tlt_drivers.node_main`), so a
device that stops answering holds only its own driver's loop.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from tlt_drivers.lifter import node as lifter
from tlt_drivers.node_main import Driver, DriverStartError, run_drivers
from tlt_drivers.nodes import active_grippers, camera_mounts, ee, top_grippers
from tlt_drivers.ur import node as ur

PROG = "tlt-drivers"

#: ``--driver`` kinds, named as their one-driver executables without ``tlt-``.
KINDS: dict[str, Callable[[list[str]], Driver]] = {
    "lifter": lifter.driver,
    "top-grippers": top_grippers.driver,
    "active-grippers": active_grippers.driver,
    "camera-mounts": camera_mounts.driver,
    "ee-x": ee.driver_x,
    "ee-y": ee.driver_y,
    "ur": ur.driver,
}


def parse_drivers(args: Sequence[str]) -> list[Driver]:
    """The drivers ``args`` asks for (ROS arguments already removed); raises :class:`DriverStartError`."""
    if not args or args[0] != "--driver":
        raise DriverStartError(f"arguments must start with --driver KIND (KIND one of {', '.join(KINDS)})")
    segments: list[list[str]] = []
    for arg in args:
        if arg == "--driver":
            segments.append([])
        else:
            segments[-1].append(arg)
    drivers: list[Driver] = []
    for i, segment in enumerate(segments):
        if not segment or segment[0] not in KINDS:
            kind = segment[0] if segment else "nothing"
            raise DriverStartError(f"--driver #{i + 1}: {kind!r} is not a driver (one of {', '.join(KINDS)})")
        try:
            driver = KINDS[segment[0]](segment[1:])
        except DriverStartError as exc:
            raise DriverStartError(f"--driver {segment[0]} (#{i + 1}): {exc}") from exc
        except SystemExit as exc:  # argparse has printed the driver's usage and what was wrong
            raise DriverStartError(f"--driver {segment[0]} (#{i + 1}): bad arguments") from exc
        drivers.append(driver)
    names = [d.name for d in drivers]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise DriverStartError(f"two drivers would be node {', '.join(twice)}: give each its own --config")
    return drivers


def main(argv: list[str] | None = None) -> int:
    """Run the drivers ``argv`` names until interrupted. Returns the process exit status."""
    return run_drivers(PROG, parse_drivers, argv)


if __name__ == "__main__":
    raise SystemExit(main())
