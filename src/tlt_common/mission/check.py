"""Check mission files (and optionally a persisted tower model) from the command line.

    python -m tlt_common.mission.check missions/*.yaml
    python -m tlt_common.mission.check missions/one_bay.yaml --model runs/crs/tower_model.json

Prints one line per file: a summary when it is valid, the file, key and reason when it is not.
Exit status 0 when every file is valid, 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import STATE_NAMES, TowerModel, TowerModelError


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tlt-mission-check", description="Validate TLT mission files.")
    parser.add_argument("missions", nargs="+", type=Path, help="mission YAML files")
    parser.add_argument(
        "--model", type=Path, help="tower model state file to check against the (single) mission"
    )
    args = parser.parse_args(argv)
    if args.model is not None and len(args.missions) != 1:
        parser.error("--model needs exactly one mission file")
    failed = False
    for path in args.missions:
        try:
            mission = load_mission(path)
        except ConfigError as exc:
            print(f"INVALID {exc}")
            failed = True
            continue
        kinds = Counter(m.kind for m in mission.members)
        print(
            f"ok {path}: mission '{mission.name}', {mission.bay_count} bay(s), {len(mission.members)} members"
            f" ({', '.join(f'{n} {k}' for k, n in kinds.items())}), {len(mission.dispensers)} dispensers,"
            f" hash {mission.hash[:12]}"
        )
        if args.model is not None:
            try:
                model = TowerModel.load(mission, args.model)
            except TowerModelError as exc:
                print(f"INVALID {exc}")
                failed = True
                continue
            states = Counter(STATE_NAMES[s] for s in model.states.values())
            print(
                f"ok {args.model}: revision {model.revision}, {model.bays_built()} bay(s) built,"
                f" {', '.join(f'{n} {s}' for s, n in sorted(states.items()))}"
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
