"""Headless ground station: ``tlt gsw send|watch|query|export`` (paper §V.A).

``send``    build an authenticated command, send it to the CRS, optionally wait for its acks.
``watch``   receive telemetry, record it in the archive and print one line per packet.
``query``   list archived packets, totals, or one field's series.
``export``  write the fields of one packet kind to CSV.
``keygen``  create a shared key file (mode 0600) for both ends.
``levers``  list what an operator may set: every agent's writable keys (type, range, meaning),
            the tower-model corrections and the actuators with their states.
``correct-member``, ``correct-dispenser``
            correct the CRS's tower model (Set Blackboard Value of ``tower/<member>`` or
            ``dispenser/<name>``, :mod:`tlt_common.bt.ground_keys`), acknowledged like ``send``.
``mission`` start a build and follow it to tower built; ``summary`` summarize an archive
            (both in :mod:`tlt_gsw.mission_job`, with their own exit codes).

Settings come from ``config/ccsds/link.yaml`` (``--config``) and the definitions file
(``--definitions``); options override them. Exit status: 0 success, 1 command rejected or failed,
2 bad usage, configuration, key or archive, 3 no acknowledgement in time.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tlt_common.bt.ground_keys import (
    AGENTS,
    MEMBER_MARKS,
    agent_key,
    dispenser_key,
    load_whitelists,
    member_key,
)
from tlt_common.ccsds.auth import CommandSequencer, KeyFileError, KeyRing, ReplayStateError, write_key_file
from tlt_common.ccsds.codec import Packet, ParseResult
from tlt_common.ccsds.definitions import CommandDef, Definitions, FieldDef, load_definitions
from tlt_common.ccsds.fields import FieldError
from tlt_common.ccsds.link_config import expand_path, load_link_config
from tlt_common.ccsds.reasons import AckStage
from tlt_common.config_schema import ConfigError
from tlt_gsw.archive import query as archive_query
from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.link import GswLink, accepted_sources, host_port
from tlt_gsw.mission_job import ACTIONS as MISSION_ACTIONS
from tlt_gsw.mission_job import add_mission_parser, add_summary_parser
from tlt_gsw.mission_job import run as run_mission_action

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_TIMEOUT = 0, 1, 2, 3


class UsageError(ValueError):
    """Bad command-line input; the message says what to change."""


def _parse_typed(text: str) -> Any:
    """A Set Blackboard Value value: ``int:3``, ``float:2``, ``bool:true``, ``str:x`` or inferred."""
    kind, sep, rest = text.partition(":")
    if sep and kind in ("int", "float", "bool", "str"):
        if kind == "int":
            return int(rest, 0)
        if kind == "float":
            return float(rest)
        if kind == "bool":
            if rest.lower() not in ("true", "false", "1", "0"):
                raise ValueError(f"{rest!r} is not a boolean")
            return rest.lower() in ("true", "1")
        return rest
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for convert in (lambda t: int(t, 0), float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def _convert(fd: FieldDef, text: str) -> Any:
    try:
        if fd.type == "value":
            return _parse_typed(text)
        if fd.type in ("f32", "f64"):
            return float(text)
        if fd.type.startswith(("u", "i")):
            return int(text, 0)
        if fd.type == "bool":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(f"{text!r} is not true or false")
            return text.lower() in ("true", "1")
        if fd.type == "bytes":
            return bytes.fromhex(text)
    except ValueError as exc:
        raise UsageError(f"parameter {fd.name}: {exc}") from None
    return text


def parse_params(cmd: CommandDef, items: Sequence[str]) -> dict[str, Any]:
    """``name=value`` words to typed parameters of ``cmd``."""
    by_name = {p.name: p for p in cmd.params}
    params: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise UsageError(f"parameter {item!r} is not name=value")
        if name not in by_name:
            known = ", ".join(by_name) or "none"
            raise UsageError(f"{cmd.name} has no parameter {name!r} (parameters: {known})")
        params[name] = _convert(by_name[name], text)
    for p in cmd.params:
        if p.name not in params and not p.optional:
            raise UsageError(f"{cmd.name} needs parameter {p.name}= ({p.type})")
    return params


def _stamp(t: float) -> str:
    return datetime.datetime.fromtimestamp(t, tz=datetime.UTC).strftime("%H:%M:%S.%f")[:-3]


def format_result(result: ParseResult, defs: Definitions) -> str:
    """One line for a received datagram, with limit colours of housekeeping values."""
    if not isinstance(result, Packet):
        return f"REJECTED {result.reason.label}: {result.detail}"
    pdef = defs.telemetry.get(result.kind)
    parts = []
    for fd in pdef.fields if pdef else ():
        value = result.fields.get(fd.name)
        if isinstance(value, bytes):
            shown = value.hex() if len(value) <= 16 else f"{value[:16].hex()}...({len(value)} B)"
        elif isinstance(value, float):
            shown = f"{value:.4g}"
        else:
            shown = str(value)
        colour = fd.limits.classify(value) if fd.limits else None
        unit = f" {fd.unit}" if fd.unit else ""
        parts.append(f"{fd.name}={shown}{unit}" + (f" [{colour.upper()}]" if colour else ""))
    return f"{_stamp(result.time)} {result.kind} #{result.seq_count} " + " ".join(parts)


def _settings(args: argparse.Namespace) -> tuple[Definitions, dict[str, Any]]:
    return load_definitions(args.definitions), load_link_config(args.config)


def _recorder(args: argparse.Namespace, conf: dict[str, Any]) -> Recorder | None:
    if args.no_archive:
        return None
    return Recorder(expand_path(args.archive or conf["gsw"]["archive"]))


def _link(
    args: argparse.Namespace, defs: Definitions, conf: dict[str, Any], bind: tuple[str, int]
) -> GswLink:
    gsw = conf["gsw"]
    key_file = args.key_file or conf["key_file"]
    keyring = KeyRing.load(expand_path(key_file) if key_file else None)
    key_id = args.key_id if args.key_id is not None else conf["key_id"]
    if keyring.get(key_id) is None:
        raise UsageError(f"key id {key_id} is not in the key file (it has {keyring.key_ids})")
    sequencer = CommandSequencer(expand_path(gsw["command_state"]))
    recorder = _recorder(args, conf)
    try:
        return GswLink(
            defs,
            keyring,
            key_id,
            args.crs or (gsw["crs_host"], gsw["crs_port"]),
            bind=bind,
            recorder=recorder,
            close_recorder=True,
            sequencer=sequencer,
            tm_key_overlap_s=gsw["tm_key_overlap_s"],
            accept_from=accepted_sources(gsw, args.crs),
        )
    except BaseException:
        if recorder is not None:
            recorder.close()
        raise


def _cmd_send(args: argparse.Namespace, out) -> int:
    defs, conf = _settings(args)
    try:
        cmd = defs.command(args.command)
    except KeyError as exc:
        raise UsageError(str(exc.args[0])) from None
    return _send(args, out, defs, conf, cmd, parse_params(cmd, args.params))


def _cmd_correct_member(args: argparse.Namespace, out) -> int:
    defs, conf = _settings(args)
    params = {"key": member_key(args.member), "value": args.mark}
    return _send(args, out, defs, conf, defs.command("set_blackboard_value"), params)


def _cmd_correct_dispenser(args: argparse.Namespace, out) -> int:
    defs, conf = _settings(args)
    params = {"key": dispenser_key(args.dispenser), "value": args.count}
    return _send(args, out, defs, conf, defs.command("set_blackboard_value"), params)


def _range(spec: Any) -> str:
    if spec.choices is not None:
        return "one of " + ", ".join(map(str, spec.choices))
    low = "" if spec.minimum is None else f"{spec.minimum:g}"
    high = "" if spec.maximum is None else f"{spec.maximum:g}"
    return f"{low} .. {high}".strip() if low or high else ""


def _cmd_levers(args: argparse.Namespace, out) -> int:
    defs = load_definitions(args.definitions)
    whitelists = load_whitelists()
    print("Set Blackboard Value keys (send set_blackboard_value key=KEY value=TYPE:VALUE):", file=out)
    for agent in AGENTS:
        for spec in whitelists[agent].writable():
            limits = _range(spec)
            units = f" {spec.units}" if spec.units else ""
            print(f"  {agent_key(agent, spec.name):<30} {spec.type:<5} {limits}{units}".rstrip(), file=out)
            print(f"      {spec.meaning}", file=out)
    print("Tower model corrections:", file=out)
    print(
        f"  tower/<member id>              str   one of {', '.join(MEMBER_MARKS)}  (correct-member)", file=out
    )
    print("  dispenser/<name>               int   parts it holds  (correct-dispenser)", file=out)
    print("Set Actuator State (send set_actuator_state actuator=A state=S [value=V] --yes):", file=out)
    for actuator in defs.actuators.values():
        value = (
            f"  value {actuator.value_minimum:g} .. {actuator.value_maximum:g} {actuator.unit}"
            f" with {', '.join(actuator.value_states)}"
            if actuator.value_states
            else ""
        )
        print(f"  {actuator.name:<16} {', '.join(actuator.states)}{value}", file=out)
    return EXIT_OK


def _send(
    args: argparse.Namespace,
    out,
    defs: Definitions,
    conf: dict[str, Any],
    cmd: CommandDef,
    params: dict[str, Any],
) -> int:
    """Send ``cmd`` and, as the options ask, wait for and print its acknowledgements."""
    if cmd.hazardous and not args.yes:
        raise UsageError(f"{cmd.name} is hazardous: add --yes to confirm")
    timeout = args.timeout if args.timeout is not None else conf["gsw"]["ack_timeout_s"]
    with _link(args, defs, conf, args.bind or ("0.0.0.0", 0)) as link:
        try:
            sent = link.send_command(cmd.name, params)
        except FieldError as exc:
            raise UsageError(f"parameter {exc.field}: {exc.detail}") from None
        print(
            f"sent {cmd.name} {params or ''} security_seq={sent.security_seq} seq_count={sent.seq_count}",
            file=out,
        )
        if not (args.wait_ack or args.wait_complete):
            return EXIT_OK
        ack = link.wait_ack(sent, final=False, timeout=timeout)
        if ack is not None and args.wait_complete and not ack.stage.final:
            print(f"{ack.stage.label}", file=out)
            ack = link.wait_ack(sent, final=True, timeout=timeout)
        if ack is None:
            print(f"no acknowledgement within {timeout:g} s", file=out)
            return EXIT_TIMEOUT
        reason = f" reason={ack.reason.label}" if ack.stage in (AckStage.REJECTED, AckStage.FAILED) else ""
        detail = f" ({ack.detail})" if ack.detail else ""
        print(f"{ack.stage.label}{reason}{detail}", file=out)
        return EXIT_REFUSED if ack.stage in (AckStage.REJECTED, AckStage.FAILED) else EXIT_OK


def _cmd_watch(args: argparse.Namespace, out) -> int:
    defs, conf = _settings(args)
    gsw = conf["gsw"]
    bind = args.bind or (gsw["bind_host"], gsw["bind_port"])
    with _link(args, defs, conf, bind) as link:
        print(f"listening on {link.address[0]}:{link.address[1]}", file=out, flush=True)
        deadline = time.monotonic() + args.duration if args.duration else None
        shown = 0
        reported_error: str | None = None
        while (deadline is None or time.monotonic() < deadline) and (not args.count or shown < args.count):
            wait = 0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic()))
            for result in link.poll(wait):
                if args.kind and getattr(result, "kind", None) not in args.kind:
                    continue
                print(format_result(result, defs), file=out, flush=True)
                shown += 1
                if args.count and shown >= args.count:
                    break
            error = link.recorder.last_error if link.recorder is not None else None
            if error != reported_error:
                print(error or "archive writable again", file=out, flush=True)
                reported_error = error
        stats = link.stats
        print(
            f"received {stats.packets_rx} packet(s), {stats.bytes_rx} B, gaps {stats.gaps} "
            f"(missing {stats.missing}), CRC errors {stats.crc_errors}, rejected {stats.rejections} "
            f"(failed authentication {stats.auth_rejections}, not a configured source "
            f"{stats.source_rejections})",
            file=out,
        )
    return EXIT_OK


def _archive_path(args: argparse.Namespace) -> Path:
    if args.archive:
        return expand_path(args.archive)
    return expand_path(load_link_config(args.config)["gsw"]["archive"])


def _cmd_query(args: argparse.Namespace, out) -> int:
    conn = archive_query.open_archive(_archive_path(args))
    try:
        if args.counts:
            for direction, kind, status, number in archive_query.counts(conn):
                print(f"{direction} {kind:<22} {status:<20} {number}", file=out)
            return EXIT_OK
        if args.series:
            kind, _, name = args.series.partition(".")
            for t, value in archive_query.field_series(
                conn, kind, name, since=args.since, until=args.until, limit=args.limit
            ):
                print(f"{t:.3f} {value}", file=out)
            return EXIT_OK
        rows = archive_query.packets(
            conn, kind=args.kind, status=args.status, since=args.since, until=args.until, limit=args.limit
        )
        for row in reversed(rows):
            line = (
                f"{row.id} {row.direction} {_stamp(row.recorded_at)} apid={row.apid} seq={row.seq_count} "
                f"{row.kind or '-'} {row.status}"
            )
            if row.detail:
                line += f" ({row.detail})"
            if args.fields and row.status == "ok":
                line += " " + " ".join(
                    f"{k}={v}" for k, v in archive_query.packet_fields(conn, row.id).items()
                )
            if args.hex:
                line += f"\n    {row.raw.hex(' ')}"
            print(line, file=out)
        return EXIT_OK
    finally:
        conn.close()


def _cmd_export(args: argparse.Namespace, out) -> int:
    conn = archive_query.open_archive(_archive_path(args))
    fields = args.fields.split(",") if args.fields else None
    try:
        if args.output and args.output != "-":
            with open(args.output, "w", newline="", encoding="utf-8") as handle:
                rows = archive_query.export_csv(
                    conn, handle, args.kind, fields=fields, since=args.since, until=args.until
                )
            print(f"wrote {rows} row(s) to {args.output}", file=sys.stderr)
        else:
            archive_query.export_csv(conn, out, args.kind, fields=fields, since=args.since, until=args.until)
    finally:
        conn.close()
    return EXIT_OK


def _cmd_keygen(args: argparse.Namespace, out) -> int:
    path = expand_path(args.path)
    if args.add_tm_key:
        ring = KeyRing.load(path)
        tm = ring.telemetry
        new_id = max(tm.key_ids, default=0) + 1
        tm_keys = {k: key for k in tm.key_ids if (key := tm.get(k)) is not None}
        commands = {k: key for k in ring.key_ids if (key := ring.get(k)) is not None}
        write_key_file(path, commands, {**tm_keys, new_id: os.urandom(32)})
        print(
            f"added telemetry key id {new_id} to {path}; copy the file to the CRS over a secure channel, "
            "then send switch_tm_key (docs/ground-link.md, key rotation)",
            file=out,
        )
        return EXIT_OK
    if path.exists() and not args.force:
        raise UsageError(
            f"{path} exists; add --force to replace it (every CRS and GSW using it needs the new key)"
        )
    tm_ids = args.tm_key_ids
    write_key_file(path, {args.key_id: os.urandom(32)}, {k: os.urandom(32) for k in tm_ids})
    print(
        f"wrote a 32-byte command key with id {args.key_id} and telemetry keys with ids "
        f"{', '.join(map(str, tm_ids))} to {path} (mode 0600); copy it to the CRS over a secure "
        "channel and point key_file (or $TLT_GROUND_KEY_FILE) at it on both ends",
        file=out,
    )
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tlt gsw", description="TLT ground station (headless).")
    parser.add_argument("--config", help="link settings YAML (default config/ccsds/link.yaml)")
    parser.add_argument("--definitions", help="command/telemetry definitions YAML")
    sub = parser.add_subparsers(dest="action", required=True)

    def link_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("--crs", type=host_port, help="CRS host:port")
        p.add_argument("--bind", type=host_port, help="local host:port to receive on")
        p.add_argument("--key-file", help="key file (default: link.yaml key_file or $TLT_GROUND_KEY_FILE)")
        p.add_argument("--key-id", type=int)
        p.add_argument("--archive", help="archive SQLite file")
        p.add_argument("--no-archive", action="store_true", help="do not record")

    def send_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("--wait-ack", action="store_true", help="wait for accepted/rejected")
        p.add_argument("--wait-complete", action="store_true", help="wait for completed/failed")
        p.add_argument("--timeout", type=float, help="seconds to wait for each ack")
        p.add_argument(
            "--yes", action="store_true", help="confirm a hazardous command (stop, set_actuator_state)"
        )
        link_options(p)

    send = sub.add_parser("send", help="send a command")
    send.add_argument("command", help="start, stop, pause, resume, set_blackboard_value, set_actuator_state")
    send.add_argument("params", nargs="*", help="name=value parameters (value=int:3, value=str:abc, ...)")
    send_options(send)

    member = sub.add_parser("correct-member", help="correct a member's state in the CRS's tower model")
    member.add_argument("member", help="member id, e.g. bay1/vertical/x0_y1")
    member.add_argument("mark", choices=MEMBER_MARKS)
    send_options(member)
    dispenser = sub.add_parser("correct-dispenser", help="correct the parts a dispenser holds")
    dispenser.add_argument("dispenser", help="dispenser name, e.g. vertical_dispenser_x")
    dispenser.add_argument("count", type=int, help="parts it holds")
    send_options(dispenser)
    sub.add_parser("levers", help="list the writable keys, tower corrections and actuator states")

    watch = sub.add_parser("watch", help="print telemetry as it arrives (and record it)")
    watch.add_argument("--duration", type=float, help="stop after this many seconds")
    watch.add_argument("--count", type=int, help="stop after this many packets")
    watch.add_argument("--kind", action="append", help="only this packet kind (repeatable)")
    link_options(watch)

    def archive_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("--archive", help="archive SQLite file")
        p.add_argument("--since", type=float, help="Unix time")
        p.add_argument("--until", type=float, help="Unix time")

    q = sub.add_parser("query", help="query the archive")
    archive_options(q)
    q.add_argument("--kind")
    q.add_argument("--status", help="ok or a rejection reason")
    q.add_argument("--limit", type=int, default=20)
    q.add_argument("--fields", action="store_true", help="show decoded fields")
    q.add_argument("--hex", action="store_true", help="show raw bytes")
    q.add_argument("--counts", action="store_true", help="totals by direction, kind and status")
    q.add_argument("--series", metavar="KIND.FIELD", help="one field over time")

    k = sub.add_parser("keygen", help="create a shared key file (outside the repository)")
    k.add_argument("path", help="key file to write, e.g. ~/.config/tlt/ground.key")
    k.add_argument("--key-id", type=int, default=1, help="command key id")
    k.add_argument(
        "--tm-key-ids",
        type=lambda text: sorted({int(part) for part in text.split(",")}),
        default=[1, 2],
        help="telemetry key ids, comma separated (the CRS starts on link.yaml tm_key_id and "
        "switch_tm_key moves it to the next)",
    )
    k.add_argument("--force", action="store_true", help="replace an existing file")
    k.add_argument(
        "--add-tm-key",
        action="store_true",
        help="add a telemetry key with the next id to an existing file (key rotation), keeping its keys",
    )

    e = sub.add_parser("export", help="export one packet kind's fields to CSV")
    archive_options(e)
    e.add_argument("--kind", required=True)
    e.add_argument("--fields", help="comma-separated field names (default: all)")
    e.add_argument("-o", "--output", help="CSV file (default: standard output)")

    add_mission_parser(sub)
    add_summary_parser(sub)
    return parser


_ACTIONS = {
    "send": _cmd_send,
    "watch": _cmd_watch,
    "query": _cmd_query,
    "export": _cmd_export,
    "keygen": _cmd_keygen,
    "levers": _cmd_levers,
    "correct-member": _cmd_correct_member,
    "correct-dispenser": _cmd_correct_dispenser,
}


def main(argv: list[str] | None = None, out=None) -> int:
    """Entry point of ``tlt gsw``; returns the exit status."""
    out = out or sys.stdout
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["gui"]:
        # Qt is loaded only for the GUI, so the CLI stays light on a headless ground station.
        from tlt_gsw.gui.app import main as gui_main

        return gui_main(argv[1:])
    args = build_parser().parse_args(argv)
    if args.action in MISSION_ACTIONS:
        # The mission job handles Ctrl-C itself (exit 130, after printing the summary).
        return run_mission_action(args, out)
    try:
        return _ACTIONS[args.action](args, out)
    except (
        UsageError,
        ConfigError,
        KeyFileError,
        ReplayStateError,
        archive_query.ArchiveError,
        OSError,
    ) as exc:
        print(f"tlt gsw {args.action}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
