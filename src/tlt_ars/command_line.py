"""The ARS process's command line: its options and the ARS file they override, validated
(``tlt-ars``, ``python -m tlt_ars.node``; :func:`tlt_ars.node.main` runs the node with them).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from tlt_ars.config import ArsConfig, ars_config_from_dict, default_config_path
from tlt_common import ros_names
from tlt_common.config_schema import ConfigError, load_yaml


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="ars", description="Assistant Robot System: action servers and behaviour tree of one arm"
    )
    p.add_argument("--ars", choices=ros_names.ARS_AGENTS, required=True, help="which ARS this process is")
    p.add_argument("--config", type=Path, help="ARS file (default config/ars/<ars>.yaml)")
    p.add_argument("--mission", type=Path, help="mission file (overrides the ARS file; the same as the CRS)")
    p.add_argument(
        "--state-file",
        type=Path,
        help="where a held part, a rivet and a request that set its member are kept for a restart"
        " (overrides the ARS file)",
    )
    p.add_argument(
        "--velocity-scale",
        type=_optional_float,
        metavar="FRACTION",
        help="the arm's speed as a fraction of its limits (overrides arm.velocity_scale; empty: the"
        " ARS file's)",
    )
    p.add_argument("--no-reach-check", action="store_true", help="skip the start-up reachability check")
    return p


def _optional_float(text: str) -> float | None:
    # A launch set passes an unset variable as an empty argument: the ARS file's value then.
    return float(text) if text.strip() else None


def config_from_args(args: argparse.Namespace) -> ArsConfig:
    """The ARS file with the command line's overrides, validated; :class:`ConfigError` names the
    file (and the option), the key and the reason."""
    path = args.config or default_config_path(args.ars)
    overrides: dict[str, Any] = {
        key: str(value.resolve())
        for key, value in (("mission", args.mission), ("state_file", args.state_file))
        if value is not None
    }
    raw = load_yaml(path)
    source = str(path)
    if args.velocity_scale is not None:
        arm = raw.get("arm")
        overrides["arm"] = {**(arm if isinstance(arm, dict) else {}), "velocity_scale": args.velocity_scale}
        source += f" with --velocity-scale {args.velocity_scale:g}"
    config = ars_config_from_dict({**raw, **overrides}, source)
    if config.ars != args.ars:
        raise ConfigError(path, "ars", f"file is for '{config.ars}', not '{args.ars}'")
    return config


__all__ = ["build_parser", "config_from_args"]
