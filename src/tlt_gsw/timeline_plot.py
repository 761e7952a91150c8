"""The mission timeline as a PNG: per bay and member, when each step of the CRS tree ran.

One row per member (or phase: Index Payload n, Test Bay n), grouped by bay, foundation rivets
last; the x axis is the CRS's ROS time (simulated time on the twin) from the first step that ran
(:func:`timeline_origin`).
Each step is a bar, coloured by what it does (sending a request, waiting for an ARS, inspecting,
moving the lifter, grippers or cameras, waiting for help). Faults are red bands from when they
were raised to when they were cleared (to the end of the run if they stand); a failed part
inspection is a red cross on its member's row. Drawn with matplotlib's Agg backend, so it needs no
display. Input: a :class:`~tlt_gsw.summary.MissionSummary`.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
from matplotlib.artist import Artist
from matplotlib.patches import Patch

from tlt_gsw.summary import MissionSummary, StepSpan

# (legend label, colour, words that put a step in it), checked in order.
CATEGORIES = (
    ("inspection", "#9467bd", ("Inspect", "Inspection", "Part", "Forward Result")),
    ("send request", "#1f77b4", ("Send ",)),
    (
        "wait for ARS",
        "#17becf",
        ("Wait For AddMember", "Wait For AffixMember", "Wait For AddCrossFrame", "Wait For FoundationRivet"),
    ),
    ("lifter", "#2ca02c", ("Lifter", "Raise", "Lower", "Compression", "CRS Control")),
    ("grippers / cameras", "#ff7f0e", ("Gripper", "Camera")),
    ("fault: waiting for help", "#d62728", ("Wait For Help",)),
)
OTHER = ("other", "#7f7f7f")
MIN_BAR_FRACTION = 0.002  # of the x range: a step shorter than this still shows


def category(step: str) -> tuple[str, str]:
    """(label, colour) of a step name."""
    for label, colour, words in CATEGORIES:
        if any(w in step for w in words):
            return label, colour
    return OTHER


def _rows(steps: list[StepSpan]) -> list[tuple[str, str]]:
    """(group, member) rows in the order they first ran, bays in order, foundation last."""
    seen: dict[tuple[str, str], None] = {}
    for span in steps:
        seen.setdefault((span.group, span.member or span.step), None)

    def order(row: tuple[str, str]) -> tuple[int, int]:
        group = row[0]
        return (1, 0) if not group.startswith("bay ") else (0, int(group.split()[1]))

    return sorted(seen, key=order)  # stable: within a group, first-run order


def timeline_origin(summary: MissionSummary) -> float:
    """The sim time the x axis starts at: the first step that ran. A CRS reports its mission step
    from the moment it is up, well before Start (which can be refused as "not ready" for the better
    part of a minute), and a run's first packet would leave that much empty axis."""
    ran = [s.sim_start for s in summary.steps if s.step]
    return min(ran) if ran else summary.sim_start or 0.0


def plot_timeline(summary: MissionSummary, path: str | Path, *, title: str | None = None) -> Path:
    """Draw ``summary``'s timeline to ``path`` (PNG); return the path."""
    path = Path(path)
    steps = [s for s in summary.steps if s.step]
    rows = _rows(steps)
    origin = timeline_origin(summary)
    end = (summary.sim_end or origin) - origin
    # A fault raised before the first step (a CRS that faults while it comes up) stays in view.
    first = min([0.0] + [f.raised_sim - origin for f in summary.faults if f.raised_sim is not None])
    height = max(3.0, 0.28 * len(rows) + 1.6)
    fig, ax = plt.subplots(figsize=(12, height), dpi=100)
    try:
        index = {row: i for i, row in enumerate(rows)}
        min_width = max(end, 1.0) * MIN_BAR_FRACTION
        used: dict[str, str] = {}
        for span in steps:
            y = index[(span.group, span.member or span.step)]
            label, colour = category(span.step)
            used[label] = colour
            start = span.sim_start - origin
            ax.broken_barh(
                [(start, max(span.sim_end - span.sim_start, min_width))], (y - 0.38, 0.76), color=colour
            )
        for fault in summary.faults:
            if fault.raised_sim is None:
                continue
            stop = fault.cleared_sim if fault.cleared_sim is not None else summary.sim_end or fault.raised_sim
            ax.axvspan(fault.raised_sim - origin, stop - origin, color="#d62728", alpha=0.15)
            ax.axvline(fault.raised_sim - origin, color="#d62728", linewidth=1.2)
        rows_by_member = {member: i for (group, member), i in index.items()}
        for inspection in summary.inspections:
            if inspection.passed or inspection.sim is None or inspection.target not in rows_by_member:
                continue
            ax.plot(inspection.sim - origin, rows_by_member[inspection.target], "x", color="#d62728",
                    markersize=9, markeredgewidth=2)  # fmt: skip
        ax.set_yticks(range(len(rows)))
        ax.set_yticklabels([f"{group}: {member}" for group, member in rows], fontsize=7)
        ax.invert_yaxis()
        ax.set_xlabel("sim time since the first step [s]")
        ax.set_xlim(first, max(end, 1e-3) * 1.02)
        ax.grid(axis="x", alpha=0.3)
        handles: list[Artist] = [Patch(color=c, label=label) for label, c in used.items()]
        if summary.faults:
            handles.append(Patch(color="#d62728", alpha=0.3, label="fault (raised to cleared)"))
        if any(not i.passed and not i.bay_inspection for i in summary.inspections):
            handles.append(
                plt.Line2D([], [], marker="x", linestyle="", color="#d62728", label="part failed inspection")
            )
        if handles:
            ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        built = "tower built" if summary.tower_built else f"not built ({summary.run_state})"
        ax.set_title(
            title
            or f"Mission timeline: {summary.bays_built}/{summary.bays_total} bays, {built}, "
            f"{len(summary.faults)} fault(s), {summary.parts_discarded} part(s) discarded"
        )
        fig.tight_layout()
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path)
    finally:
        plt.close(fig)
    return path


__all__ = ["category", "plot_timeline", "timeline_origin"]
