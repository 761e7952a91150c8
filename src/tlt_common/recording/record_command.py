"""``tlt record``: what a recording holds (``info``), its replay into the graph (``play``) and its
topics as CSV (``export``). Recording itself is ``tlt-record``.

Exit 0: done (``play`` stopped by Ctrl-C or SIGTERM included); 2: bad options, or the file is
missing or not MCAP (the message names the file), or ``export`` was asked for a topic the file
does not have. A recording cut short by a killed recorder is read up to its last flushed chunk,
and each command says it was cut. ``play`` passes ROS arguments (``--ros-args ...``) to rclpy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mcap.exceptions import McapError


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _not_negative(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tlt record", description="Read, replay and export MCAP recordings made by tlt-record."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="{info,play,export}")

    info = sub.add_parser("info", help="topics, types, message counts, times, rates, duration")
    info.add_argument("file", type=Path)

    play = sub.add_parser("play", help="publish the recorded messages on their topics at their timing")
    play.add_argument("file", type=Path)
    play.add_argument(
        "--rate", type=_positive, default=1.0, help="speed factor (2: twice as fast; default 1)"
    )
    play.add_argument(
        "--topics",
        nargs="+",
        metavar="PATTERN",
        help="play only topics whose whole name matches one of these regular expressions",
    )
    play.add_argument(
        "--clock",
        action="store_true",
        help="publish /clock from the recorded times, for nodes with use_sim_time "
        "(a recorded /clock is then not played)",
    )
    play.add_argument(
        "--clock-hz", type=_positive, default=100.0, help="/clock messages per second (default 100)"
    )
    play.add_argument(
        "--delay",
        type=_not_negative,
        default=0.5,
        metavar="S",
        help="wait S seconds after making the publishers, so running subscribers match them (default 0.5)",
    )
    play.add_argument(
        "--wait-for-subscribers",
        action="store_true",
        help="before playing, wait until every played topic (and /clock) has a subscriber",
    )
    play.add_argument(
        "--progress-period", type=_positive, default=1.0, metavar="S", help="print progress every S seconds"
    )

    export = sub.add_parser("export", help="chosen topics to CSV, one file per topic")
    export.add_argument("file", type=Path)
    export.add_argument("--topics", nargs="+", required=True, metavar="TOPIC", help="exact topic names")
    export.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder for the CSV files")
    return parser


def main(argv: list[str] | None = None) -> int:
    import rclpy.utilities

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(rclpy.utilities.remove_ros_args(["tlt-record", *argv])[1:])
    try:
        if args.command == "info":
            return _info(args)
        if args.command == "export":
            return _export(args)
        return _play(args, argv)
    except (OSError, McapError) as exc:
        print(f"tlt record {args.command}: cannot read {args.file}: {exc}", file=sys.stderr)
        return 2


def _info(args: argparse.Namespace) -> int:
    from tlt_common.recording.summary import format_summary, summarise

    print(format_summary(summarise(args.file)))
    return 0


def _export(args: argparse.Namespace) -> int:
    from tlt_common.recording.csv_export import UnknownTopics, export_csv

    try:
        report = export_csv(args.file, args.topics, args.out)
    except UnknownTopics as exc:
        print(f"tlt record export: {exc}", file=sys.stderr)
        return 2
    if not report.complete:
        print(
            f"tlt record export: {args.file} was cut short ({report.stopped_at or 'no footer'}): "
            "exported the messages before the cut",
            file=sys.stderr,
        )
    for topic, path in report.files.items():
        print(f"{path}: {report.rows[topic]} rows ({topic})")
    return 0


def _play(args: argparse.Namespace, argv: list[str]) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from tlt_common.recording.player import PlayOptions, RecordingPlayer, open_recording
    from tlt_common.ros.stop_signals import stop_on_signals

    recording = open_recording(args.file)
    options = PlayOptions(
        rate=args.rate,
        topics=args.topics,
        clock=args.clock,
        clock_hz=args.clock_hz,
        delay_s=args.delay,
        wait_for_subscribers=args.wait_for_subscribers,
        progress_period_s=args.progress_period,
    )
    stop = stop_on_signals()
    rclpy.init(args=["tlt-record-play", *argv], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("tlt_record_play")
    try:
        try:
            player = RecordingPlayer(node, recording, options)
        except ValueError as exc:
            print(f"tlt record play: {exc}", file=sys.stderr)
            return 2
        if not recording.complete:
            print(
                f"tlt record play: {args.file} was cut short ({recording.stopped_at or 'no footer'}): "
                "playing the messages before the cut, in file order",
                flush=True,
            )
        for topic, why in sorted(player.skipped.items()):
            print(f"tlt record play: not playing {topic}: {why}", flush=True)
        if not player.topics:
            print("tlt record play: no topic to play", file=sys.stderr)
            return 2
        print(
            f"tlt record play: {len(player.topics)} topics, {recording.duration_s:.1f} s at rate "
            f"{args.rate:g}{', publishing /clock' if args.clock else ''}",
            flush=True,
        )
        report = player.play(stop)
        state = "stopped" if report.stopped else "done"
        print(
            f"tlt record play: {state}: {report.played_s:.1f} / {recording.duration_s:.1f} s, "
            f"{sum(report.published.values())} messages",
            flush=True,
        )
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
