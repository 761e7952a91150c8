"""``tlt mission-check``: a mission the EDU cannot build is refused before anything starts.

    tlt mission-check missions/*.yaml [--model STATE.json] [--no-reach-check]

For each file, the file's own checks (:func:`tlt_common.mission.check.check_file`: schema,
geometry, a tower model state file with ``--model``), then, for each ARS with its ARS file
(``config/ars/<ars>.yaml``, what the launch sets start it with), what that ARS checks at start-up
(:mod:`tlt_ars.mission_checks`): a coarse pose for every dispenser it uses, moved to this
mission's racks, and every place and rivet step of its arm within reach (``--no-reach-check``, as
the ARS's own option, leaves that out). An unreachable step is printed as ``UNREACHABLE file:
member: ars cannot step: reason``. Exit status 0 when everything passes, 1 otherwise.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TextIO

from tlt_ars.config import ArsConfig, ars_config_from_dict, default_config_path
from tlt_ars.mission_checks import check_reach, prepare_for_mission
from tlt_ars.planning.world import SceneConfig, load_scene_config
from tlt_common import ros_names
from tlt_common.config_schema import ConfigError, load_yaml
from tlt_common.mission.check import build_parser, check_file, parse_args


def ars_config_for(ars: str, mission_path: Path) -> ArsConfig:
    """The ARS's shipped file with its mission replaced by ``mission_path``, as ``tlt-ars
    --ars ARS --mission PATH`` reads it; :class:`ConfigError` names the file, key and reason."""
    path = default_config_path(ars)
    return ars_config_from_dict({**load_yaml(path), "mission": str(mission_path.resolve())}, str(path))


def check_ars(
    ars: str, path: Path, mission: object, scenes: dict[Path, SceneConfig], *, reach: bool, out: TextIO
) -> bool:
    """One ARS's start-up checks of the mission in ``path``, each finding printed; whether it passes.
    ``scenes`` keeps the planning scenes loaded so far, by file."""
    try:
        config = ars_config_for(ars, path)
        if config.scene_path not in scenes:
            scenes[config.scene_path] = load_scene_config(config.scene_path)
        scene = scenes[config.scene_path]
        config = prepare_for_mission(config, mission, scene)
    except ConfigError as exc:
        print(f"INVALID {path}: {ars}: {exc}", file=out, flush=True)
        return False
    if not reach:
        print(f"ok {path}: {ars}: a coarse pose for every dispenser it uses", file=out, flush=True)
        return True
    print(f"... {path}: {ars}: checking the reach of every step of its arm", file=out, flush=True)
    began = time.monotonic()
    report = check_reach(config, mission, scene)
    took = time.monotonic() - began
    for issue in report.issues:
        print(f"UNREACHABLE {path}: {issue}", file=out, flush=True)
    if report.ok:
        print(
            f"ok {path}: {ars}: {len(report.reached)} step(s) within reach ({took:.1f} s)",
            file=out,
            flush=True,
        )
    else:
        print(
            f"FAIL {path}: {ars}: {len(report.issues)} unreachable step(s),"
            f" {len(report.reached)} within reach: the ARS would refuse this mission at start-up",
            file=out,
            flush=True,
        )
    return report.ok


def main(argv: list[str] | None = None, out: TextIO | None = None) -> int:
    out = out or sys.stdout
    parser = build_parser(
        "tlt mission-check", "Validate mission files and check that each ARS can build them (reach included)."
    )
    parser.add_argument(
        "--no-reach-check", action="store_true", help="leave out the ARSs' reach check (the ARS's own option)"
    )
    args = parse_args(parser, argv)
    scenes: dict[Path, SceneConfig] = {}
    failed = False
    for path in args.missions:
        mission = check_file(path, args.model, out)
        if mission is None:
            failed = True
            continue
        for ars in ros_names.ARS_AGENTS:
            if not check_ars(ars, path, mission, scenes, reach=not args.no_reach_check, out=out):
                failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
