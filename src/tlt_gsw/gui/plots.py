"""Live plots (pyqtgraph) of selected housekeeping fields, with their yellow and red limits.

One plot per field, stacked, sharing the time axis (UTC). A per-agent field (``hk_ee.width``)
gets one curve per agent. The series come from :attr:`ArchiveModel.series`, which reads each
plotted field's new points from the archive on every refresh and keeps ``plot_window_s`` of them.
Fields are added and removed with the chooser above the plots (every numeric field of the
definitions file is offered).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from tlt_common.ccsds.definitions import Definitions
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.style import LIMIT_COLOURS

NUMERIC = ("u8", "u16", "u32", "u64", "i8", "i16", "i32", "i64", "f32", "f64", "bool")
CURVE_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e")


def plottable_fields(defs: Definitions, kinds: Iterable[str]) -> list[tuple[str, str]]:
    return [(k, f.name) for k in kinds for f in defs.packet(k).fields if f.type in NUMERIC]


class PlotsPage(QtWidgets.QWidget):
    """The chooser and the stacked plots; :meth:`show_series` redraws the changed ones."""

    def __init__(self, model: ArchiveModel, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.defs = model.defs
        layout = QtWidgets.QVBoxLayout(self)
        row = QtWidgets.QHBoxLayout()
        self.chooser = QtWidgets.QComboBox()
        self.chooser.setObjectName("plot_chooser")
        for kind, name in plottable_fields(self.defs, model.hk_kinds):
            self.chooser.addItem(f"{kind}.{name}", (kind, name))
        add = QtWidgets.QPushButton("Add plot")
        add.clicked.connect(lambda: self.add_field(*self.chooser.currentData()))
        remove = QtWidgets.QPushButton("Remove plot")
        remove.clicked.connect(lambda: self.remove_field(*self.chooser.currentData()))
        row.addWidget(QtWidgets.QLabel("Field"))
        row.addWidget(self.chooser, 1)
        row.addWidget(add)
        row.addWidget(remove)
        layout.addLayout(row)
        pg.setConfigOptions(antialias=False, background="w", foreground="k")
        self.canvas = pg.GraphicsLayoutWidget()
        self.canvas.setObjectName("plots")
        layout.addWidget(self.canvas, 1)
        self.plots: dict[tuple[str, str], pg.PlotItem] = {}
        self.curves: dict[tuple[str, str], dict[str, pg.PlotDataItem]] = {}
        for key in list(model.series):
            self._make_plot(key)

    def _make_plot(self, key: tuple[str, str]) -> None:
        kind, name = key
        fd = next(f for f in self.defs.packet(kind).fields if f.name == name)
        plot = self.canvas.addPlot(
            row=len(self.plots), col=0, axisItems={"bottom": pg.DateAxisItem(utcOffset=0)}
        )
        plot.setTitle(f"{kind}.{name}" + (f" [{fd.unit}]" if fd.unit else ""), size="9pt")
        plot.showGrid(x=True, y=True, alpha=0.3)
        plot.setMinimumHeight(110)
        if self.plots:
            plot.setXLink(next(iter(self.plots.values())))
        if fd.limits is not None:
            for colour in ("yellow", "red"):
                pair = getattr(fd.limits, colour)
                for bound in pair or ():
                    line = pg.InfiniteLine(
                        pos=bound,
                        angle=0,
                        pen=pg.mkPen(LIMIT_COLOURS[colour], width=1, style=QtCore.Qt.PenStyle.DashLine),
                    )
                    plot.addItem(line, ignoreBounds=True)
        if key[0] in self.model.instance_field:
            plot.addLegend(offset=(5, 5))
        self.plots[key] = plot
        self.curves[key] = {}

    def _relayout(self) -> None:
        self.canvas.clear()
        keys = list(self.plots)
        self.plots, self.curves = {}, {}
        for key in keys:
            self._make_plot(key)
        self.show_series(keys)

    def add_field(self, kind: str, name: str) -> None:
        if (kind, name) in self.plots:
            return
        self.model.add_plot_field(kind, name)
        self._make_plot((kind, name))
        self.show_series([(kind, name)])

    def remove_field(self, kind: str, name: str) -> None:
        if (kind, name) not in self.plots:
            return
        self.model.remove_plot_field(kind, name)
        del self.plots[(kind, name)]
        self._relayout()

    def show_series(self, keys: Iterable[tuple[str, str]]) -> None:
        for key in keys:
            plot = self.plots.get(key)
            series = self.model.series.get(key)
            if plot is None or series is None:
                continue
            curves = self.curves[key]
            for instance in list(curves):
                if instance not in series:
                    plot.removeItem(curves.pop(instance))
            for instance, points in series.items():
                curve = curves.get(instance)
                if curve is None:
                    colour = CURVE_COLOURS[len(curves) % len(CURVE_COLOURS)]
                    curve = plot.plot(pen=pg.mkPen(colour, width=1.5), name=instance or None)
                    curve.setClipToView(True)
                    curve.setDownsampling(auto=True)
                    curves[instance] = curve
                if points:
                    data = np.fromiter((v for p in points for v in p), dtype=float, count=2 * len(points))
                    curve.setData(data[0::2], data[1::2])
                else:
                    curve.setData([], [])

    def point_counts(self) -> dict[str, int]:
        """Points drawn per plot title (tests)."""
        out = {}
        for (kind, name), curves in self.curves.items():
            out[f"{kind}.{name}"] = sum(len(c.xData) if c.xData is not None else 0 for c in curves.values())
        return out


__all__ = ["PlotsPage", "plottable_fields"]
