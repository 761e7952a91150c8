"""Candidate Mask R-CNN weights against the shipped ones, on every held-out set the card names.

The card (models/vision/README.md) asks, before new weights ship, for ``bench/vision.py`` on the
five held-out seeds and ``bench/inspection.py --segmentation mask_rcnn`` at seeds 1100 and 1200.
This runs all of them for each weights file, side by side in ``--jobs`` processes (a GPU
machine's 16 cores finish them in a few minutes; this is CPU work), and prints one table: per
seed, each weights file's mask AP50 as the node segments and certified share of the views that
show enough of a part, their poses within the ADD-S goal, and the inspection figures; then the
goals met and, seed by seed, how the candidate compares with the weights it would replace.

Each held-out set is rendered once into ``--work`` (40 images a seed, as the card's) and reused.
Frame times are left out: processes side by side slow each other, and the frame's figure is
measured by ``bench/vision.py`` alone. Every figure of every run is also in
``--work``/``<weights>_<seed>.json``, and the table's in ``--work/summary.json``.

    .venv/bin/python bench/vision_candidate.py --weights CANDIDATE.pt
        [--against models/vision/mask_rcnn.pt] [--seeds 900 901 950 1300 1301]
        [--inspection-seeds 1100 1200] [--rounds 6] [--jobs 2] [--work /tmp/tlt_vision_candidate]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "models/vision/mask_rcnn.pt"
HELD_OUT = (900, 901, 950, 1300, 1301)
INSPECTION = (1100, 1200)
IMAGES = 40
GOALS = {"ap50": 0.90, "certified": 0.95, "shown": 0.95, "add_s_ok": 0.95, "caught": 0.99, "rejected": 0.02}


@dataclass(frozen=True)
class Job:
    """One benchmark run: its label in the progress lines, its command, the JSON it writes, its log."""

    label: str
    command: list[str]
    figures: Path
    log: Path


def vision_figures(figures: dict[str, Any]) -> dict[str, float | None]:
    """The table's figures of one ``bench/vision.py --json`` file: mask AP50 as the node segments,
    the share certified of the views non-degenerate at the true pose, the same of the views the
    twin's mask shows enough of (``shown``: segmentation's losses counted; None from a file written
    by a bench/vision.py that did not count them), the share of the certified within the ADD-S
    goal (None where there is nothing to divide)."""
    poses = figures["poses"]
    shown = poses.get("views_shown", 0)
    return {
        "ap50": figures["mask_ap50_node"]["mean"],
        "certified": poses["views_certified"] / poses["views"] if poses["views"] else None,
        "shown": poses["views_shown_certified"] / shown if shown else None,
        "add_s_ok": poses["add_s_ok"] / poses["certified"] if poses["certified"] else None,
        "views": poses["views"],
        "views_shown": shown,
    }


def goals_met(row: dict[str, float | None]) -> dict[str, bool]:
    """For each goal a row has a figure for, whether the figure meets it."""
    met = {}
    for key, goal in GOALS.items():
        value = row.get(key)
        if value is not None:
            met[key] = value <= goal if key == "rejected" else value >= goal
    return met


def compare(candidate: dict[str, float | None], against: dict[str, float | None]) -> dict[str, float]:
    """Candidate minus the weights it would replace, figure by figure (rejected: lower is better,
    so its difference is negated: a positive difference is always a gain)."""
    out = {}
    for key in GOALS:
        a, b = candidate.get(key), against.get(key)
        if a is not None and b is not None:
            out[key] = (b - a) if key == "rejected" else (a - b)
    return out


LABELS = {
    "ap50": "mask AP50",
    "certified": "certified",
    "shown": "certified*",
    "add_s_ok": "ADD-S ok",
    "caught": "caught",
    "rejected": "good rejected",
}


def _fmt(value: float | None, key: str) -> str:
    if value is None:
        return "-"
    text = f"{value:.3f}" if key == "ap50" else f"{value * 100:.1f} %"
    return text + (" ok" if goals_met({key: value})[key] else " --")


def table(rows: dict[str, dict[str, dict[str, float | None]]], names: list[str], keys: list[str]) -> str:
    """``rows[set][weights name]``'s ``keys`` as a text table, a column per weights under each
    figure, each cell marked "ok" where its goal is met; with two weights, a line per set of how
    the first compares with the second."""
    width = 13
    head = f"{'':20s}" + "".join(f"{LABELS[k]:>{width * len(names)}s}" for k in keys)
    sub = f"{'':20s}" + "".join(f"{n[: width - 1]:>{width}s}" for _ in keys for n in names)
    lines = [head, sub]
    for name_of_set, by_weights in rows.items():
        cells = "".join(f"{_fmt(by_weights.get(n, {}).get(k), k):>{width}s}" for k in keys for n in names)
        lines.append(f"{name_of_set:20s}{cells}")
    if len(names) == 2:
        lines.append(f"{names[0]} against {names[1]} (positive: better)")
        for name_of_set, by_weights in rows.items():
            diff = compare(by_weights.get(names[0], {}), by_weights.get(names[1], {}))
            text = ", ".join(
                f"{LABELS[k]} {v:+.3f}" if k == "ap50" else f"{LABELS[k]} {v * 100:+.1f} points"
                for k, v in diff.items()
                if k in keys
            )
            lines.append(f"  {name_of_set:20s}{text}")
    return "\n".join(lines)


def pooled(rows: dict[str, dict[str, float | None]], names: list[str]) -> dict[str, dict[str, float | None]]:
    """Over the held-out sets, for each weights: the mean mask AP50, and the shares certified of all
    their views by either count (each set weighted by its views, as one larger set would be)."""
    out = {}
    for n in names:
        sets = [by_weights[n] for by_weights in rows.values() if n in by_weights]
        out[n] = {"ap50": sum(r["ap50"] for r in sets) / len(sets) if sets else None}
        for key, views_key in (("certified", "views"), ("shown", "views_shown")):
            views = sum(r.get(views_key, 0) for r in sets if r.get(key) is not None)
            out[n][key] = (
                sum(r[key] * r[views_key] for r in sets if r.get(key) is not None) / views if views else None
            )
    return out


def _run(job: Job) -> tuple[Job, int, float]:
    started = time.monotonic()
    job.figures.unlink(missing_ok=True)  # a figure left from an earlier run is not this run's
    with job.log.open("w") as log:
        rc = subprocess.run(job.command, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, check=False)
    return job, rc.returncode, time.monotonic() - started


def run_all(jobs: list[Job], parallel: int) -> list[Job]:
    """Run ``jobs`` ``parallel`` at a time, a line as each ends; the jobs that failed."""
    failed = []
    with ThreadPoolExecutor(max_workers=parallel) as pool:
        for done, (job, rc, seconds) in enumerate(pool.map(_run, jobs), start=1):
            state = "done" if rc == 0 and job.figures.exists() else f"FAILED (exit {rc}, log {job.log})"
            print(f"  [{done}/{len(jobs)}] {job.label}: {state} in {seconds:.0f} s", flush=True)
            if state != "done":
                failed.append(job)
    return failed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--weights", type=Path, required=True, help="the candidate Mask R-CNN weights")
    p.add_argument("--against", type=Path, default=SHIPPED, help="the weights it would replace")
    p.add_argument("--seeds", type=int, nargs="+", default=list(HELD_OUT), help="held-out render seeds")
    p.add_argument("--inspection-seeds", type=int, nargs="*", default=list(INSPECTION))
    p.add_argument("--rounds", type=int, default=6, help="bench/inspection.py's rounds")
    p.add_argument("--count", type=int, default=IMAGES, help="images a held-out set")
    p.add_argument("--jobs", type=int, default=2, help="benchmarks run side by side, one thread each")
    p.add_argument("--work", type=Path, default=Path("/tmp/tlt_vision_candidate"))
    args = p.parse_args(argv)
    weights = {"candidate": args.weights, "current": args.against}
    for name, path in weights.items():
        if not path.is_file():
            p.error(f"--{'weights' if name == 'candidate' else 'against'} {path}: no such file")
    if args.jobs < 1:
        p.error(f"--jobs {args.jobs}: at least one")
    args.work.mkdir(parents=True, exist_ok=True)
    python = sys.executable

    renders = []
    for seed in args.seeds:
        images = args.work / f"held_out_{seed}_{args.count}"
        if not (images / "index.json").exists():
            renders.append(
                Job(
                    f"render held-out seed {seed}",
                    [
                        python,
                        "-m",
                        "tlt_tools.vision_training.render_dataset",
                        "--out",
                        str(images),
                        "--count",
                        str(args.count),
                        "--seed",
                        str(seed),
                    ],
                    images / "index.json",
                    args.work / f"render_{seed}.log",
                )
            )
    print(f"rendering {len(renders)} held-out sets into {args.work} ...", flush=True)
    if run_all(renders, args.jobs):
        return 1

    jobs = []
    for name, path in weights.items():
        for seed in args.seeds:
            out = args.work / f"{name}_{seed}.json"
            jobs.append(
                Job(
                    f"bench/vision.py {name} seed {seed}",
                    [
                        python,
                        "bench/vision.py",
                        "--weights",
                        str(path),
                        "--threads",
                        "1",
                        "--json",
                        str(out),
                        "--images",
                        str(args.work / f"held_out_{seed}_{args.count}"),
                    ],
                    out,
                    args.work / f"{name}_{seed}.log",
                )
            )
        for seed in args.inspection_seeds:
            out = args.work / f"{name}_inspection_{seed}.json"
            jobs.append(
                Job(
                    f"bench/inspection.py {name} seed {seed}",
                    [
                        python,
                        "bench/inspection.py",
                        "--segmentation",
                        "mask_rcnn",
                        "--weights",
                        str(path),
                        "--rounds",
                        str(args.rounds),
                        "--seed",
                        str(seed),
                        "--threads",
                        "1",
                        "--json",
                        str(out),
                    ],
                    out,
                    args.work / f"{name}_inspection_{seed}.log",
                )
            )
    print(f"running {len(jobs)} benchmarks, {args.jobs} at a time ...", flush=True)
    failed = run_all(jobs, args.jobs)

    vision: dict[str, dict[str, dict[str, float | None]]] = {}
    inspection: dict[str, dict[str, dict[str, float | None]]] = {}
    names = list(weights)
    for name in names:
        for seed in args.seeds:
            path = args.work / f"{name}_{seed}.json"
            if path.exists():
                vision.setdefault(f"seed {seed}", {})[name] = vision_figures(json.loads(path.read_text()))
        for seed in args.inspection_seeds:
            path = args.work / f"{name}_inspection_{seed}.json"
            if path.exists():
                figures = json.loads(path.read_text())
                inspection.setdefault(f"seed {seed}", {})[name] = {
                    "caught": figures["caught"],
                    "rejected": figures["rejected"],
                }
    if vision:
        vision["all (mean, pooled)"] = pooled(vision, names)
    print(f"\ncandidate {args.weights}, current {args.against} ('ok': the goal met)")
    print(
        f"\nheld-out sets ({args.count} images each; certified: of the views whose cloud shows enough of "
        "a part; certified*: of those the twin's mask of the part does, segmentation's losses counted)"
    )
    print(table(vision, names, ["ap50", "certified", "shown", "add_s_ok"]))
    if inspection:
        print(
            f"\ninspection (the two-bay mission's struts presented {args.rounds} times, on Mask R-CNN's "
            "masks)"
        )
        print(table(inspection, names, ["caught", "rejected"]))
    rows = {"vision": vision, "inspection": inspection}
    (args.work / "summary.json").write_text(
        json.dumps(
            {"weights": {n: str(p) for n, p in weights.items()}, "goals": GOALS, "rows": rows}, indent=1
        )
        + "\n"
    )
    print(f"\nfigures of every run in {args.work}; frame times are bench/vision.py's, run alone")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
