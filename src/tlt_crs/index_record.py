"""Which bays the payload has been indexed (raised and the lifter lowered) for, persisted.

The tower model records members; it cannot tell whether Raise Payload and Lower Lifter already
ran for a bay whose first member is not placed yet. This record can: a CRS restarted between
lowering the lifter and placing the cross frame must not index the payload a second time. It is
written with the tower model's atomic write on every change and belongs to one mission (by its
content hash); a record of another mission is refused like a tower model of another mission.
"""

from __future__ import annotations

import json
from pathlib import Path

from tlt_common.mission.schema import Mission
from tlt_common.mission.tower_model import TowerModelError, atomic_write


class IndexRecord:
    """The set of bay numbers indexed so far, persisted to ``path`` (None: in memory only)."""

    def __init__(self, mission: Mission, path: str | Path | None) -> None:
        self.mission = mission
        self.path = Path(path) if path is not None else None
        self.bays: set[int] = set()
        if self.path is not None and self.path.exists():
            self._load()

    def _load(self) -> None:
        assert self.path is not None
        try:
            document = json.loads(self.path.read_text())
            bays = {int(b) for b in document["bays"]}
            mission_hash = document["mission_hash"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise TowerModelError(f"{self.path}: index record unreadable: {exc}") from exc
        if mission_hash != self.mission.hash:
            raise TowerModelError(
                f"{self.path}: index record belongs to another mission than '{self.mission.name}'"
            )
        if not all(1 <= b <= self.mission.bay_count for b in bays):
            raise TowerModelError(f"{self.path}: index record names bays outside 1..{self.mission.bay_count}")
        self.bays = bays

    def indexed(self, bay: int) -> bool:
        return bay in self.bays

    def record(self, bay: int) -> None:
        if bay in self.bays:
            return
        self.bays.add(bay)
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            body = {
                "mission": self.mission.name,
                "mission_hash": self.mission.hash,
                "bays": sorted(self.bays),
            }
            atomic_write(self.path, json.dumps(body).encode())


__all__ = ["IndexRecord"]
