"""``tlt gsw gui``: the ground station's Qt GUI, live on the link or replaying an archive.

Live (default): a link process receives the CRS's telemetry on the GSW port of
``config/ccsds/link.yaml`` into the archive and sends the operator's commands; the window reads
the archive on a timer. Without a key file (``key_file``, ``--key-file`` or
``$TLT_GROUND_KEY_FILE``) the GUI only monitors: the command panel is disabled.

Replay (``--replay ARCHIVE``): the archive is opened read-only and can be scrubbed, stepped and
played; nothing is sent or written.

``--screenshot OUT.png`` saves the window after ``--screenshot-after`` refreshes and exits (for
docs; headless it uses Qt's offscreen platform). Exit status: 0, or 2 for bad configuration, key
or archive.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from tlt_common.ccsds.auth import KeyFileError, KeyRing, ReplayStateError
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.link_config import expand_path, load_link_config
from tlt_common.config_schema import ConfigError
from tlt_gsw.archive.query import ArchiveError, open_archive
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.config import GuiConfig, load_gui_config, parse_plot_field
from tlt_gsw.gui.link_process import LinkProcess, LinkSettings, LinkStartError
from tlt_gsw.gui.main_window import TABS, MainWindow
from tlt_gsw.gui.tower_layout import load_layout_mission
from tlt_gsw.gui.tree_definitions import TreeDefinitionFiles
from tlt_gsw.link import accepted_sources, host_port

EXIT_OK, EXIT_USAGE = 0, 2


def _size(text: str) -> tuple[int, int]:
    width, _, height = text.partition("x")
    if not (width.isdigit() and height.isdigit()):
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}")
    return int(width), int(height)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tlt gsw gui", description="TLT ground station GUI.")
    parser.add_argument("--config", help="link settings YAML (default config/ccsds/link.yaml)")
    parser.add_argument("--definitions", help="command/telemetry definitions YAML")
    parser.add_argument("--gui-config", help="GUI settings YAML (default config/gsw/gui.yaml)")
    parser.add_argument("--replay", metavar="ARCHIVE", help="replay this archive read-only")
    parser.add_argument("--position", default="end", help="replay: start, end or a packet id (default end)")
    parser.add_argument("--play", action="store_true", help="replay: start playing at once")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed factor (default 1)")
    parser.add_argument("--archive", help="live: archive SQLite file (default from link.yaml)")
    parser.add_argument("--crs", type=host_port, help="live: CRS host:port")
    parser.add_argument("--bind", type=host_port, help="live: local host:port to receive telemetry on")
    parser.add_argument(
        "--key-file", help="live: key file (default link.yaml key_file or $TLT_GROUND_KEY_FILE)"
    )
    parser.add_argument("--key-id", type=int)
    parser.add_argument("--mission", help="mission file of the tower view")
    parser.add_argument(
        "--tree", action="append", default=[], metavar="AGENT=FILE", help="tree definition JSON"
    )
    parser.add_argument("--plot", action="append", default=[], metavar="KIND.FIELD", help="plot this field")
    parser.add_argument("--refresh-hz", type=float, help="display refreshes per second")
    parser.add_argument("--tab", choices=TABS, default="housekeeping", help="tab shown first")
    parser.add_argument("--size", type=_size, help="window size WIDTHxHEIGHT")
    parser.add_argument("--screenshot", metavar="PNG", help="save the window after some refreshes and exit")
    parser.add_argument("--screenshot-after", type=int, default=5, metavar="N", help="refreshes first (5)")
    return parser


def _gui_config(args: argparse.Namespace, defs) -> GuiConfig:
    conf = load_gui_config(args.gui_config, defs)
    trees = dict(conf.tree_definitions)
    for item in args.tree:
        agent, sep, path = item.partition("=")
        if not sep or not agent or not path:
            raise ConfigError("--tree", "", f"expected AGENT=FILE, got {item!r}")
        trees[agent] = Path(path)
    changes: dict = {"tree_definitions": trees}
    if args.plot:
        changes["plot_fields"] = conf.plot_fields + tuple(
            parse_plot_field(text, defs, "--plot") for text in args.plot
        )
    if args.refresh_hz:
        if not 0.2 <= args.refresh_hz <= 100:
            raise ConfigError("--refresh-hz", "", "expected 0.2 .. 100")
        changes["refresh_hz"] = args.refresh_hz
    if args.mission:
        changes["mission"] = Path(args.mission)
    return conf.with_options(**changes)


def _model(conn, defs, conf: GuiConfig, shapes, definition_files) -> ArchiveModel:
    return ArchiveModel(
        conn,
        defs,
        shapes=shapes,
        definition_files=definition_files,
        plot_fields=conf.plot_fields,
        packet_rows=conf.packet_rows,
        event_rows=conf.event_rows,
        command_rows=conf.command_rows,
        plot_window_s=conf.plot_window_s,
        rate_window_s=conf.rate_window_s,
        max_rows_per_refresh=conf.max_rows_per_refresh,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``tlt gsw gui``; returns the exit status."""
    args = build_parser().parse_args(argv)
    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if args.screenshot and headless:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    link = None
    conn = None
    try:
        defs = load_definitions(args.definitions)
        conf = _gui_config(args, defs)
        definition_files = TreeDefinitionFiles(conf.tree_definitions)
        # A file named on the command line must be there; one from the config may appear later.
        required = {item.partition("=")[0] for item in args.tree}
        shapes = definition_files.load_present(required)
        mission = load_layout_mission(conf.mission)
        from PySide6 import QtCore, QtWidgets

        from tlt_gsw.gui.qt_check import binding_problem

        problem = binding_problem()
        if problem is not None:
            print(f"tlt gsw gui: {problem}", file=sys.stderr)
            return EXIT_USAGE

        app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
        if args.replay:
            archive = Path(args.replay)
            conn = open_archive(archive)
            model = _model(conn, defs, conf, shapes, definition_files)
            window = MainWindow(model, conf, archive_path=archive, mission=mission, replay=True)
            head = model.head()
            target = {"start": model.first(), "end": head}.get(args.position)
            if target is None:
                if not args.position.isdigit():
                    raise ConfigError("--position", "", "expected start, end or a packet id")
                target = int(args.position)
            window.seek(target)
            if window.replay_bar is not None:
                speed = window.replay_bar.speed
                index = speed.findData(args.speed)
                if index < 0:
                    speed.addItem(f"{args.speed:g}×", args.speed)
                    index = speed.count() - 1
                speed.setCurrentIndex(index)
                if args.play:
                    window.replay_bar.buttons["play"].click()
        else:
            link_conf = load_link_config(args.config)
            gsw = link_conf["gsw"]
            archive = expand_path(args.archive or gsw["archive"])
            key_file = args.key_file or link_conf["key_file"] or os.environ.get("TLT_GROUND_KEY_FILE")
            key_id = args.key_id if args.key_id is not None else link_conf["key_id"]
            disabled = ""
            if key_file:
                keyring = KeyRing.load(expand_path(key_file))  # refuse a bad key file before starting
                if keyring.get(key_id) is None:
                    raise KeyFileError(f"key id {key_id} is not in {key_file} (it has {keyring.key_ids})")
            else:
                disabled = (
                    "monitor only: no key file (key_file in link.yaml, --key-file or $TLT_GROUND_KEY_FILE)"
                )
            link = LinkProcess(
                LinkSettings(
                    definitions=args.definitions,
                    key_file=str(expand_path(key_file)) if key_file else None,
                    key_id=key_id,
                    crs_address=args.crs or (gsw["crs_host"], gsw["crs_port"]),
                    bind=args.bind or (gsw["bind_host"], gsw["bind_port"]),
                    archive=str(archive),
                    command_state=str(expand_path(gsw["command_state"])),
                    flush_interval_s=conf.recorder_flush_s,
                    tm_key_overlap_s=gsw["tm_key_overlap_s"],
                    accept_from=accepted_sources(gsw, args.crs),
                )
            ).start()
            conn = open_archive(archive)
            model = _model(conn, defs, conf, shapes, definition_files)
            window = MainWindow(
                model,
                conf,
                archive_path=archive,
                sender=None if disabled else link.submit,
                disabled_reason=disabled,
                mission=mission,
                archive_health=link.health,
                on_refresh=link.poll,
            )
            window.seek(model.head())
        if args.size:
            window.resize(*args.size)
        window.show_tab(args.tab)
        window.show()
        window.start()
        if args.screenshot:
            shot = Path(args.screenshot)

            def maybe_shoot() -> None:
                if window.refresh_count >= args.screenshot_after:
                    window.timer.stop()
                    window.show_tab(args.tab)
                    app.processEvents()
                    window.save_screenshot(shot)
                    print(f"wrote {shot}")
                    app.quit()

            window.timer.timeout.connect(maybe_shoot)
            QtCore.QTimer.singleShot(120_000, app.quit)  # never hang a docs build
        app.exec()
        window.timer.stop()
        window.close()
        return EXIT_OK
    except (ConfigError, KeyFileError, ReplayStateError, ArchiveError, LinkStartError, OSError) as exc:
        print(f"tlt gsw gui: {exc}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        if link is not None:
            link.close()
        if conn is not None:
            conn.close()


if __name__ == "__main__":
    sys.exit(main())
