"""Replay controls: scrub, step and play an archive opened read-only.

The slider spans the archive's packet ids; buttons go to the start, one packet back, play/pause,
one packet forward and to the end; the speed multiplies the archive's own time while playing. The
bar only emits requests (:attr:`seek_requested`, :attr:`step_requested`); the main window moves
the archive model and calls :meth:`show_position`.
"""

from __future__ import annotations

from PySide6 import QtCore, QtWidgets

from tlt_gsw.gui.style import clock_text

SPEEDS = (0.5, 1.0, 2.0, 5.0, 10.0, 50.0, 200.0)


class ReplayBar(QtWidgets.QFrame):
    """Scrub slider, step and play buttons, speed and position."""

    seek_requested = QtCore.Signal(int)
    step_requested = QtCore.Signal(int)  # -1 back, +1 forward
    slider: QtWidgets.QSlider  # made below the buttons whose handlers read it

    def __init__(self, first: int, last: int, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFrameShape(QtWidgets.QFrame.Shape.StyledPanel)
        self.playing = False
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(6, 2, 6, 2)
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        for key, text, tip in (
            ("start", "|◀", "go to the first packet"),
            ("back", "◀", "one packet back"),
            ("play", "▶ Play", "play at the chosen speed"),
            ("forward", "▶|", "one packet forward"),
            ("end", "▶▶|", "go to the last packet"),
        ):
            button = QtWidgets.QPushButton(text)
            button.setObjectName(f"replay_{key}")
            button.setToolTip(tip)
            layout.addWidget(button)
            self.buttons[key] = button
        self.buttons["start"].clicked.connect(lambda: self.seek_requested.emit(self.slider.minimum()))
        self.buttons["end"].clicked.connect(lambda: self.seek_requested.emit(self.slider.maximum()))
        self.buttons["back"].clicked.connect(lambda: self.step_requested.emit(-1))
        self.buttons["forward"].clicked.connect(lambda: self.step_requested.emit(1))
        self.buttons["play"].clicked.connect(self.toggle_play)
        self.speed = QtWidgets.QComboBox()
        self.speed.setObjectName("replay_speed")
        for value in SPEEDS:
            self.speed.addItem(f"{value:g}×", value)
        self.speed.setCurrentIndex(SPEEDS.index(1.0))
        layout.addWidget(self.speed)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal)
        self.slider.setObjectName("replay_slider")
        self.slider.setRange(first, max(first, last))
        self.slider.sliderReleased.connect(lambda: self.seek_requested.emit(self.slider.value()))
        self.slider.valueChanged.connect(self._value_changed)
        layout.addWidget(self.slider, 1)
        self.position = QtWidgets.QLabel("-")
        self.position.setObjectName("replay_position")
        layout.addWidget(self.position)

    @property
    def speed_factor(self) -> float:
        return float(self.speed.currentData())

    def _value_changed(self, value: int) -> None:
        # Keyboard and page clicks move the slider without a drag: seek at once. While dragging,
        # seek on release only (each seek rebuilds the state).
        if not self.slider.isSliderDown() and self.slider.signalsBlocked() is False:
            self.seek_requested.emit(value)

    def toggle_play(self) -> None:
        self.set_playing(not self.playing)

    def set_playing(self, playing: bool) -> None:
        self.playing = playing
        self.buttons["play"].setText("❚❚ Pause" if playing else "▶ Play")

    def set_range(self, first: int, last: int) -> None:
        self.slider.blockSignals(True)
        self.slider.setRange(first, max(first, last))
        self.slider.blockSignals(False)

    def show_position(self, packet_id: int, t: float | None, last: int) -> None:
        self.slider.blockSignals(True)
        self.slider.setValue(packet_id)
        self.slider.blockSignals(False)
        self.position.setText(f"packet {packet_id} of {last}  {clock_text(t, with_date=True)}")


__all__ = ["SPEEDS", "ReplayBar"]
