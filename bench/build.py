"""Where a tower build's time goes: wall time of the build, and sim time per bay against the
motions it ran.

Two figures of the issue "whole system", read from one run of the main job:

* **wall time** of the build (goal for a 2-bay tower: 10 minutes), from Start taken to
  ``tower_built``, and of the whole job (start-up and shut-down included);
* **sim time per bay against its physical lower bound**: every trajectory a driver ran is recorded
  when it ends (``/<component>/executed_trajectories``, ``tlt_interfaces/ExecutedTrajectory``: its
  own planned duration, when it started and ended, how it ended). A bay's bound is the sum of the
  planned durations of the trajectories that started in the bay and succeeded: the ARSs' arm
  motions are time-optimal along their checked paths (``tlt_ars.planning.time_parameterisation``),
  the lifter's run at the mission's ``lifter_speed``, the grippers' and end effectors' take the time
  their configuration gives them. A joint commanded by position over ``/<component>/position_command``
  (an end effector's width: 16 s for a diagonal's 0.25 m at 15 mm/s) has no trajectory record: each
  change of its command counts as a move at the joint's ``max_velocity`` in
  ``config/hardware/<component>.yaml`` from the previous command (from 0, where calibration leaves
  it, for the first). The ratio of the bay's sim time to that bound is the time lost
  to waiting, polling, inspecting and planning (goal <= 1.25). Also printed: the time anything
  was moving (two arms moving at once count once), the bound by component, and the trajectories
  that did not succeed, whose time is lost.

The bay's span (first CRS step to the packet saying it is built) comes from the ground archive
(``tlt_gsw.summary``), the records from the MCAP recording, both on the twin's sim clock.

Also, on the twin, where each member's part stands against its place: the twin's last ground
truth in the recording (``/twin/ground_truth``) puts every part; a part's body frame sits at its
member's first joint (the mission file), and the part nearest that joint from the member's
dispenser is taken as the member's. Members more than ``PLACE_WARN_M`` off are listed.

The run is the main job as fast as this machine builds: the twin uncapped (real-time factor 0) and
the arms at their full speed limits, as the system tests run them. A 2-bay build needs over 1000 s
of sim time, so the goal presupposes both; ``--rtf 1 --arm-speed 0.5`` measures the main job as
``scripts/main.sh`` runs it for people (the twin at real time, the ARS files' arm speed).

Usage:
  python bench/build.py [--mission two_bay] [--rtf R] [--arm-speed S]
                                                      # run scripts/main.sh into a fresh run
                                                      # folder (the twin at real-time factor R, 0:
                                                      # no limit, the default; the arms at S of
                                                      # their speed limits, 1 by default), report
  python bench/build.py --run-dir DIR [--mission NAME]   # report on a finished run (archive and
                                                      # recording; the mission for the placements)
"""

from __future__ import annotations

import argparse
import functools
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOPIC_SUFFIX = "/executed_trajectories"
COMMAND_SUFFIX = "/position_command"
WALL_GOAL_S = 600.0  # a 2-bay tower
RATIO_GOAL = 1.25
PLACE_WARN_M = 0.005


@dataclass(frozen=True)
class Motion:
    """One executed trajectory: ``component`` (``ur_x``, ``lifter``, ...), sim-time span, outcome."""

    component: str
    started: float
    ended: float
    planned_s: float
    succeeded: bool


@dataclass
class PhaseMotion:
    """The motions of one phase (a bay, or the foundation rivets) against its sim time."""

    name: str
    sim_s: float
    wall_s: float
    complete: bool
    bound_s: float = 0.0  # sum of the succeeded motions' planned durations
    moving_s: float = 0.0  # union of every motion's span
    lost_s: float = 0.0  # planned time of motions that did not succeed
    failed: int = 0
    by_component: dict[str, float] = field(default_factory=dict)
    motions: int = 0

    @property
    def ratio(self) -> float | None:
        return self.sim_s / self.bound_s if self.bound_s > 0 else None


