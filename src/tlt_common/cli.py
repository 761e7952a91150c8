"""The ``tlt`` command: one entry point for operators and engineers.

Subcommands live with the code they drive and are imported only when called, so ``tlt launch``
does not pay for loading the vision models. Each is ``module:function`` taking ``argv`` and
returning an exit code.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from tlt_common.config_schema import ConfigError

# name -> (module:function, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "launch": ("tlt_common.cli:launch_main", "start the processes of a launch set"),
    "check": ("tlt_common.cli:check_main", "validate launch sets without starting anything"),
    "interfaces": ("tlt_common.interfaces_cli:main", "list the tlt_interfaces messages, services, actions"),
    "gsw": (
        "tlt_gsw.cli:main",
        "ground station: gui, mission, summary, send, watch, query, export, keygen, levers,"
        " correct-member, correct-dispenser",
    ),
    "twin": ("tlt_sim.cli:main", "the digital twin: run it behind the drivers' links, render a PNG"),
    "hosts": ("tlt_common.launch.hosts_cli:main", "emulated hosts: check, list, cut, heal, remove"),
    "mission-check": (
        "tlt_ars.mission_check_cli:main",
        "validate mission files; check that each ARS can build them, reach included",
    ),
    "ars-state": ("tlt_ars.state_cli:main", "an ARS's state file: show, resolve a step in doubt, clear"),
    "mission-generate": ("tlt_common.mission.generate:main", "write a mission file for N bays"),
    "record": ("tlt_common.recording.record_command:main", "a recording (MCAP): info, play, export to CSV"),
}


def launch_main(argv: list[str]) -> int:
    from tlt_common.launch import Supervisor, load_launch_set
    from tlt_common.launch.supervisor import default_log_dir

    parser = argparse.ArgumentParser(prog="tlt launch", description="Start the processes of a launch set.")
    parser.add_argument("launch_set", help="launch set YAML, e.g. config/launch/hardware_emulated.yaml")
    parser.add_argument(
        "--isolated",
        action="store_true",
        help="claim a ROS domain no other run here holds; localhost discovery only",
    )
    parser.add_argument(
        "--log-dir",
        help="folder of the processes' log files, <name>.log (default: $TLT_RUN_DIR/logs, "
        "TLT_RUN_DIR defaulting to /tmp/tlt-run)",
    )
    parser.add_argument("--no-log-files", action="store_true", help="the console only, no log files")
    args = parser.parse_args(argv)
    if os.environ.get("TLT_LOG_LEVEL", "").strip():  # refused before anything starts, not by each process
        from tlt_common.ros.rosout_logging import LogLevelError, env_log_level

        try:
            env_log_level()
        except LogLevelError as exc:
            print(f"tlt launch: {exc}", file=sys.stderr)
            return 2
    if args.isolated:
        from tlt_common.ros.isolation import isolate

        print(f"[launch] isolated: ROS_DOMAIN_ID={isolate(os.environ)}, localhost discovery", flush=True)
    try:
        launch_set = load_launch_set(args.launch_set)
    except ConfigError as exc:
        print(f"tlt launch: {exc}", file=sys.stderr)
        return 2
    log_dir = None if args.no_log_files else (args.log_dir or default_log_dir(os.environ))
    return Supervisor(launch_set, log_dir=log_dir).run()


def check_main(argv: list[str]) -> int:
    from tlt_common.launch import load_launch_set

    parser = argparse.ArgumentParser(prog="tlt check", description="Validate launch sets.")
    parser.add_argument("launch_sets", nargs="+")
    args = parser.parse_args(argv)
    status = 0
    for path in args.launch_sets:
        try:
            launch_set = load_launch_set(path)
        except ConfigError as exc:
            print(f"FAIL {exc}")
            status = 1
            continue
        print(f"ok   {path}: {', '.join(p.name for p in launch_set.processes)}")
    return status


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: tlt <command> [args...]\n\ncommands:")
        for name, (_, text) in SUBCOMMANDS.items():
            print(f"  {name:<12} {text}")
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in SUBCOMMANDS:
        print(f"tlt: unknown command {name!r} (try: {', '.join(SUBCOMMANDS)})", file=sys.stderr)
        return 2
    module_name, func_name = SUBCOMMANDS[name][0].split(":")
    func = getattr(importlib.import_module(module_name), func_name)
    return int(func(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
