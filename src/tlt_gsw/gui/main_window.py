"""The GSW main window: every display is a query on the archive, refreshed on a timer (Fig. 6).

The window never receives or records packets itself: in live mode the link runs in its own process
(:mod:`tlt_gsw.gui.link_process`) and this window reads what it committed.

Layout: the link status strip on top; on the left the command panel above the command history;
on the right tabs for housekeeping, plots, behaviour trees, the tower and packets, above the limit
alarms (:mod:`~tlt_gsw.gui.limit_alarms`) and the event log; in replay mode the replay bar at the
bottom.

Each refresh (a :class:`QTimer` at ``refresh_hz``) moves the :class:`ArchiveModel`: live, to the
newest packet the link thread committed; in replay, along the archive at the chosen speed. Only
what changed is redrawn, and a hidden tab is redrawn when it is shown. :attr:`refresh_seconds`
keeps the duration of the recent refreshes (the benchmark reads it).
"""

from __future__ import annotations

import sqlite3
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from tlt_common.mission.schema import Mission
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.archive_records import Changes
from tlt_gsw.gui.command_history import CommandHistory
from tlt_gsw.gui.command_panel import CommandPanel, Sender
from tlt_gsw.gui.config import GuiConfig
from tlt_gsw.gui.event_log import EventLog
from tlt_gsw.gui.housekeeping import HousekeepingPages
from tlt_gsw.gui.limit_alarms import LimitAlarmPanel
from tlt_gsw.gui.link_status import LinkStatusPanel
from tlt_gsw.gui.packet_view import PacketView
from tlt_gsw.gui.plots import PlotsPage
from tlt_gsw.gui.replay_bar import ReplayBar
from tlt_gsw.gui.tower_view import TowerView
from tlt_gsw.gui.tree_view import TreeStatusView

TABS = ("housekeeping", "plots", "tree", "tower", "packets")
TAB_TITLES = {
    "housekeeping": "Housekeeping",
    "plots": "Plots",
    "tree": "Behaviour trees",
    "tower": "Tower",
    "packets": "Packets",
}