def union_length(spans: Iterable[tuple[float, float]]) -> float:
    """Total length covered by the spans (overlaps counted once)."""
    total, end = 0.0, float("-inf")
    for a, b in sorted(spans):
        if b <= end:
            continue
        total += b - max(a, end)
        end = b
    return total


def account(phases: Iterable, motions: Iterable[Motion]) -> list[PhaseMotion]:
    """Each phase (``tlt_gsw.summary.PhaseTimes``) with the motions that started within its sim span."""
    motions = sorted(motions, key=lambda m: m.started)
    out = []
    for phase in phases:
        mine = [m for m in motions if phase.sim_start <= m.started < phase.sim_end]
        pm = PhaseMotion(phase.name, phase.sim_s, phase.wall_s, phase.complete, motions=len(mine))
        by_component: dict[str, float] = defaultdict(float)
        for m in mine:
            if m.succeeded:
                pm.bound_s += m.planned_s
                by_component[m.component] += m.planned_s
            else:
                pm.lost_s += m.planned_s
                pm.failed += 1
        pm.by_component = dict(sorted(by_component.items()))
        pm.moving_s = union_length((m.started, min(m.ended, phase.sim_end)) for m in mine)
        out.append(pm)
    return out


@functools.cache
def group_speeds(component: str) -> list[float] | None:
    """The ``max_velocity`` of each joint of ``component``'s group position command, in command
    order, from its hardware file; None when the file gives none."""
    import yaml

    path = ROOT / "config" / "hardware" / f"{component}.yaml"
    if not path.is_file():
        return None
    joints = yaml.safe_load(path.read_text()).get("joints", [])
    joints = [j for j in joints if j.get("controller") == "group_position"]
    if not joints or any("max_velocity" not in j for j in joints):
        return None
    return [float(j["max_velocity"]) for j in joints]


def read_motions(recording: Path) -> list[Motion]:
    """Every ExecutedTrajectory in a recording, and every change of a group position command whose
    joints' speeds the hardware files give (component ``<component> position``)."""
    from mcap.reader import make_reader
    from tlt_interfaces.msg import ExecutedTrajectory

    from tlt_common.recording.reading import read_messages
    from tlt_common.ros.stamps import stamp_seconds

    with open(recording, "rb") as stream:
        summary = make_reader(stream).get_summary()
    topics = [c.topic for c in summary.channels.values() if c.topic.endswith((TOPIC_SUFFIX, COMMAND_SUFFIX))]
    motions = []
    commanded: dict[str, list[float]] = {}
    for _schema, channel, message, msg in read_messages(recording, topics=topics):
        if channel.topic.endswith(COMMAND_SUFFIX):
            component = channel.topic[1 : -len(COMMAND_SUFFIX)]
            speeds = group_speeds(component)
            if speeds is None or len(msg.data) != len(speeds):
                continue
            before = commanded.get(component, [0.0] * len(speeds))
            commanded[component] = list(msg.data)
            planned = max(abs(b - a) / v for a, b, v in zip(before, msg.data, speeds, strict=True))
            if planned > 0.0:  # the same command again (a repeat) moves nothing
                started = message.log_time * 1e-9
                motions.append(Motion(f"{component} position", started, started + planned, planned, True))
            continue
        motions.append(Motion(
            component=channel.topic[1:-len(TOPIC_SUFFIX)],
            started=stamp_seconds(msg.started),
            ended=stamp_seconds(msg.header.stamp),
            planned_s=msg.planned_s,
            succeeded=msg.outcome == ExecutedTrajectory.OUTCOME_SUCCEEDED,
        ))  # fmt: skip
    return motions


def placed_members(run_dir: Path, mission_path: Path) -> set[str] | None:
    """The members the run's tower model (``tower_model.json``) says stand, or None without a
    model to read (every member is then looked for)."""
    from tlt_common.mission.schema import load_mission
    from tlt_common.mission.tower_model import PLACED, TowerModel, TowerModelError

    path = run_dir / "tower_model.json"
    if not path.is_file():
        return None
    try:
        model = TowerModel.load(load_mission(mission_path), path)
    except TowerModelError as exc:
        print(f"build bench: {exc}; looking for every member's part", file=sys.stderr)
        return None
    return {member for member, state in model.states.items() if state >= PLACED}


