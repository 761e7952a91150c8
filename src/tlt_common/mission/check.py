"""Check mission files (and optionally a persisted tower model) from the command line.

    python -m tlt_common.mission.check missions/*.yaml
    python -m tlt_common.mission.check missions/one_bay.yaml --model runs/crs/tower_model.json

Prints one line per file: a summary when it is valid, the file, key and reason when it is not.
Exit status 0 when every file is valid, 1 otherwise. These are the file's own checks; ``tlt
mission-check`` (``tlt_ars.mission_check_cli``) runs them and then what each ARS checks of a
mission at start-up, its reach included.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path
from typing import TextIO

from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import Mission, load_mission
from tlt_common.mission.tower_model import STATE_NAMES, TowerModel, TowerModelError


def check_file(path: Path, model: Path | None = None, out: TextIO | None = None) -> Mission | None:
    """Check one mission file (and, with ``model``, a tower model state file against it), print
    one line for each to ``out`` (stdout by default); the mission when both are valid, else None."""
    out = out or sys.stdout
    try:
        mission = load_mission(path)
    except ConfigError as exc:
        print(f"INVALID {exc}", file=out, flush=True)
        return None
    kinds = Counter(m.kind for m in mission.members)
    print(
        f"ok {path}: mission '{mission.name}', {mission.bay_count} bay(s), {len(mission.members)} members"
        f" ({', '.join(f'{n} {k}' for k, n in kinds.items())}), {len(mission.dispensers)} dispensers,"
        f" hash {mission.hash[:12]}",
        file=out,
        flush=True,
    )
    if model is None:
        return mission
    try:
        tower = TowerModel.load(mission, model)
    except TowerModelError as exc:
        print(f"INVALID {exc}", file=out, flush=True)
        return None
    states = Counter(STATE_NAMES[s] for s in tower.states.values())
    print(
        f"ok {model}: revision {tower.revision}, {tower.bays_built()} bay(s) built,"
        f" {', '.join(f'{n} {s}' for s, n in sorted(states.items()))}",
        file=out,
        flush=True,
    )
    return mission


def build_parser(
    prog: str = "tlt-mission-check", description: str = "Validate TLT mission files."
) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("missions", nargs="+", type=Path, help="mission YAML files")
    parser.add_argument(
        "--model", type=Path, help="tower model state file to check against the (single) mission"
    )
    return parser


def parse_args(parser: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    args = parser.parse_args(argv)
    if args.model is not None and len(args.missions) != 1:
        parser.error("--model needs exactly one mission file")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(build_parser(), argv)
    failed = [check_file(path, args.model) is None for path in args.missions]
    return 1 if any(failed) else 0


if __name__ == "__main__":
    sys.exit(main())
