"""Link status strip: connected, packet and byte rates, gaps, CRC errors, rejections, telemetry that
failed authentication, last packet age.

Reads :class:`LinkFigures` of the archive model (what the archive holds up to the position) and,
in live mode, the archive writer's health. "Connected" means a packet arrived within
``link_timeout_s``; in replay the age is measured from the replay position.
"""

from __future__ import annotations

from PySide6 import QtCore, QtWidgets

from tlt_gsw.gui.link_counter import LinkFigures
from tlt_gsw.gui.style import BAD_COLOUR, LIMIT_COLOURS, OK_COLOUR, rate_text

_ITEMS = (
    ("link", "Link"),
    ("rate", "Receiving"),
    ("packets", "Packets rx / tx"),
    ("gaps", "Gaps (missing)"),
    ("crc", "CRC errors"),
    ("rejections", "Rejected"),
    ("auth", "Failed authentication"),
    ("age", "Last packet"),
    ("archive", "Archive"),
)


class LinkStatusPanel(QtWidgets.QFrame):
    """A row of labelled figures; :meth:`show_figures` updates them."""

    def __init__(self, link_timeout_s: float, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.link_timeout_s = link_timeout_s
        self.setFrameShape(QtWidgets.QFrame.Shape.StyledPanel)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(6, 3, 6, 3)
        self.values: dict[str, QtWidgets.QLabel] = {}
        for key, title in _ITEMS:
            box = QtWidgets.QVBoxLayout()
            box.setSpacing(0)
            caption = QtWidgets.QLabel(title)
            caption.setStyleSheet("color: #555; font-size: 9pt;")
            value = QtWidgets.QLabel("-")
            value.setObjectName(f"link_{key}")
            value.setStyleSheet("font-weight: bold; padding: 1px 4px;")
            value.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
            box.addWidget(caption)
            box.addWidget(value)
            layout.addLayout(box)
            self.values[key] = value
        layout.addStretch(1)

    def _set(self, key: str, text: str, colour: str | None = None) -> None:
        label = self.values[key]
        if label.text() != text:
            label.setText(text)
        style = "font-weight: bold; padding: 1px 4px;"
        if colour:
            style += f" background: {colour}; border-radius: 3px;"
        if label.styleSheet() != style:  # a new style sheet re-polishes the widget: only on change
            label.setStyleSheet(style)

    def show_figures(
        self, figures: LinkFigures, now: float | None, archive_text: str, archive_ok: bool = True
    ) -> None:
        age = None if figures.last_rx_at is None or now is None else max(0.0, now - figures.last_rx_at)
        connected = age is not None and age <= self.link_timeout_s
        self._set("link", "CONNECTED" if connected else "NO SIGNAL", OK_COLOUR if connected else BAD_COLOUR)
        self._set("rate", f"{figures.rate_pps:.1f} pkt/s  {rate_text(figures.rate_bps, 'B/s')}")
        self._set("packets", f"{figures.packets_rx} / {figures.packets_tx}")
        self._set(
            "gaps", f"{figures.gaps} ({figures.missing})", LIMIT_COLOURS["yellow"] if figures.gaps else None
        )
        self._set("crc", str(figures.crc_errors), LIMIT_COLOURS["yellow"] if figures.crc_errors else None)
        reasons = ", ".join(f"{k} {v}" for k, v in figures.by_reason.most_common(3))
        self._set(
            "rejections",
            f"{figures.rejections}" + (f" ({reasons})" if reasons else ""),
            LIMIT_COLOURS["yellow"] if figures.rejections else None,
        )
        self._set("auth", str(figures.auth_rejections), BAD_COLOUR if figures.auth_rejections else None)
        self._set("age", "never" if age is None else f"{age:.1f} s ago", None if connected else BAD_COLOUR)
        self._set("archive", archive_text, None if archive_ok else BAD_COLOUR)


__all__ = ["LinkStatusPanel"]