def read_placements(
    recording: Path, mission_path: Path, placed: set[str] | None = None
) -> list[tuple[str, str, float]]:
    """(member id, part, metres off) for each member of the mission that is in ``placed`` (every
    member when None), from the recording's last twin ground truth; empty when the recording has
    none (a run on the hardware)."""
    import numpy as np

    from tlt_common.mission.schema import load_mission
    from tlt_common.recording.reading import read_messages

    last: dict[str, np.ndarray] = {}
    for _schema, _channel, _message, msg in read_messages(recording, topics=["/twin/ground_truth"]):
        for tf in msg.transforms:
            t = tf.transform.translation
            last[tf.child_frame_id] = np.array([t.x, t.y, t.z])
    if "tower" not in last:
        return []
    out = []
    for member in load_mission(mission_path).members:
        if member.kind == "foundation_rivet" or not member.joints:
            continue
        if placed is not None and member.id not in placed:
            continue
        place = last["tower"] + np.asarray(member.joints[0][1])
        parts = {k: v for k, v in last.items() if k.startswith(f"part/{member.dispenser}/")}
        if parts:
            part = min(parts, key=lambda k: float(np.linalg.norm(parts[k] - place)))
            out.append((member.id, part, float(np.linalg.norm(parts[part] - place))))
    return out


def _print_placements(placements: list[tuple[str, str, float]]) -> None:
    if not placements:
        print("\nplacement: no twin ground truth in the recording")
        return
    offs = sorted(off for _, _, off in placements)
    worst = max(placements, key=lambda p: p[2])
    print(
        f"\nplacement (twin ground truth, each part against its place): {len(placements)} members, "
        f"median {1000 * offs[len(offs) // 2]:.1f} mm, worst {1000 * worst[2]:.1f} mm ({worst[0]})"
    )
    for member, part, off in placements:
        if off > PLACE_WARN_M:
            print(f"  {member}: {part} {1000 * off:.1f} mm off")


def _ratio(value: float | None, goal: float) -> str:
    if value is None:
        return "n/a"
    return f"{value:.2f} (goal <= {goal:g}: {'met' if value <= goal else 'not met'})"


def report(run_dir: Path, job_wall_s: float | None = None, mission: str | None = None) -> int:
    """Print the figures of a finished run (and, given its ``mission``, where each member's part
    stands); 0 when it had what they need, 1 otherwise."""
    from tlt_gsw.summary import summarize_file

    archive, recording = run_dir / "gsw_archive.sqlite", run_dir / "recording.mcap"
    missing = [p.name for p in (archive, recording) if not p.is_file()]
    if missing:
        print(f"build bench: {run_dir} has no {' or '.join(missing)}", file=sys.stderr)
        return 1
    summary = summarize_file(archive)
    motions = read_motions(recording)
    phases = [p for p in summary.phases if p.sim_s > 0]
    print(f"run {run_dir}: {summary.bays_built} of {summary.bays_total} bays, "
          f"{'tower built' if summary.tower_built else 'tower NOT built'}, "
          f"{len(motions)} executed trajectories recorded")  # fmt: skip
    if phases:
        build_wall = phases[-1].wall_end - phases[0].wall_start
        build_sim = phases[-1].sim_end - phases[0].sim_start
        print(f"build (first step to the last phase's end): {build_wall:.0f} s wall, {build_sim:.0f} s sim, "
              f"sim/wall {build_sim / build_wall:.2f}")  # fmt: skip
        if summary.bays_total == 2 and summary.tower_built:
            print(f"2-bay build wall time: {build_wall / 60:.1f} min, ratio to the 10 min goal "
                  f"{_ratio(build_wall / WALL_GOAL_S, 1.0)}")  # fmt: skip
    if job_wall_s is not None:
        print(f"whole job (start-up, build, shut-down): {job_wall_s:.0f} s wall")
    print()
    print(f"{'phase':<12}{'sim s':>8}{'wall s':>8}{'bound s':>9}{'ratio':>7}{'moving s':>10}"
          f"{'motions':>9}{'failed':>8}{'lost s':>8}")  # fmt: skip
    rows = account(phases, motions)
    for r in rows:
        ratio = f"{r.ratio:.2f}" if r.ratio is not None else "n/a"
        mark = "" if r.complete else "  (not finished)"
        print(f"{r.name:<12}{r.sim_s:>8.1f}{r.wall_s:>8.1f}{r.bound_s:>9.1f}{ratio:>7}{r.moving_s:>10.1f}"
              f"{r.motions:>9}{r.failed:>8}{r.lost_s:>8.1f}{mark}")  # fmt: skip
    print()
    for r in rows:
        parts = ", ".join(f"{c} {s:.1f}" for c, s in r.by_component.items())
        print(f"{r.name}: bound by component (s): {parts or 'none'}")
    bays = [r for r in rows if r.name.startswith("bay") and r.complete]
    if bays:
        worst = max((r.ratio for r in bays if r.ratio is not None), default=None)
        print(f"\nsim time per bay / motion lower bound, worst bay: {_ratio(worst, RATIO_GOAL)}")
    if mission is not None:
        mission_path = ROOT / "missions" / f"{mission}.yaml"
        placed = placed_members(run_dir, mission_path)
        if placed is not None and not placed:
            print("\nplacement: no member placed in this run")  # the parts in the dispensers are no result
        else:
            _print_placements(read_placements(recording, mission_path, placed))
    return 0 if rows else 1


