"""What one ARS knows of the mission: which members stand, which bays have begun, what is left in
each dispenser; and whether a CRS request makes sense against that (paper §V.C.1).

Reads the mission (the same file as the CRS), the ARS's own results, and the CRS's
``MissionProgress`` when it arrives (:meth:`MissionState.apply_progress`). Knowledge only grows:
a member counts as placed once this ARS placed it or the CRS reports it placed; a dispenser's
count is the lowest of this ARS's own count and the CRS's (parts are only ever taken).

:meth:`MissionState.check_request` answers ``None`` for a request to carry out, or the reason to
refuse it: unknown member, a member of another kind or bay, a request for another ARS or for a
strut or foundation rivet the mission gives the other ARS, a bay not yet started (bay n starts
when the CRS says its current bay is n, or when every member of bay n-1 stands), a member already
placed (or already affixed / riveted), a member to affix that is not placed yet. An Affix Member
that names a joint (:attr:`Request.reshot`) shoots that joint of a placed member again: it needs
the member placed and the joint one this ARS rivets in the mission. Nothing here talks to ROS.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

from tlt_common.mission.schema import Member, Mission

# tlt_interfaces/MemberState states, without importing the message here.
STATE_PLACED = 1
STATE_RIVETED = 2


class DispenserEmpty(RuntimeError):
    """A part was asked of a dispenser with none left."""


@dataclass(frozen=True)
class Request:
    """One CRS request, reduced to what the checks need. ``kind`` is the goal's KIND_* code (0 when
    the request has none); ``position`` is empty when the request has none; ``joint`` names the
    joint an Affix Member shoots again (an operator's retry of a failed joint), empty otherwise."""

    request: str  # add_cross_frame, add_member, affix_member, foundation_rivet
    member_id: str
    ars: str
    bay: int = 0
    kind: int = 0
    position: str = ""
    joint: str = ""

    @property
    def reshot(self) -> bool:
        """An Affix Member that shoots a joint of a set member again, and does nothing else."""
        return self.request == "affix_member" and bool(self.joint)


_KIND_CODES = {"vertical": 1, "diagonal": 2}
# The requests only the member's own ARS may carry out, and what each does to it.
_OWN_WORK = {"add_member": "add", "affix_member": "affix", "foundation_rivet": "rivet"}


class MissionState:
    """The ARS's runtime model of the mission; thread-safe (the tick and ROS callbacks share it)."""

    def __init__(self, mission: Mission, ars: str) -> None:
        self.mission = mission
        self.ars = ars
        self._lock = threading.Lock()
        self._placed: set[str] = set()
        self._affixed: set[str] = set()
        self._riveted: set[str] = set()  # foundation rivets
        self._current_bay = 0
        self.remaining = {name: d.count for name, d in mission.dispensers.items()}
        self.discarded = dict.fromkeys(mission.dispensers, 0)

    # ----- knowledge -----
    def placed(self) -> set[str]:
        with self._lock:
            return set(self._placed)

    def is_placed(self, member_id: str) -> bool:
        with self._lock:
            return member_id in self._placed

    def is_riveted(self, member_id: str) -> bool:
        """A foundation rivet already set."""
        with self._lock:
            return member_id in self._riveted

    def mark_placed(self, member_id: str) -> None:
        with self._lock:
            self._placed.add(member_id)

    def mark_affixed(self, member_id: str) -> None:
        with self._lock:
            self._affixed.add(member_id)

    def mark_riveted(self, member_id: str) -> None:
        with self._lock:
            self._riveted.add(member_id)

    def take_part(self, dispenser: str) -> int:
        """Take one part; returns what is left. :class:`DispenserEmpty` when none is left."""
        with self._lock:
            left = self.remaining[dispenser]
            if left <= 0:
                raise DispenserEmpty(f"dispenser '{dispenser}' is empty")
            self.remaining[dispenser] = left - 1
            return left - 1

    def count_discard(self, dispenser: str) -> None:
        with self._lock:
            self.discarded[dispenser] += 1

    def apply_progress(self, progress: Any) -> bool:
        """Merge a ``MissionProgress`` of this mission; returns False (and changes nothing) for
        another mission's."""
        if progress.mission != self.mission.name:
            return False
        with self._lock:
            self._current_bay = max(self._current_bay, int(progress.current_bay))
            for m in progress.members:
                if m.state >= STATE_PLACED:
                    self._placed.add(m.member_id)
                if m.state >= STATE_RIVETED and m.member_id.startswith("foundation/"):
                    self._riveted.add(m.member_id)
                elif m.state >= STATE_RIVETED and m.kind == 1:  # a riveted vertical has both rivets
                    self._affixed.add(m.member_id)
            for d in progress.dispensers:
                if d.name in self.remaining:
                    self.remaining[d.name] = min(self.remaining[d.name], int(d.remaining))
        return True

    def bay_started(self, bay: int) -> bool:
        with self._lock:
            return self._bay_started(bay)

    def _bay_started(self, bay: int) -> bool:
        if bay <= 1 or self._current_bay >= bay:
            return True
        return all(m.id in self._placed for m in self.mission.bay_members(bay - 1))

    # ----- checks -----
    def member(self, member_id: str) -> Member | None:
        try:
            return self.mission.member(member_id)
        except KeyError:
            return None

    def check_request(self, req: Request) -> str | None:
        """``None`` when ``req`` may run, else why it is refused."""
        refusal = self.mission_refusal(req)
        if refusal is not None:
            return refusal
        return self._progress_refusal(req, self.mission.member(req.member_id))

    def mission_refusal(self, req: Request) -> str | None:
        """Why the mission alone refuses ``req`` (``None`` when it does not): the wrong ARS, member,
        kind, position or bay. No MissionProgress can change this answer."""
        if req.ars and req.ars != self.ars:
            return f"request addressed to '{req.ars}', this is '{self.ars}'"
        member = self.member(req.member_id)
        if member is None:
            return f"unknown member '{req.member_id}' in mission '{self.mission.name}'"
        expected = {
            "add_cross_frame": ("cross_frame",),
            "add_member": ("vertical", "diagonal"),
            "affix_member": ("vertical", "diagonal"),
            "foundation_rivet": ("foundation_rivet",),
        }[req.request]
        if member.kind not in expected:
            return f"member '{member.id}' is a {member.kind}, not something {req.request} acts on"
        if req.kind and _KIND_CODES.get(member.kind) != req.kind:
            return f"member '{member.id}' is a {member.kind}; the request says kind {req.kind}"
        if req.position and req.position != member.position:
            return f"member '{member.id}' is at '{member.position}', not '{req.position}'"
        if req.bay and member.kind != "foundation_rivet" and req.bay != member.bay:
            return f"member '{member.id}' belongs to bay {member.bay}, not bay {req.bay}"
        if req.reshot:
            rivet = next((r for r in member.rivets if r.joint == req.joint), None)
            if rivet is None:
                return f"member '{member.id}' has no rivet at joint '{req.joint}' in the mission"
            if rivet.ars != self.ars:
                return f"joint '{req.joint}' of '{member.id}' is for '{rivet.ars}' to rivet, not '{self.ars}'"
            return None
        # A strut's parts and rivets come from its ARS's own dispensers, within its own reach; a
        # cross frame may go to either ARS (the CRS's writable cross_frame_ars).
        owner = member.affix_ars if req.request == "affix_member" else member.add_ars
        if req.request in _OWN_WORK and owner is not None and owner != self.ars:
            return f"member '{member.id}' is for '{owner}' to {_OWN_WORK[req.request]}, not '{self.ars}'"
        return None

    def _progress_refusal(self, req: Request, member: Member) -> str | None:
        """Why the tower's progress refuses ``req`` for ``member`` (``None`` when it does not)."""
        with self._lock:
            if not self._bay_started(member.bay):
                return f"bay {member.bay} has not started (bay {member.bay - 1} is not complete)"
            if req.request in ("add_cross_frame", "add_member") and member.id in self._placed:
                return f"member '{member.id}' is already placed"
            if req.reshot:
                if member.id not in self._placed:
                    return f"member '{member.id}' is not placed: no joint of it to shoot again"
                return None
            if req.request == "affix_member":
                if member.id not in self._placed:
                    return f"member '{member.id}' is not placed yet: nothing to affix"
                if member.id in self._affixed:
                    return f"member '{member.id}' is already affixed"
                if not any(r.step == "affix" for r in member.rivets):
                    return f"member '{member.id}' has no affix rivet in the mission"
            if req.request == "foundation_rivet" and member.id in self._riveted:
                return f"foundation rivet '{member.id}' is already set"
        return None


__all__ = ["DispenserEmpty", "MissionState", "Request"]
