"""A check that the installed Qt binding can run the GUI for hours, done before the GUI starts.

PySide6 6.12.0 on CPython 3.11 returns ``None`` from every Qt call that returns nothing without
taking a reference to it, so each such call drops one reference to ``None``; after a few thousand
calls (a few seconds of this GUI) the interpreter aborts with "none_dealloc". CPython 3.12 made
``None`` immortal, which hides the bug there; PySide6 6.11.3 and 6.10.3 do not have it. The check
measures the behaviour itself rather than matching version numbers.
"""

from __future__ import annotations

import sys

PROBE_CALLS = 64


def binding_problem() -> str | None:
    """Why the installed PySide6 cannot run the GUI, or None when it can."""
    import PySide6
    from PySide6 import QtCore

    probe = QtCore.QObject()
    before = sys.getrefcount(None)
    for _ in range(PROBE_CALLS):
        probe.setObjectName("probe")
    lost = before - sys.getrefcount(None)
    if lost < PROBE_CALLS // 2:
        return None
    return (
        f"PySide6 {PySide6.__version__} on Python {sys.version.split()[0]} drops a reference to None on "
        f"every Qt call that returns nothing ({lost} in {PROBE_CALLS} calls): the interpreter would abort "
        "within seconds. Install PySide6-Essentials 6.11.3 (or run Python 3.12 or newer)."
    )


__all__ = ["binding_problem"]
