"""The headless mission job of the ground station: ``tlt gsw mission`` and ``tlt gsw summary``.

``tlt gsw mission`` supervises one build over the CCSDS ground link (paper §III, §V.A):

1. records every packet, sent and received, in the SQLite archive for the whole run;
2. sends an authenticated Start and waits for its accepted and completed acknowledgements (a
   rejection is printed with its reason and the job exits 1; so is a rejection the CRS reports
   only as an event, as it does for a command it cannot authenticate);
3. prints progress: a line whenever the CRS's bay or step changes (``mission_step``), the CRS
   tree's running node when it changes (decoded from ``tree_status`` with ``--tree``, else status
   counts), and every event of severity warning or above, and every fault as it is raised or cleared;
4. ends when the telemetry says the tower is built (exit 0), when a fault has stood for
   ``--fault-timeout`` s without being cleared (exit 1), at ``--timeout`` (exit 3) or on Ctrl-C
   (exit 130); the archive is flushed and closed in every case;
5. prints the summary computed from the archive (:mod:`tlt_gsw.summary`) and writes the timeline
   PNG next to it (:mod:`tlt_gsw.timeline_plot`).

``tlt gsw summary --archive FILE [--plot PNG]`` prints the same summary from any archive.

Exit status: 0 tower built (summary: an archive was read), 1 Start rejected or failed, or a fault
not cleared in time, 2 bad usage, configuration, key or archive, 3 no acknowledgement or
``--timeout``, 130 interrupted.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from tlt_common.bt.status_codec import TreeShape
from tlt_common.ccsds.auth import CommandSequencer, KeyFileError, KeyRing, ReplayStateError
from tlt_common.ccsds.codec import Packet, ParseResult
from tlt_common.ccsds.definitions import Definitions, load_definitions
from tlt_common.ccsds.link_config import expand_path, load_link_config
from tlt_common.ccsds.reasons import AckStage
from tlt_common.config_schema import ConfigError
from tlt_gsw.archive import query as archive_query
from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.link import GswLink, SentCommand, accepted_sources, host_port
from tlt_gsw.mission_progress import Progress
from tlt_gsw.summary import format_summary, summarize_file

EXIT_BUILT, EXIT_FAULT, EXIT_USAGE, EXIT_TIMEOUT, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
EXIT_REJECTED = EXIT_FAULT
# How often the job re-sends Start while the CRS has not answered (it may still be starting).
START_RETRY_S = 2.0
REJECTION_CODES = ("COMMAND_REJECTED", "DATAGRAM_REJECTED")
# A Start the CRS refuses with this in the reason is asked again: its drivers are still coming up.
NOT_READY = "not ready"

REJECTION_ACK_GRACE_S = 0.5
# After "done", how long the job waits for the tower model's next report (hk_tower, every 2 s and
# after each progress report): the last member's state may have changed after the report before.
TOWER_REPORT_WAIT_S = 3.0


class JobError(ValueError):
    """Bad usage or settings; the message says what to change."""


def _rejected_by_event(packet: Packet, own: tuple[str, int]) -> str | None:
    """The reason of a CRS rejection report about a datagram from ``own`` address, else None."""
    if packet.kind != "event" or packet.fields["code"] not in REJECTION_CODES:
        return None
    text = packet.fields["text"]
    # Bound to every interface, the job does not know which address the CRS saw; the port tells.
    where = f":{own[1]} rejected: " if own[0] in ("0.0.0.0", "") else f" from {own[0]}:{own[1]} rejected: "
    if where not in text:
        return None
    return f"{packet.fields['reason']}: {packet.fields['text']}"


def _start(link: GswLink, out: IO[str], timeout: float, seen: list[Packet]) -> tuple[int, SentCommand | None]:
    """Send Start (again while the CRS is silent) and wait for its final ack; (exit code, command)."""
    deadline = time.monotonic() + timeout
    sent: list[SentCommand] = []
    last_sent = 0.0
    checked = len(seen)  # only rejections reported from now on can be about this Start
    rejected_event: tuple[str, float] | None = None
    not_ready = ""
    while time.monotonic() < deadline:
        silent = not any(s.acks for s in sent)
        retry_due = time.monotonic() - last_sent >= START_RETRY_S
        if (not sent and (not not_ready or retry_due)) or (silent and retry_due):
            command = link.send_command("start")
            last_sent = time.monotonic()
            sent.append(command)
            print(f"sent start (security_seq {command.security_seq})", file=out, flush=True)
        link.poll(0.1)
        for packet in seen[checked:]:
            reason = _rejected_by_event(packet, link.address)
            if reason is not None and rejected_event is None and NOT_READY not in reason:
                # An authenticated command's rejection also comes as an ack, with the CRS's words.
                rejected_event = (reason, time.monotonic() + REJECTION_ACK_GRACE_S)
        checked = len(seen)
        if rejected_event is not None and time.monotonic() >= rejected_event[1]:
            print(f"start rejected: {rejected_event[0]}", file=out, flush=True)
            return EXIT_REJECTED, None
        # Start may have been sent more than once while the CRS was coming up: one that completed
        # wins, and a later copy refused as "already started" is no rejection of the job's Start.
        done = next((c for c in sent if c.final is not None and c.final.stage is AckStage.COMPLETED), None)
        accepted = any(a.stage is AckStage.ACCEPTED for c in sent for a in c.acks)
        for command in [done] if done is not None else list(sent):
            final = command.final
            if final is not None:
                if final.stage in (AckStage.REJECTED, AckStage.FAILED):
                    if accepted and final.stage is AckStage.REJECTED:
                        continue
                    if NOT_READY in (final.detail or ""):  # refused, or failed when its turn came
                        # The CRS is up but its drivers are not yet: ask again until start_timeout.
                        if final.detail != not_ready:
                            print(
                                f"start refused for now ({final.detail}); asking again", file=out, flush=True
                            )
                        not_ready = final.detail
                        sent.remove(command)
                        continue
                    detail = f" ({final.detail})" if final.detail else ""
                    print(f"start {final.stage.label}: {final.reason.label}{detail}", file=out, flush=True)
                    return EXIT_REJECTED, command
                print("start accepted and completed", file=out, flush=True)
                return EXIT_BUILT, command
    answered = any(s.acks for s in sent)
    what = "no completion of start" if answered else "no acknowledgement of start"
    print(f"{what} within {timeout:g} s", file=out, flush=True)
    return EXIT_TIMEOUT, None


def run_mission(
    link: GswLink,
    out: IO[str],
    *,
    timeout: float,
    fault_timeout: float,
    start_timeout: float,
    tree: TreeShape | None = None,
    restart_start: bool = True,
    clock: Callable[[], float] = time.monotonic,
) -> int:
    """Start the build through ``link`` and follow it to its end; return the exit code.

    With ``restart_start``, a CRS that announces itself again (``CRS_UP``: it was restarted)
    while the tower is not built gets Start again.
    """
    seen: list[Packet] = []
    progress = Progress(out, tree)

    def on_packet(result: ParseResult) -> None:
        if isinstance(result, Packet):
            seen.append(result)
            progress.packet(result, clock())

    link.on_packet = on_packet
    started = clock()
    code, _ = _start(link, out, start_timeout, seen)
    if code != EXIT_BUILT:
        return code
    crs_up = progress.crs_up
    while True:
        if restart_start and progress.crs_up > crs_up and not progress.tower_built:
            # A CRS restarted mid-build resumes its tower model but waits for Start (§V.C.2).
            crs_up = progress.crs_up
            progress.say("the CRS restarted: sending Start again")
            code, command = _start(link, out, start_timeout, seen)
            refused = command.final if command is not None else None
            if refused is not None and refused.detail == "already started":
                progress.say("the restarted CRS was already started")
            elif code != EXIT_BUILT:
                return code
        link.poll(0.2)
        del seen[:-100]  # the archive has them all; keep the list small
        if link.recorder is not None and link.recorder.last_error:
            progress.say(f"  ARCHIVE: {link.recorder.last_error}")
        if progress.tower_built:
            progress.say("tower built")
            # The packets the CRS sent along with "done" (progress, tower model) belong in the archive,
            # and a tower model reported after it: the summary's member states are the last report's.
            reports, deadline = progress.tower_reports, clock() + TOWER_REPORT_WAIT_S
            link.poll(0.3)
            while progress.tower_reports == reports and clock() < deadline:
                link.poll(0.1)
            return EXIT_BUILT
        now = clock()
        since = progress.fault_since
        if progress.fault and since is not None and now - since >= fault_timeout:
            progress.say(f"fault not cleared within {fault_timeout:g} s: {progress.fault}")
            return EXIT_FAULT
        if now - started >= timeout:
            state = progress.last_mission.get("run_state", "unknown")
            progress.say(f"timeout: the tower was not built within {timeout:g} s (run state {state})")
            return EXIT_TIMEOUT


def default_plot_path(archive: Path) -> Path:
    return archive.with_name(archive.stem + "_timeline.png")


def _last_packet_id(archive: Path) -> int:
    conn = archive_query.open_archive(archive)
    try:
        return int(conn.execute("SELECT COALESCE(MAX(id), 0) FROM packets").fetchone()[0])
    finally:
        conn.close()


def _print_summary(
    archive: Path, plot: Path | None, out: IO[str], after: int = 0, defs: Definitions | None = None
) -> None:
    summary = summarize_file(archive, after, defs)
    print(format_summary(summary), file=out, flush=True)
    if plot is not None:
        from tlt_gsw.timeline_plot import plot_timeline

        plot_timeline(summary, plot)
        print(f"  timeline plot:    {plot}", file=out, flush=True)
    print(f"  archive:          {archive}", file=out, flush=True)


def _cmd_mission(args: argparse.Namespace, out: IO[str]) -> int:
    if threading.current_thread() is threading.main_thread():
        # A script's background job starts with SIGINT ignored, and Python then raises no
        # KeyboardInterrupt: Ctrl-C or `kill -INT` must still end the job with its summary.
        signal.signal(signal.SIGINT, signal.default_int_handler)
    defs = load_definitions(args.definitions)
    conf = load_link_config(args.config)
    gsw = conf["gsw"]
    key_file = args.key_file or conf["key_file"]
    keyring = KeyRing.load(expand_path(key_file) if key_file else None)
    key_id = args.key_id if args.key_id is not None else conf["key_id"]
    if keyring.get(key_id) is None:
        raise JobError(f"key id {key_id} is not in the key file (it has {keyring.key_ids})")
    tree = None
    if args.tree:
        from tlt_gsw.gui.tree_definitions import load_tree_definition

        tree = load_tree_definition(args.tree)
    archive = expand_path(args.archive or gsw["archive"])
    archive.parent.mkdir(parents=True, exist_ok=True)
    plot = None if args.no_plot else Path(args.plot) if args.plot else default_plot_path(archive)
    recorder = Recorder(archive)
    # An archive kept across runs holds earlier runs: this job's summary starts after them.
    first = _last_packet_id(archive)
    try:
        link = GswLink(
            defs,
            keyring,
            key_id,
            args.crs or (gsw["crs_host"], gsw["crs_port"]),
            bind=args.bind or (gsw["bind_host"], gsw["bind_port"]),
            recorder=recorder,
            close_recorder=True,
            sequencer=CommandSequencer(expand_path(gsw["command_state"])),
            recv_buffer_bytes=4 << 20,
            tm_key_overlap_s=gsw["tm_key_overlap_s"],
            accept_from=accepted_sources(gsw, args.crs),
        )
    except BaseException:
        recorder.close()
        raise
    code = EXIT_INTERRUPTED
    started = time.monotonic()
    try:
        print(
            f"mission job: archive {archive}, listening on {link.address[0]}:{link.address[1]}, "
            f"CRS at {link.crs_address[0]}:{link.crs_address[1]}",
            file=out,
            flush=True,
        )
        code = run_mission(
            link,
            out,
            timeout=args.timeout,
            fault_timeout=args.fault_timeout,
            start_timeout=args.start_timeout,
            tree=tree,
            restart_start=not args.no_restart_start,
        )
    except KeyboardInterrupt:
        print("interrupted", file=out, flush=True)
        code = EXIT_INTERRUPTED
    finally:
        # A last short listen so the packets in flight at the end are archived too.
        try:
            link.poll(0.2)
        except (OSError, KeyboardInterrupt):
            pass
        link.close()
        print(f"wall time {time.monotonic() - started:.1f} s, exit status {code}", file=out, flush=True)
    _print_summary(archive, plot, out, after=first, defs=defs)
    return code


def _cmd_summary(args: argparse.Namespace, out: IO[str]) -> int:
    if args.archive:
        archive = expand_path(args.archive)
    else:
        archive = expand_path(load_link_config(args.config)["gsw"]["archive"])
    plot = Path(args.plot) if args.plot else None
    _print_summary(archive, plot, out, defs=load_definitions(args.definitions))
    return EXIT_BUILT


def add_mission_parser(sub: Any) -> argparse.ArgumentParser:
    """Add ``mission`` to the subcommands ``sub`` of a ``tlt gsw`` parser."""
    p = sub.add_parser("mission", help="start a build and follow it to tower built, then summarize")
    p.add_argument("--crs", type=host_port, help="CRS host:port (default: link.yaml)")
    p.add_argument("--bind", type=host_port, help="local host:port for telemetry (default: link.yaml)")
    p.add_argument("--key-file", help="key file (default: link.yaml key_file or $TLT_GROUND_KEY_FILE)")
    p.add_argument("--key-id", type=int)
    p.add_argument("--archive", help="archive SQLite file (default: link.yaml gsw.archive)")
    # Generous: a one-bay build can take about an hour of wall time on a loaded 2-core machine.
    p.add_argument("--timeout", type=float, default=14400.0, help="give up after this many s (exit 3)")
    p.add_argument(
        "--fault-timeout", type=float, default=300.0,
        help="end when a fault stands this many s without being cleared (exit 1)",
    )  # fmt: skip
    p.add_argument(
        "--start-timeout", type=float, default=60.0,
        help="how long to wait for the CRS to acknowledge Start (it may still be starting)",
    )  # fmt: skip
    p.add_argument("--tree", help="CRS tree definition JSON, to name the running node of tree_status")
    p.add_argument(
        "--no-restart-start", action="store_true",
        help="do not send Start again to a CRS that restarted mid-build",
    )  # fmt: skip
    p.add_argument("--plot", help="timeline PNG (default: <archive>_timeline.png)")
    p.add_argument("--no-plot", action="store_true", help="do not write the timeline plot")
    return p


def add_summary_parser(sub: Any) -> argparse.ArgumentParser:
    """Add ``summary`` to the subcommands ``sub`` of a ``tlt gsw`` parser."""
    p = sub.add_parser("summary", help="print the mission summary of an archive (and plot its timeline)")
    p.add_argument("--archive", help="archive SQLite file (default: link.yaml gsw.archive)")
    p.add_argument("--plot", help="also write the timeline PNG here")
    return p


ACTIONS = {"mission": _cmd_mission, "summary": _cmd_summary}
ERRORS = (
    JobError,
    ConfigError,
    KeyFileError,
    ReplayStateError,
    archive_query.ArchiveError,
    OSError,
)


def run(args: argparse.Namespace, out: IO[str] | None = None) -> int:
    """Run a parsed ``mission`` or ``summary`` subcommand; errors become exit status 2."""
    out = out or sys.stdout
    try:
        return ACTIONS[args.action](args, out)
    except ERRORS as exc:
        print(f"tlt gsw {args.action}: {exc}", file=sys.stderr)
        return EXIT_USAGE


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tlt gsw", description="TLT ground station: the mission job.")
    parser.add_argument("--config", help="link settings YAML (default config/ccsds/link.yaml)")
    parser.add_argument("--definitions", help="command/telemetry definitions YAML")
    sub = parser.add_subparsers(dest="action", required=True)
    add_mission_parser(sub)
    add_summary_parser(sub)
    return parser


def main(argv: list[str] | None = None, out: IO[str] | None = None) -> int:
    """``tlt gsw mission ...`` / ``tlt gsw summary ...`` (argv starts with the subcommand)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) if isinstance(exc.code, int) else EXIT_USAGE
    try:
        return run(args, out)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