def run_job(
    mission: str, run_dir: Path, rtf: float, arm_speed: float, cameras: str, segmentation: str
) -> tuple[int, float]:
    """Run the main job on ``mission`` into ``run_dir``, its output shown as it comes."""
    env = dict(
        os.environ,
        TLT_RUN_DIR=str(run_dir),
        TLT_TWIN_RTF=f"{rtf:g}",
        TLT_ARM_VELOCITY_SCALE=f"{arm_speed:g}",
        TLT_CAMERA_MODEL=cameras,
        TLT_SEGMENTATION=segmentation,
    )
    started = time.monotonic()
    status = subprocess.call(["bash", str(ROOT / "scripts" / "main.sh"), "--mission", mission], env=env)
    return status, time.monotonic() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mission", default="two_bay", help="mission to build (missions/NAME.yaml)")
    parser.add_argument("--run-dir", type=Path, help="report on this finished run instead of running one")
    parser.add_argument(
        "--rtf",
        type=float,
        default=0.0,
        help="the twin's real-time factor (0, the default: as fast as it can)",
    )
    parser.add_argument(
        "--arm-speed",
        type=float,
        default=1.0,
        help="the arms' speed as a fraction of their limits (default 1; the ARS files': 0.5)",
    )
    parser.add_argument(
        "--camera-model",
        choices=("exact", "realistic"),
        default="exact",
        help="the twin's cameras (TLT_CAMERA_MODEL; default exact, as the main job's)",
    )
    parser.add_argument(
        "--segmentation",
        choices=("", "twin_labels", "mask_rcnn"),
        default="",
        help="where vision's masks come from (TLT_SEGMENTATION; default: config/vision/node.yaml's)",
    )
    args = parser.parse_args(argv)
    if args.run_dir is not None:
        return report(args.run_dir, mission=args.mission)
    run_dir = Path(tempfile.mkdtemp(prefix="tlt-bench-build."))
    status, wall = run_job(
        args.mission, run_dir, args.rtf, args.arm_speed, args.camera_model, args.segmentation
    )
    described = (
        f"twin real-time factor {args.rtf:g}, arms at {args.arm_speed:g} of their speed limits, "
        f"{args.camera_model} cameras, masks from {args.segmentation or 'node.yaml'}"
    )
    print(f"\nbuild bench: main job on {args.mission} ({described}) exited {status} after {wall:.0f} s\n")
    return report(run_dir, wall, args.mission) or status


if __name__ == "__main__":
    sys.exit(main())
