"""The inspection desk: the thread-safe meeting point of ``/crs/inspect_part`` calls (the ARS
presenting a part) and the tree's Inspection Check (:mod:`tlt_crs.behaviours.inspection`, which
describes the hand-off). It is part of the CRS's shared state (:class:`tlt_crs.context.CrsContext`
holds one), so it depends on neither."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any


def not_inspected_report(member_id: str, part_kind: str, reason: str) -> Any:
    """The answer to a presentation nobody inspected: not passed, ``not_inspected`` set, so the
    ARS keeps the part (it was not judged) and may present it again."""
    from tlt_interfaces.msg import InspectionReport

    report = InspectionReport()
    report.target_id = member_id
    report.target_kind = part_kind
    report.passed = False
    report.not_inspected = True
    report.reasons = [reason]
    return report


@dataclass
class PendingInspection:
    member_id: str
    part_kind: str
    camera: str
    answered: threading.Event = field(default_factory=threading.Event)
    report: Any = None


class InspectionDesk:
    """Thread-safe meeting point of ``/crs/inspect_part`` calls and the tree's Inspection Check."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.expected: str | None = None
        self.pending: PendingInspection | None = None
        self.served = 0  # reports forwarded to an ARS
        self.closed = ""  # why no call is held any more (the CRS stopping)

    # ----- tree side -----
    def expect(self, member_id: str) -> None:
        with self._lock:
            self.expected = member_id

    def take(self, member_id: str) -> PendingInspection | None:
        """The unanswered call for ``member_id``, if the ARS made one."""
        with self._lock:
            pending = self.pending
            if pending is not None and pending.member_id == member_id and not pending.answered.is_set():
                return pending
            return None

    def answer(self, member_id: str, report: Any) -> bool:
        """Give ``report`` to the call for ``member_id`` waiting now; False when none waits."""
        with self._lock:
            pending = self.pending
            if pending is None or pending.member_id != member_id or pending.answered.is_set():
                return False
            pending.report = report
            pending.answered.set()
            self.pending = None
            return True

    def withdraw(self, member_id: str, why: str) -> None:
        """Stop expecting ``member_id``; a call still waiting gets a failed report saying ``why``."""
        with self._lock:
            if self.expected == member_id:
                self.expected = None
            pending = self.pending
            if pending is not None and pending.member_id == member_id:
                pending.report = not_inspected_report(
                    member_id, pending.part_kind, f"inspection withdrawn: {why}"
                )
                pending.answered.set()
                self.pending = None

    def close(self, why: str) -> None:
        """Hold no call any more: the one waiting, and every later one, gets a not-inspected report
        saying ``why`` at once. The CRS stopping must not wait out a held call's ``timeout``: the
        process's exit waits for its executor's threads."""
        with self._lock:
            self.closed, self.expected = why, None
            pending, self.pending = self.pending, None
            if pending is not None:
                pending.report = not_inspected_report(pending.member_id, pending.part_kind, why)
                pending.answered.set()

    # ----- service side -----
    def serve(self, member_id: str, part_kind: str, camera: str, timeout: float) -> Any:
        """Answer one ``/crs/inspect_part`` call (blocks the calling service thread ≤ ``timeout`` s)."""
        with self._lock:
            if self.closed:
                return not_inspected_report(member_id, part_kind, self.closed)
            if self.expected is None:
                return not_inspected_report(
                    member_id, part_kind, "the CRS is not expecting a part for inspection"
                )
            if member_id != self.expected:
                return not_inspected_report(
                    member_id, part_kind, f"the CRS expects a part for '{self.expected}', not '{member_id}'"
                )
            earlier = self.pending
            if earlier is not None:
                # The expected member's earlier call, given up by its ARS: release its thread.
                earlier.report = not_inspected_report(
                    earlier.member_id, earlier.part_kind, f"a newer call for '{member_id}' took over"
                )
                earlier.answered.set()
            pending = PendingInspection(member_id, part_kind, camera)
            self.pending = pending
        if pending.answered.wait(timeout):
            return pending.report
        with self._lock:
            if self.pending is pending:
                self.pending = None
            if pending.report is not None:
                return pending.report
        return not_inspected_report(
            member_id, part_kind, f"the CRS did not inspect the part within {timeout:g} s"
        )


__all__ = ["InspectionDesk", "PendingInspection", "not_inspected_report"]
