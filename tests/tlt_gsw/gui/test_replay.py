"""Replay of an archive into the GUI: read-only, scrub, step, play."""

from __future__ import annotations

import hashlib
import itertools

import pytest
from PySide6 import QtCore
from PySide6.QtTest import QTest

from tlt_common.ccsds.definitions import load_definitions
from tlt_gsw.archive.query import open_archive
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.config import GuiConfig
from tlt_gsw.gui.main_window import MainWindow
from tlt_gsw.gui.tree_definitions import load_tree_definition

DEFS = load_definitions()
LEFT = QtCore.Qt.MouseButton.LeftButton


@pytest.fixture
def replay(qapp, demo):
    archive, definition = demo
    before = hashlib.sha256(archive.path.read_bytes()).hexdigest()
    conn = open_archive(archive.path)
    model = ArchiveModel(conn, DEFS, shapes={"crs": load_tree_definition(definition)})
    window = MainWindow(model, GuiConfig(), archive_path=archive.path, replay=True)
    window.show()
    yield window, archive
    window.close()
    conn.close()
    assert hashlib.sha256(archive.path.read_bytes()).hexdigest() == before  # replay never writes


def test_replay_disables_commands_and_starts_where_asked(replay):
    window, archive = replay
    assert not window.command_panel.buttons["start"].isEnabled()
    assert "replay" in window.command_panel.status.text()
    window.seek(archive.packets)
    assert window.model.position == archive.packets
    assert window.replay_bar.slider.value() == archive.packets
    assert f"packet {archive.packets} of {archive.packets}" in window.replay_bar.position.text()


def test_scrub_and_step_show_the_archive_as_of_that_packet(replay):
    window, archive = replay
    window.seek(archive.packets)
    rejected_at = next(
        r for r in window.model.commands.values() if r.name == "set_blackboard_value"
    ).packet_id
    window.seek(rejected_at - 1)  # back: a rebuild
    assert "set_blackboard_value" not in {row[1] for row in window.command_history.row_texts()}
    QTest.mouseClick(window.replay_bar.buttons["forward"], LEFT)  # one packet forward: the command
    assert window.model.position == rejected_at
    assert window.command_history.row_texts()[0][1:3] == ["set_blackboard_value", "sent"]
    QTest.mouseClick(window.replay_bar.buttons["back"], LEFT)
    assert window.model.position == rejected_at - 1
    window.replay_bar.slider.setValue(rejected_at + 3)  # keyboard-like move: seeks at once
    assert window.model.position == rejected_at + 3
    QTest.mouseClick(window.replay_bar.buttons["start"], LEFT)
    assert window.model.position == window.model.first() and window.command_history.rowCount() == 0


def test_play_runs_through_the_archive_at_speed(replay):
    window, archive = replay
    clock = [0.0]
    window.monotonic = lambda: clock[0]  # one refresh = one second of wall time
    window.seek(archive.packets)
    window.replay_bar.speed.setCurrentText("2×")
    QTest.mouseClick(window.replay_bar.buttons["play"], LEFT)  # at the end: starts over
    assert window.replay_bar.playing and window.model.position <= 2
    times = []
    for _ in range(40):
        clock[0] += 1.0
        window.refresh()
        times.append(window.model.position_time)
        if not window.replay_bar.playing:
            break
    assert window.model.position == archive.packets and not window.replay_bar.playing
    steps = [b - a for a, b in itertools.pairwise(times[:-1])]  # the last step ends at the archive's end
    assert len(times) >= 20 and all(1.5 <= s <= 2.5 for s in steps), steps  # 2 s of archive per second
    stages = {row[1]: row[2] for row in window.command_history.row_texts()}
    assert stages["start"] == "sent → accepted → completed"


def test_an_unreadable_archive_is_reported_and_recovered(replay):
    window, archive = replay
    window.monotonic = lambda: 0.0  # playing, but the replay clock stands still
    window.seek(archive.packets // 2)
    window.replay_bar.set_playing(True)
    shown = list(window.model.packets)
    window.model.conn.close()  # stands for a read that fails (locked, disk error)
    window.refresh()
    assert (
        window.read_error is not None and "ARCHIVE READ ERROR" in window.link_status.values["archive"].text()
    )
    window.model.conn = open_archive(archive.path)
    window.refresh()  # rebuilt at the same position, nothing counted twice
    assert window.read_error is None and list(window.model.packets) == shown
    assert (
        window.model.link_figures().packets_rx + window.model.link_figures().packets_tx
        == archive.packets // 2
    )


def test_packet_view_selections_are_archive_queries(replay):
    window, archive = replay
    window.seek(archive.packets)
    window.show_tab("packets")
    view = window.packet_view
    view.selection.setCurrentIndex(view.selection.findData("rejected"))
    rows = view.table_model.rows
    assert [(r.status, r.direction) for r in rows] == [("bad_crc", "rx")]
    assert "status bad_crc" in view.detail.toPlainText()  # the newest of the selection is shown
    view.selection.setCurrentIndex(view.selection.findData("tx"))
    assert [r.kind for r in view.table_model.rows] == [
        "start", "pause", "resume", "set_blackboard_value", "set_actuator_state",
    ]  # fmt: skip
    view.selection.setCurrentIndex(view.selection.findData("hk_tower"))
    assert len(view.table_model.rows) == 41 and {r.kind for r in view.table_model.rows} == {"hk_tower"}
    middle = archive.packets // 2
    window.seek(middle)  # a selection follows the replay position
    query = "SELECT id FROM packets WHERE kind = 'hk_tower' AND id <= ?"
    expected = [i for (i,) in window.model.conn.execute(query, (middle,))]
    assert [r.id for r in view.table_model.rows] == expected and 15 < len(expected) < 26


def test_export_csv_of_the_shown_kind_up_to_the_position(replay, tmp_path):
    window, archive = replay
    middle = archive.packets // 2
    window.seek(middle)
    pages = window.housekeeping
    pages.setCurrentWidget(pages.pages["hk_lifter"])
    text = pages.export(pages.current_kind(), tmp_path / "lifter.csv")
    lines = (tmp_path / "lifter.csv").read_text().splitlines()
    expected = window.model.conn.execute(
        "SELECT COUNT(*) FROM packets WHERE kind = 'hk_lifter' AND id <= ?", (middle,)
    ).fetchone()[0]
    assert text == f"wrote {expected} hk_lifter packet(s) to {tmp_path / 'lifter.csv'}"
    assert len(lines) == expected + 1 and lines[0].startswith("time,recorded_at,seq_count,state,position_0")
    assert "failed" in pages.export("hk_lifter", tmp_path / "no" / "such" / "dir.csv")