class MainWindow(QtWidgets.QMainWindow):
    """The ground station window; ``replay`` selects replay mode (no commands, replay bar)."""

    def __init__(
        self,
        model: ArchiveModel,
        config: GuiConfig,
        *,
        archive_path: Path,
        sender: Sender | None = None,
        disabled_reason: str = "",
        mission: Mission | None = None,
        replay: bool = False,
        archive_health: Callable[[], tuple[str, bool]] | None = None,
        on_refresh: Callable[[], None] | None = None,
        clock: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.model = model
        self.config = config
        self.replay = replay
        self.clock = clock  # wall clock: ages of live packets
        self.monotonic = monotonic  # paces replay (tests step it by hand)
        self.archive_path = archive_path
        self.archive_health = archive_health
        self.on_refresh = on_refresh  # e.g. LinkProcess.poll: command outcomes, archive health
        self.read_error: str | None = None
        self.refresh_count = 0
        self.refresh_seconds: deque[float] = deque(maxlen=10000)
        self.replay_time: float | None = None
        self._last_tick = monotonic()
        self._dirty: set[str] = set()
        self._dirty_kinds: set[str] = set()
        self._dirty_trees: set[str] = set()
        self._dirty_series: set[tuple[str, str]] = set()
        self.setWindowTitle(f"TLT ground station: {'replay of' if replay else 'live,'} {archive_path}")

        central = QtWidgets.QWidget()
        outer = QtWidgets.QVBoxLayout(central)
        outer.setContentsMargins(4, 4, 4, 4)
        self.link_status = LinkStatusPanel(config.link_timeout_s)
        outer.addWidget(self.link_status)

        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        left = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        reason = disabled_reason or ("replay: commands are not sent" if replay else "")
        self.command_panel = CommandPanel(model.defs, None if replay else sender, reason, mission=mission)
        self.command_history = CommandHistory()
        history_box = QtWidgets.QGroupBox("Command history")
        QtWidgets.QVBoxLayout(history_box).addWidget(self.command_history)
        left.addWidget(self.command_panel)
        left.addWidget(history_box)
        left.setSizes([330, 560])

        right = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.setObjectName("main_tabs")
        self.housekeeping = HousekeepingPages(
            model.defs, model.hk_kinds, model.instance_field, exporter=model.export_csv
        )
        self.plots = PlotsPage(model)
        self.tree_view = TreeStatusView(model)
        self.tower_view = TowerView(mission)
        self.packet_view = PacketView(model)
        self.pages = {
            "housekeeping": self.housekeeping,
            "plots": self.plots,
            "tree": self.tree_view,
            "tower": self.tower_view,
            "packets": self.packet_view,
        }
        for key in TABS:
            self.tabs.addTab(self.pages[key], TAB_TITLES[key])
        self.tabs.currentChanged.connect(lambda _: self._draw_current())
        self.event_log = EventLog(config.event_rows)
        self.limit_alarms = LimitAlarmPanel(model.alarms, current=self._current_value)
        right.addWidget(self.tabs)
        right.addWidget(self.limit_alarms)
        right.addWidget(self.event_log)
        right.setSizes([520, 150, 210])
        split.addWidget(left)
        split.addWidget(right)
        split.setSizes([560, 940])
        outer.addWidget(split, 1)

        self.replay_bar: ReplayBar | None = None
        if replay:
            self.replay_bar = ReplayBar(model.first(), model.head())
            self.replay_bar.seek_requested.connect(self.seek)
            self.replay_bar.step_requested.connect(self.step)
            self.replay_bar.buttons["play"].clicked.connect(self._play_clicked)
            outer.addWidget(self.replay_bar)
        self.setCentralWidget(central)
        self.resize(1500, 940)

        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(max(1, int(1000 / config.refresh_hz)))
        self.timer.timeout.connect(self.refresh)

    def _current_value(self, key: tuple[str, str, str]) -> object:
        """A housekeeping field's newest value shown (None when none is)."""
        kind, instance, name = key
        snapshot = self.model.housekeeping.get((kind, instance))
        return None if snapshot is None else snapshot.fields.get(name)

    # -- tabs -------------------------------------------------------------------------------
    def show_tab(self, key: str) -> None:
        self.tabs.setCurrentWidget(self.pages[key])

    def current_tab(self) -> str:
        widget = self.tabs.currentWidget()
        return next(k for k, w in self.pages.items() if w is widget)

    # -- refreshing -------------------------------------------------------------------------
    def start(self) -> None:
        self.timer.start()

    def now(self) -> float | None:
        return self.model.position_time if self.replay else self.clock()

    def refresh(self) -> Changes:
        """One timer tick: move the model, redraw what changed; return the changes."""
        started = time.perf_counter()
        if self.on_refresh is not None:
            self.on_refresh()
        self.command_panel.poll_pending()
        try:
            if self.read_error is not None:  # a failed read may have left the state half-moved
                changes = self.model.seek(self.model.position)
            else:
                changes = self._replay_tick() if self.replay else self.model.advance()
            self.read_error = None
        except sqlite3.Error as exc:
            # The archive could not be read this time (locked, being replaced, disk error): say so
            # in the status strip and try again on the next tick; the window stays usable.
            self.read_error = f"ARCHIVE READ ERROR: {exc}"
            changes = Changes()
        self.apply(changes)
        self.refresh_count += 1
        self.refresh_seconds.append(time.perf_counter() - started)
        return changes

    def apply(self, changes: Changes) -> None:
        """Redraw the views ``changes`` touches (hidden tabs when they are next shown)."""
        model = self.model
        if changes.reset or changes.alarms or (self.limit_alarms.has_rows() and changes.kinds):
            self.limit_alarms.show_alarms()  # the alarms, and the newest values of their fields
        if changes.reset:
            self.event_log.reset(model.events)
            self._dirty.update(TABS)
            self._dirty_kinds.update(model.hk_kinds)
            self._dirty_trees.update(model.trees)
            self._dirty_series.update(model.series)
            self.command_history.show_commands(model.commands.values())
        else:
            self.event_log.add_events(changes.events)
            if changes.commands:
                self.command_history.show_commands(model.commands.values())
            if changes.kinds:
                self._dirty.add("housekeeping")
                self._dirty_kinds.update(changes.kinds)
                if changes.kinds & {"hk_tower", "hk_mission"}:
                    self._dirty.add("tower")
            if changes.trees:
                self._dirty.add("tree")
                self._dirty_trees.update(changes.trees)
            if changes.series:
                self._dirty.add("plots")
                self._dirty_series.update(changes.series)
            if changes.packets:
                self._dirty.add("packets")
        self._draw_current()
        if self.read_error is not None:
            health = (self.read_error, False)
        elif self.archive_health is not None:
            health = self.archive_health()
        else:
            health = (str(self.archive_path.name), True)
        self.link_status.show_figures(model.link_figures(self.now()), self.now(), *health)
        if self.replay_bar is not None:
            try:
                last = model.head()
            except sqlite3.Error:
                last = model.position
            self.replay_bar.show_position(model.position, model.position_time, last)

    def _draw_current(self) -> None:
        key = self.current_tab()
        if key not in self._dirty:
            return
        self._dirty.discard(key)
        model = self.model
        if key == "housekeeping":
            self.housekeeping.show_housekeeping(model.housekeeping, self._dirty_kinds)
            self._dirty_kinds.clear()
        elif key == "plots":
            self.plots.show_series(self._dirty_series)
            self._dirty_series.clear()
        elif key == "tree":
            self.tree_view.show_trees(self._dirty_trees)
            self._dirty_trees.clear()
        elif key == "tower":
            self.tower_view.show_tower(
                model.housekeeping.get(("hk_tower", "")), model.housekeeping.get(("hk_mission", ""))
            )
        elif key == "packets":
            self.packet_view.show_packets()

    def draw_all(self) -> None:
        """Draw every tab now (screenshots, tests)."""
        current = self.tabs.currentIndex()
        for key in TABS:
            self.show_tab(key)
        self.tabs.setCurrentIndex(current)

    # -- replay -----------------------------------------------------------------------------
    def _replay_tick(self) -> Changes:
        now = self.monotonic()
        elapsed, self._last_tick = now - self._last_tick, now
        bar = self.replay_bar
        if bar is None or not bar.playing:
            return Changes()
        head = self.model.head()
        if self.model.position >= head:
            bar.set_playing(False)
            return Changes()
        if self.replay_time is None:
            self.replay_time = self.model.position_time or self.model.time_of(self.model.first()) or 0.0
        self.replay_time += elapsed * bar.speed_factor
        target = max(self.model.id_at_time(self.replay_time), self.model.position)
        return self.model.advance(until=target)

    def _play_clicked(self) -> None:
        # Playing from the last packet starts over from the first.
        if (
            self.replay_bar is not None
            and self.replay_bar.playing
            and self.model.position >= self.model.head()
        ):
            self.seek(self.model.first())
        self.replay_time = self.model.position_time
        self._last_tick = self.monotonic()

    def seek(self, packet_id: int) -> Changes:
        """Show the archive as of ``packet_id`` (forward moves read only the packets in between)."""
        model = self.model
        if packet_id >= model.position and packet_id - model.position <= model.max_rows_per_refresh:
            changes = model.advance(until=packet_id)
        else:
            changes = model.seek(packet_id)
        self.replay_time = model.position_time
        self.apply(changes)
        return changes

    def step(self, direction: int) -> Changes:
        return self.seek(max(self.model.first(), self.model.position + direction))

    # -- output -----------------------------------------------------------------------------
    def save_screenshot(self, path: str | Path) -> Path:
        """Save the window as it is drawn now to ``path`` (PNG)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if not self.grab().save(str(path)):
            raise OSError(f"could not write the screenshot {path}")
        return path


__all__ = ["TABS", "MainWindow"]
