"""GSW GUI refresh at 10 Hz while 2,000 packets/s are ingested into the archive (issue 7 goal:
no growing lag).

A sender process plays a CRS: it sends a housekeeping-heavy mix of real telemetry packets (lifter,
grippers, both end effectors and arms, the CRS tree status, mission progress, tower model, link
stats, events) over loopback UDP at ``--rate`` packets/s. The GUI runs as ``tlt gsw gui`` does,
offscreen: the link process (GswLink + Recorder) receives into the SQLite archive, the main window
refreshes on its QTimer at ``--refresh-hz`` and reads the archive, cycling through every tab so
each view is redrawn. Printed per window of the run:

* refresh time p50/p99 (ms): one timer tick, archive queries and redraw;
* lag p50/p99 (s): newest packet recorded in the DB minus newest packet shown, sampled right
  after each refresh, i.e. how far the display trails the archive;
* age (s): wall clock minus the newest packet shown (adds the recorder's batching delay).

A lag whose p99 does not rise from window to window is the goal. Run:
``python bench/gsw_gui_refresh.py [--seconds 30] [--rate 2000] [--refresh-hz 10]``.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import socket
import sqlite3
import statistics
import sys
import tempfile
import time
from pathlib import Path

from tlt_common.bt.status_codec import TreeShape, encode
from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.sequence import SequenceCounters
from tlt_common.ccsds.tm_security import TelemetrySigner
from tlt_gsw.gui.demo_archive import demo_tree, set_demo_statuses
from tlt_gsw.gui.tower_layout import pack_member_states


def packet_mix(defs) -> list[tuple[str, dict]]:
    """One cycle of packets (kinds and values) in the proportions of a busy link."""
    shape = TreeShape.of(demo_tree())
    set_demo_statuses(shape, 1)
    (part,) = encode(shape, agent="crs", tick_count=1)
    tree = {
        "agent": "crs", "shape_hash": part.shape_hash, "tick": 1, "node_count": part.node_count,
        "part_index": 0, "part_count": 1, "first_node": 0, "status": part.status,
    }  # fmt: skip
    lifter = {
        "state": "crs_control", "position_0": 0.5, "position_1": 0.5, "position_2": 0.5, "position_3": 0.5,
        "velocity": 100, "limit_switches": 0, "watchdog_tripped": False, "link_ok": True,
    }  # fmt: skip
    grippers = {
        "top_engaged": 15, "top_position_mean": 0.027, "top_fault": False, "active_engaged": 3,
        "active_height": 0.3, "active_fault": False,
    }  # fmt: skip
    ee = {
        "grasp_left": 0.4, "grasp_right": 0.4, "width": 0.05, "max_load": 0.2, "calibrated": True,
        "part_grasped": False, "rivet_guns": 3, "fault": False,
    }  # fmt: skip
    arm = {"q0": 0.1, "q1": -1.2, "q2": 1.5, "q3": -1.8, "q4": -1.57, "q5": 0.0, "protective_stop": False}
    mission = {
        "run_state": "running", "started": True, "bays_total": 2, "bays_built": 1, "current_bay": 2,
        "members_total": 22, "members_placed": 10, "members_riveted": 8, "current_step": "bench", "fault": "",
    }  # fmt: skip
    stats = {f.name: 0 for f in defs.packet("link_stats").fields}
    event = {"severity": "info", "source": "bench", "code": "TICK", "reason": "none", "text": "bench event"}
    mix = [("hk_lifter", lifter), ("hk_grippers", grippers), ("tree_status", tree)]
    for ars in ("ars_x", "ars_y"):
        mix += [("hk_ee", {"ars": ars, **ee}), ("hk_arm_joints", {"ars": ars, **arm})]
    mix = mix * 6 + [
        ("hk_mission", mission),
        ("hk_tower", {"member_count": 22, "member_states": pack_member_states([2] * 9 + [1] + [0] * 12)}),
        ("link_stats", stats),
        ("event", event),
    ]
    return mix


def sender(address: tuple[str, int], key_file: str, rate: float, seconds: float, sent_count) -> None:
    """The CRS stand-in: real telemetry datagrams at ``rate`` per second, in 10 ms bursts."""
    defs = load_definitions()
    mix = packet_mix(defs)
    counters = SequenceCounters()
    signer = TelemetrySigner(KeyRing.load(key_file).telemetry, 1)  # signed as the CRS signs
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    start = time.monotonic()
    sent = 0
    i = 0
    while True:
        elapsed = time.monotonic() - start
        if elapsed >= seconds:
            break
        due = int(elapsed * rate)
        while sent < due:
            kind, values = mix[i % len(mix)]
            i += 1
            if kind == "tree_status":  # the CRS sends each tick's status once, ticks counting up
                values = {**values, "tick": i}
            raw = signer.encode(
                defs, kind, values, seq_count=counters.next(defs.packet(kind).apid), timestamp=time.time()
            )
            sock.sendto(raw, address)
            sent += 1
        time.sleep(0.01)
    sent_count.value = sent


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--rate", type=float, default=2000.0, help="packets/s ingested")
    parser.add_argument("--refresh-hz", type=float, default=10.0)
    parser.add_argument("--window", type=float, default=5.0, help="seconds per printed row")
    args = parser.parse_args(argv)
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6 import QtCore, QtWidgets

    from tlt_gsw.archive.query import open_archive
    from tlt_gsw.gui.archive_model import ArchiveModel
    from tlt_gsw.gui.config import load_gui_config
    from tlt_gsw.gui.link_process import LinkProcess, LinkSettings
    from tlt_gsw.gui.main_window import TABS, MainWindow
    from tlt_gsw.gui.qt_check import binding_problem

    problem = binding_problem()
    if problem:
        print(problem, file=sys.stderr)
        return 2
    defs = load_definitions()
    conf = load_gui_config(None, defs).with_options(refresh_hz=args.refresh_hz)
    folder = Path(tempfile.mkdtemp(prefix="gsw-gui-bench-"))
    archive = folder / "archive.sqlite"
    key_file = write_key_file(folder / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    link = LinkProcess(
        LinkSettings(
            definitions=None, key_file=str(key_file), key_id=1, crs_address=("127.0.0.1", 9),
            bind=("127.0.0.1", 0), archive=str(archive), command_state=None,
            flush_interval_s=conf.recorder_flush_s,
        )
    ).start()  # fmt: skip
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(["bench"])
    conn = open_archive(archive)
    model = ArchiveModel(
        conn, defs, shapes={"crs": TreeShape.of(demo_tree())}, plot_fields=conf.plot_fields,
        packet_rows=conf.packet_rows, event_rows=conf.event_rows, plot_window_s=conf.plot_window_s,
    )  # fmt: skip
    window = MainWindow(
        model,
        conf,
        archive_path=archive,
        sender=link.submit,
        archive_health=link.health,
        on_refresh=link.poll,
    )
    window.show()
    probe = sqlite3.connect(f"{archive.resolve().as_uri()}?mode=ro", uri=True)
    samples: list[tuple[float, float, float, float]] = []  # (run time, refresh s, lag s, age s)
    started = time.monotonic()

    def sample() -> None:
        newest_db = probe.execute("SELECT MAX(recorded_at) FROM packets").fetchone()[0]
        shown = model.position_time
        if newest_db is None or shown is None or not window.refresh_seconds:
            return
        samples.append(
            (time.monotonic() - started, window.refresh_seconds[-1], newest_db - shown, time.time() - shown)
        )
        tab = TABS[int(time.monotonic() - started) % len(TABS)]  # every view gets redrawn
        if window.current_tab() != tab:
            window.show_tab(tab)

    window.timer.timeout.connect(sample)
    sent_count = multiprocessing.Value("q", 0)
    proc = multiprocessing.Process(
        target=sender, args=(link.address, str(key_file), args.rate, args.seconds, sent_count)
    )
    proc.start()
    window.start()
    QtCore.QTimer.singleShot(int((args.seconds + 1.5) * 1000), app.quit)
    app.exec()
    window.timer.stop()
    proc.join(10)
    time.sleep(0.5)  # the link process commits its last batch
    link.close()
    window.refresh()
    archived = probe.execute("SELECT COUNT(*) FROM packets WHERE status = 'ok'").fetchone()[0]

    print(f"GUI refresh at {args.refresh_hz:g} Hz, ingesting {args.rate:g} packets/s for {args.seconds:g} s")
    print(
        "(sender process -> loopback UDP -> link process -> SQLite archive -> GUI queries; "
        f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the end)"
    )
    print(f"{'window s':>10} {'refreshes':>9} {'refresh p50 ms':>15} {'p99 ms':>8} {'lag p50 s':>10} "
          f"{'lag p99 s':>10} {'age p50 s':>10}")  # fmt: skip
    edge = 0.0
    while edge < args.seconds:
        rows = [s for s in samples if edge <= s[0] < edge + args.window]
        if rows:
            ref = [r[1] * 1000 for r in rows]
            lag = [r[2] for r in rows]
            age = [r[3] for r in rows]
            print(
                f"{edge:>4.0f}-{edge + args.window:<5.0f} {len(rows):>9} {pct(ref, 0.5):>15.1f} "
                f"{pct(ref, 0.99):>8.1f} {pct(lag, 0.5):>10.3f} {pct(lag, 0.99):>10.3f} "
                f"{pct(age, 0.5):>10.3f}"
            )
        edge += args.window
    ref = [s[1] * 1000 for s in samples]
    lag = [s[2] for s in samples]
    half = len(lag) // 2
    print(
        f"all: {len(samples)} refreshes ({len(samples) / max(args.seconds, 1e-9):.1f}/s), refresh p50 "
        f"{pct(ref, 0.5):.1f} ms p99 {pct(ref, 0.99):.1f} ms; lag p50 {pct(lag, 0.5):.3f} s "
        f"p99 {pct(lag, 0.99):.3f} s"
    )
    if half:
        first, second = statistics.median(lag[:half]), statistics.median(lag[half:])
        trend = "grows" if second > 2 * first + 0.05 else "does not grow"
        print(f"lag median first half {first:.3f} s, second half {second:.3f} s: lag {trend}")
    print(
        f"packets: sent {sent_count.value}, archived {archived} (lost {sent_count.value - archived}), "
        f"shown up to packet {model.position}"
    )
    probe.close()
    conn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
