"""Write a mission file for an N-bay square tower, every member listed explicitly.

The files in ``missions/`` were made with this (``python -m tlt_common.mission.generate``) and
can be edited by hand afterwards; the loader checks whatever is in the file, not this generator.

Layout (docs/missions.md): tower frame at corner x0_y0 of the top (payload) cross frame, x and y
along its sides, z up. Joint ``bay<n>/x<i>_y<j>`` is corner (i, j) of the cross frame at the
bottom of bay n (z = -n * bay_height); ``bay0`` is the payload's frame. ARS X works near corner
x0_y0 (faces x0 and y0), ARS Y near corner x1_y1 (faces x1 and y1). The far corners x0_y1 and
x1_y0 are at the edge of both arms' reach, so ARS X adds each far vertical (setting its top
rivet) and ARS Y affixes it (the bottom rivet), as §V.C.2 describes Fig. 23.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import yaml

CORNERS = ("x0_y0", "x0_y1", "x1_y0", "x1_y1")
# Face diagonals: (position, adding ARS, lower joint corner, upper joint corner).
DIAGONALS = (
    ("face_x0", "ars_x", "x0_y0", "x0_y1"),
    ("face_y0", "ars_x", "x1_y0", "x0_y0"),
    ("face_x1", "ars_y", "x1_y1", "x1_y0"),
    ("face_y1", "ars_y", "x0_y1", "x1_y1"),
)
FAR = (("x0_y1", "ars_x", "ars_y"), ("x1_y0", "ars_x", "ars_y"))
NEAR = (("x0_y0", "ars_x"), ("x1_y1", "ars_y"))
FOUNDATION = (("x0_y0", "ars_x"), ("x0_y1", "ars_x"), ("x1_y0", "ars_y"), ("x1_y1", "ars_y"))
SPARES = 2


def _corner_xy(corner: str, width: float) -> tuple[float, float]:
    return (width * int(corner[1]), width * int(corner[4]))


def build(
    name: str, bays: int, width: float = 0.75, height: float = 0.75, description: str = ""
) -> dict[str, Any]:
    """Mission data for ``bays`` square bays of ``width`` x ``width`` x ``height`` m."""
    side = lambda a: f"{a[-1]}"  # noqa: E731 - "ars_x" -> "x"
    joints = {}
    for level in range(bays + 1):
        for corner in CORNERS:
            x, y = _corner_xy(corner, width)
            joints[f"bay{level}/{corner}"] = [round(x, 6), round(y, 6), round(-level * height, 6)]

    def rivet(joint: str, ars: str, step: str) -> dict[str, Any]:
        return {"joint": joint, "ars": ars, "dispenser": f"rivet_dispenser_{side(ars)}", "step": step}

    bay_list = []
    for n in range(1, bays + 1):
        bottom, top = f"bay{n}", f"bay{n - 1}"
        cross = {
            "id": f"bay{n}/cross_frame",
            "position": "bottom",
            "add_ars": "ars_x",
            "dispenser": "cross_frame_dispenser",
            "joints": [f"{bottom}/{c}" for c in ("x0_y0", "x1_y0", "x1_y1", "x0_y1")],
        }
        far = [
            {
                "id": f"bay{n}/vertical/{c}",
                "position": c,
                "add_ars": adder,
                "affix_ars": affixer,
                "dispenser": f"vertical_dispenser_{side(adder)}",
                "joints": [f"{top}/{c}", f"{bottom}/{c}"],
                "rivets": [rivet(f"{top}/{c}", adder, "add"), rivet(f"{bottom}/{c}", affixer, "affix")],
            }
            for c, adder, affixer in FAR
        ]
        near = [
            {
                "id": f"bay{n}/vertical/{c}",
                "position": c,
                "add_ars": ars,
                "affix_ars": ars,
                "dispenser": f"vertical_dispenser_{side(ars)}",
                "joints": [f"{top}/{c}", f"{bottom}/{c}"],
                "rivets": [rivet(f"{top}/{c}", ars, "add"), rivet(f"{bottom}/{c}", ars, "affix")],
            }
            for c, ars in NEAR
        ]
        diagonals = [
            {
                "id": f"bay{n}/diagonal/{pos}",
                "position": pos,
                "add_ars": ars,
                "dispenser": f"diagonal_dispenser_{side(ars)}",
                "joints": [f"{bottom}/{low}", f"{top}/{high}"],
                "rivets": [rivet(f"{bottom}/{low}", ars, "add")],
            }
            for pos, ars, low, high in DIAGONALS
        ]
        bay_list.append(
            {
                "number": n,
                "cross_frame": cross,
                "far_verticals": far,
                "near_verticals": near,
                "diagonals": diagonals,
            }
        )
    foundation = [
        {
            "id": f"foundation/{c}",
            "position": c,
            "ars": ars,
            "joint": f"bay{bays}/{c}",
            "dispenser": f"rivet_dispenser_{side(ars)}",
        }
        for c, ars in FOUNDATION
    ]
    # Rivets per ARS and bay: 2 for its near vertical, 2 adds (X) or 2 affixes (Y) of the far verticals,
    # 2 for its diagonals; plus 2 foundation rivets.
    rivets_per_ars = bays * (2 + 2 + 2) + 2
    dispensers = [
        {"name": "cross_frame_dispenser", "part_kind": "cross_frame", "count": bays + SPARES,
         "pose": {"frame": "base", "position": [-0.9, 0.375, 0.0], "rpy": [0.0, 0.0, 0.0]}},
        {"name": "vertical_dispenser_x", "part_kind": "vertical", "count": 3 * bays + SPARES,
         "pose": {"frame": "base", "position": [-0.9, -0.6, 0.0], "rpy": [0.0, 0.0, 0.0]}},
        {"name": "vertical_dispenser_y", "part_kind": "vertical", "count": bays + SPARES,
         "pose": {"frame": "base", "position": [1.65, 1.35, 0.0], "rpy": [0.0, 0.0, math.pi]}},
        {"name": "diagonal_dispenser_x", "part_kind": "diagonal", "count": 2 * bays + SPARES,
         "pose": {"frame": "base", "position": [-0.6, -0.9, 0.0], "rpy": [0.0, 0.0, 0.0]}},
        {"name": "diagonal_dispenser_y", "part_kind": "diagonal", "count": 2 * bays + SPARES,
         "pose": {"frame": "base", "position": [1.35, 1.65, 0.0], "rpy": [0.0, 0.0, math.pi]}},
        {"name": "rivet_dispenser_x", "part_kind": "rivet", "count": rivets_per_ars + 4 * SPARES,
         "pose": {"frame": "base", "position": [-0.45, -0.45, 0.3], "rpy": [0.0, 0.0, 0.0]}},
        {"name": "rivet_dispenser_y", "part_kind": "rivet", "count": rivets_per_ars + 4 * SPARES,
         "pose": {"frame": "base", "position": [1.2, 1.2, 0.3], "rpy": [0.0, 0.0, math.pi]}},
    ]  # fmt: skip
    return {
        "format": 1,
        "name": name,
        "description": description or f"{bays}-bay square tower, {width} m bays, {height} m high",
        "bay_count": bays,
        "geometry": {
            "bay_width": width,
            "bay_height": height,
            "strut_lengths": {
                "cross_frame_side": width,
                "vertical": height,
                "diagonal": round(math.hypot(width, height), 6),
            },
            "length_tolerance": 0.002,
        },
        "inspection": {
            "position_tolerance": 0.005,
            "angle_tolerance": 0.035,
            "chamfer_thresholds": {
                "strut_tube": 0.010,
                "end_fitting": 0.005,
                "cross_frame": 0.015,
                "corner_joint": 0.006,
                "rivet": 0.003,
            },
        },
        "joints": joints,
        "dispensers": dispensers,
        "bays": bay_list,
        "foundation_rivets": foundation,
    }


class _Dumper(yaml.SafeDumper):
    """Short lists of scalars (points, joint ids) on one line, to keep the files readable."""


def _represent_list(dumper: yaml.SafeDumper, value: list[Any]) -> yaml.Node:
    flow = all(not isinstance(v, dict | list) for v in value)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--name", required=True)
    parser.add_argument("--bays", type=int, required=True)
    parser.add_argument("--width", type=float, default=0.75, help="bay width, m")
    parser.add_argument("--height", type=float, default=0.75, help="bay height, m")
    parser.add_argument("--output", "-o", type=Path, required=True)
    args = parser.parse_args(argv)
    if args.bays < 1:
        parser.error("--bays must be at least 1")
    data = build(args.name, args.bays, args.width, args.height)
    header = (
        f"# Mission '{args.name}': {args.bays} bay(s). Written by tlt_common.mission.generate; every member\n"
        "# is listed explicitly and checked on load by tlt_common.mission.schema (docs/missions.md).\n"
    )
    args.output.write_text(
        header + yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=120), encoding="utf-8"
    )
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
