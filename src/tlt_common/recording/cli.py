"""``tlt-record``: record the run's ROS traffic to an MCAP file until SIGINT or SIGTERM.

Writes ``--out`` (default ``${TLT_RUN_DIR:-/tmp/tlt-run}/recording.mcap``). A file already at that
path is kept, renamed to ``recording.1.mcap`` (the first free number), so a restarted recorder
never overwrites what a previous one wrote. On SIGINT or SIGTERM it stops subscribing, writes the
summary and footer and exits 0; a second signal while it finishes is ignored so the file is
completed, and one that comes while it is still starting (the file just created) finishes it too.
The signals only raise a flag that the spin loop checks between callbacks: rclpy's own handler
raises ``KeyboardInterrupt`` wherever the interpreter is, halfway through writing a chunk or
before the code that finishes the file is reached. Exit 2: bad options or the file cannot be
created; 1: writing failed midway (disk full), the messages written so far being recoverable
with ``tlt-mcap-recover``.

ROS arguments (``--ros-args -p use_sim_time:=true``, ``-r __node:=name``) are passed to rclpy.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

from tlt_common.recording.mcap_writer import McapRecordingWriter, available_compressions
from tlt_common.recording.recorder import RecorderTiming, TopicRecorder
from tlt_common.recording.topic_filter import IMAGE_PATTERN, TopicFilter
from tlt_common.ros.direct_executor import DirectExecutor
from tlt_common.ros.rosout_logging import RosoutHandler, forward_logging_to_rosout, init_rclpy
from tlt_common.ros.stop_signals import stop_on_signals

SIGNAL_CHECK_S = 0.1  # longest wait for traffic before the loop looks at the stop flag again


def default_output() -> Path:
    return Path(os.environ.get("TLT_RUN_DIR") or "/tmp/tlt-run") / "recording.mcap"


def keep_existing(path: Path) -> Path | None:
    """Rename a file already at ``path`` to ``stem.N.suffix`` (first free N); return the new name."""
    if not path.exists():
        return None
    n = 1
    while (moved := path.with_name(f"{path.stem}.{n}{path.suffix}")).exists():
        n += 1
    path.rename(moved)
    return moved


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    compressions = available_compressions()
    parser = argparse.ArgumentParser(
        prog="tlt-record",
        description="Record every ROS topic (found continuously) to an MCAP file.",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="MCAP file to write (default: $TLT_RUN_DIR/recording.mcap, "
        "TLT_RUN_DIR defaulting to /tmp/tlt-run)",
    )
    parser.add_argument(
        "--exclude",
        action="append",
        default=[],
        metavar="REGEX",
        help="leave out topics whose whole name matches (repeatable)",
    )
    parser.add_argument(
        "--include-images",
        action="store_true",
        help="also record image topics (by default topics of type "
        f"sensor_msgs/Image or CompressedImage and topics matching "
        f"{IMAGE_PATTERN!r} are excluded)",
    )
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="record only these topics (exact names)")
    parser.add_argument(
        "--compression",
        choices=compressions,
        default=compressions[0],
        help=f"chunk compression (default {compressions[0]})",
    )
    parser.add_argument(
        "--chunk-size",
        type=int,
        default=1024 * 1024,
        help="bytes of messages per chunk before it is written (default 1 MiB)",
    )
    parser.add_argument(
        "--flush-period",
        type=_positive,
        default=1.0,
        metavar="S",
        help="close the chunk in progress every S seconds: what a crash can lose (default 1)",
    )
    parser.add_argument(
        "--discovery-period",
        type=_positive,
        default=0.5,
        metavar="S",
        help="look for new topics every S seconds (default 0.5)",
    )
    parser.add_argument(
        "--progress-period",
        type=_positive,
        default=10.0,
        metavar="S",
        help="log topics and messages written every S seconds (default 10)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(rclpy.utilities.remove_ros_args(["tlt-record", *argv])[1:])
    try:
        topic_filter = TopicFilter(args.topics, args.exclude, args.include_images)
    except ValueError as exc:
        parser.error(str(exc))
    if args.chunk_size <= 0:
        parser.error(f"--chunk-size must be > 0, got {args.chunk_size}")
    out = args.out or default_output()
    # From here on a signal only asks to stop, and a file once created is finished however early
    # the signal comes: installed after the writer, a SIGINT while it wrote the file's header left
    # the file without its footer (KeyboardInterrupt, exit status -2).
    stop = stop_on_signals()
    try:
        moved = keep_existing(out)
        writer = McapRecordingWriter(
            out,
            compression=args.compression,
            chunk_size=args.chunk_size,
            metadata={"argv": " ".join(argv)},
        )
    except OSError as exc:
        print(f"tlt-record: cannot write {out}: {exc}", file=sys.stderr)
        return 2
    if moved is not None:
        print(f"tlt-record: kept the previous {out.name} as {moved}", file=sys.stderr)

    node = None
    logs: RosoutHandler | None = None
    status = 0
    try:
        init_rclpy(["tlt-record", *argv], signal_handler_options=SignalHandlerOptions.NO)
        node = TopicRecorder(
            writer,
            topic_filter,
            RecorderTiming(args.discovery_period, args.flush_period, args.progress_period),
        )
        logs = forward_logging_to_rosout(node)
        executor = DirectExecutor()
        executor.add_node(node)
        while not stop and rclpy.ok():
            executor.spin_once(timeout_sec=SIGNAL_CHECK_S)
    except ExternalShutdownException:
        pass
    except OSError as exc:  # the disk filled up or the file went away: say so, keep what is there
        print(f"tlt-record: writing {out} failed: {exc}", file=sys.stderr)
        status = 1
    finally:
        status = max(status, _finish(node, writer, out))
        if logs is not None:
            logs.remove()
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return status


def _finish(node: TopicRecorder | None, writer: McapRecordingWriter, out: Path) -> int:
    """Stop recording and complete the file; 1 if it could not be completed."""
    try:
        if node is not None:
            node.stop()
        writer.close()
    except OSError as exc:
        print(
            f"tlt-record: could not finish {out}: {exc}; tlt-mcap-recover gets the messages that reached it",
            file=sys.stderr,
        )
        return 1
    if node is not None:
        stats = node.stats
        left_out = f" ({len(stats.skipped)} topics left out: no definition)" if stats.skipped else ""
        print(
            f"tlt-record: wrote {stats.messages} messages on {stats.topics} topics to {out}{left_out}",
            file=sys.stderr,
        )
    return 0
