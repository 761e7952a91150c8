"""Append-only JSON-lines files that one process writes while others read them.

The twin's ``placements.jsonl`` and the test rigs' request records are read while their writer
runs. A reader may meet a last line only half written, so :func:`read` skips a line that does not
parse instead of failing on it; :class:`JsonLinesWriter` appends each entry whole under a lock, so
the writer's threads never interleave their lines.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any


class JsonLinesWriter:
    """Appends one JSON object per line to ``path``, from any thread of this process."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()

    def append(self, entry: dict[str, Any]) -> None:
        """Append ``entry`` as one line; raises ``OSError`` when the file cannot be written."""
        line = json.dumps(entry) + "\n"
        with self._lock, self.path.open("a") as f:
            f.write(line)


def read(path: Path, kind: str | None = None) -> list[dict[str, Any]]:
    """The entries of ``path`` in the order written, only those whose ``kind`` is ``kind`` when given.

    A file not there yet reads as empty, and a line that does not parse (one being written) is
    left out.
    """
    try:
        lines = Path(path).read_text().splitlines()
    except OSError:
        return []
    entries = []
    for line in lines:
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if kind is None or entry.get("kind") == kind:
            entries.append(entry)
    return entries
