"""The CRS's model of the tower and of the parts left in each dispenser (paper §IV.B).

Every member of the mission is NOT_PLACED, PLACED, RIVETED or INSPECTED (as
``tlt_interfaces/MemberState``), and moves only forward along its kind's sequence:

* cross frame: NOT_PLACED -> PLACED -> INSPECTED (it is pre-assembled, not riveted)
* vertical and diagonal: NOT_PLACED -> PLACED -> RIVETED -> INSPECTED
* foundation rivet: NOT_PLACED -> RIVETED -> INSPECTED

Each dispenser has ``remaining`` parts and a count of parts ``discarded`` after a failed
inspection. Any refused change (an already placed member, riveting an unplaced one, an empty
dispenser) raises :class:`TransitionRefused` with the reason and changes nothing.

Operators correct the model from the ground (:meth:`TowerModel.correct_member` with one of
:data:`MEMBER_MARKS`, :meth:`TowerModel.set_remaining`) under the model's rules: a bay stands on
the bays below it, so a member is marked placed only once every lower bay is built, and marked
unplaced or needing inspection only while no higher bay has a member in place; a discarded part
is one taken from the member's dispenser and never placed; a dispenser holds at most what was
loaded less what was discarded.

Each riveted joint the ARSs looked at (joint verification) has a verification record keyed
``<member id>@<joint>`` (:data:`JOINT_STATES`): ``verified``, ``failed``, ``unverified`` as the ARS
reported it with the evidence (verdict, reason, figures), ``confirmed`` when the operator judged a
failed or unverified joint good, ``retry`` while the operator's retry of it is pending. A joint
never looked at has none. A member marked unplaced or discarded loses its joints' records.

Every accepted change is persisted at once to a JSON file by an atomic, crash-safe write (temp
file, fsync, rename, fsync of the directory), so a CRS that restarts :meth:`TowerModel.open`\\ s
the file and resumes where it stood, never adding a member the model says is placed. A file made
for another mission (different content hash), or corrupt (bad JSON, bad checksum, unknown
members), is refused with a clear :class:`TowerModelError`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tlt_common.mission.schema import Member, Mission

FILE_FORMAT = 1
NOT_PLACED, PLACED, RIVETED, INSPECTED = 0, 1, 2, 3  # tlt_interfaces/MemberState.STATE_*
STATE_NAMES = {NOT_PLACED: "NOT_PLACED", PLACED: "PLACED", RIVETED: "RIVETED", INSPECTED: "INSPECTED"}
_STATE_CODES = {v: k for k, v in STATE_NAMES.items()}
# What the ground may say of a member (correct_member).
MEMBER_MARKS = ("placed", "unplaced", "discarded", "needs_inspection")
# A joint's verification record (record_joint, decide_joint); ACCEPTED_JOINTS need no operator.
JOINT_STATES = ("verified", "failed", "unverified", "confirmed", "retry")
ACCEPTED_JOINTS = ("verified", "confirmed")
JOINT_FIELDS: dict[str, type | tuple[type, ...]] = {
    "state": str, "verdict": str, "reason": str, "shots": int, "looks": int, "verdicts": list,
    "height": float, "along": float, "pixels": int, "head": (list, type(None)), "camera": str,
}  # fmt: skip
SEQUENCES = {
    "cross_frame": (NOT_PLACED, PLACED, INSPECTED),
    "vertical": (NOT_PLACED, PLACED, RIVETED, INSPECTED),
    "diagonal": (NOT_PLACED, PLACED, RIVETED, INSPECTED),
    "foundation_rivet": (NOT_PLACED, RIVETED, INSPECTED),
}


class TowerModelError(RuntimeError):
    """A persisted tower model that cannot be resumed (wrong mission, corrupt, unreadable)."""


class TransitionRefused(ValueError):
    """A change the model refuses; ``reason`` says why. Nothing was changed."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)


def atomic_write(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data`` so that a crash at any point leaves the old or the new file whole."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    finally:
        os.close(fd)
    try:
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    # The rename is durable only once the directory entry is.
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def _checksum(body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


class TowerModel:
    """Member states and dispenser counts of one mission, persisted on every change."""

    def __init__(self, mission: Mission, path: str | Path | None = None) -> None:
        """A fresh model (nothing placed, dispensers full). Persisted at once when ``path`` is given."""
        self.mission = mission
        self.path = Path(path) if path is not None else None
        self._members: dict[str, Member] = {m.id: m for m in mission.members}
        self.states: dict[str, int] = dict.fromkeys(self._members, NOT_PLACED)
        self.remaining: dict[str, int] = {d.name: d.count for d in mission.dispensers.values()}
        self.discarded: dict[str, int] = dict.fromkeys(mission.dispensers, 0)
        self.joints: dict[str, dict[str, Any]] = {}  # "<member id>@<joint>" -> verification record
        self.revision = 0
        # The tick thread and the ground-command thread both change the model.
        self.lock = threading.RLock()
        self.listeners: list[Callable[[TowerModel], None]] = []
        if self.path is not None:
            self._persist()

    # ----- persistence -----
    def _body(self) -> dict[str, Any]:
        return {
            "format": FILE_FORMAT,
            "mission": self.mission.name,
            "mission_hash": self.mission.hash,
            "revision": self.revision,
            "members": {k: STATE_NAMES[v] for k, v in self.states.items()},
            "dispensers": {
                k: {"remaining": self.remaining[k], "discarded": self.discarded[k]} for k in self.remaining
            },
            "joints": {k: dict(v) for k, v in self.joints.items()},
        }

    def _persist(self) -> None:
        if self.path is None:
            return
        body = self._body()
        document = {"checksum": _checksum(body), **body}
        atomic_write(self.path, json.dumps(document, indent=1).encode())

    @classmethod
    def load(cls, mission: Mission, path: str | Path) -> TowerModel:
        """Resume from ``path``; :class:`TowerModelError` if it is not a sound file of ``mission``."""
        path = Path(path)
        try:
            text = path.read_bytes()
        except OSError as exc:
            raise TowerModelError(f"{path}: cannot read tower model: {exc.strerror or exc}") from exc
        try:
            document = json.loads(text)
        except (ValueError, UnicodeDecodeError) as exc:
            raise TowerModelError(
                f"{path}: tower model is not valid JSON ({exc}); it may be corrupt"
            ) from exc
        if not isinstance(document, dict) or "checksum" not in document:
            raise TowerModelError(f"{path}: not a tower model file (no checksum)")
        checksum = document.pop("checksum")
        if checksum != _checksum(document):
            raise TowerModelError(f"{path}: tower model checksum does not match its content; it is corrupt")
        if document.get("format") != FILE_FORMAT:
            raise TowerModelError(
                f"{path}: tower model format {document.get('format')!r}, expected {FILE_FORMAT}"
            )
        if document.get("mission_hash") != mission.hash:
            raise TowerModelError(
                f"{path}: tower model belongs to mission '{document.get('mission')}'"
                f" ({str(document.get('mission_hash'))[:12]}), not to '{mission.name}' ({mission.hash[:12]})"
            )
        model = cls(mission)
        members = document.get("members")
        dispensers = document.get("dispensers")
        if not isinstance(members, dict) or set(members) != set(model.states):
            raise TowerModelError(f"{path}: tower model members do not match mission '{mission.name}'")
        if not isinstance(dispensers, dict) or set(dispensers) != set(model.remaining):
            raise TowerModelError(f"{path}: tower model dispensers do not match mission '{mission.name}'")
        for member_id, name in members.items():
            state = _STATE_CODES.get(name)
            if state is None or state not in SEQUENCES[model._members[member_id].kind]:
                raise TowerModelError(f"{path}: member '{member_id}' has impossible state {name!r}")
            model.states[member_id] = state
        for name, counts in dispensers.items():
            capacity = mission.dispensers[name].count
            try:
                remaining, discarded = int(counts["remaining"]), int(counts["discarded"])
            except (TypeError, KeyError, ValueError) as exc:
                raise TowerModelError(f"{path}: dispenser '{name}' counts unreadable: {exc}") from exc
            if not 0 <= remaining <= capacity or not 0 <= discarded <= capacity - remaining:
                raise TowerModelError(f"{path}: dispenser '{name}' counts impossible: {counts}")
            model.remaining[name], model.discarded[name] = remaining, discarded
        joints = document.get("joints", {})  # files of a build without joint verification have none
        if not isinstance(joints, dict):
            raise TowerModelError(f"{path}: tower model joints are not a mapping")
        for key, record in joints.items():
            why = model._joint_problem(key, record)
            if why:
                raise TowerModelError(f"{path}: joint '{key}' {why}")
            model.joints[key] = dict(record)
        revision = document.get("revision")
        if not isinstance(revision, int) or revision < 0:
            raise TowerModelError(f"{path}: tower model revision {revision!r} is not a count")
        model.revision = revision
        model.path = path
        return model

    @classmethod
    def open(cls, mission: Mission, path: str | Path) -> TowerModel:
        """Resume from ``path`` if it exists, else start fresh and persist there."""
        path = Path(path)
        # Temp files of writers killed mid-write: never read, safe to remove.
        for stale in path.parent.glob(f".{path.name}.*.tmp"):
            with contextlib.suppress(OSError):
                stale.unlink()
        return cls.load(mission, path) if path.exists() else cls(mission, path)

    def _commit(self) -> None:
        self.revision += 1
        self._persist()
        for listener in list(self.listeners):
            listener(self)

    # ----- members -----
    def member(self, member_id: str) -> Member:
        try:
            return self._members[member_id]
        except KeyError:
            raise TransitionRefused(f"unknown member '{member_id}'") from None

    def state(self, member_id: str) -> int:
        self.member(member_id)
        return self.states[member_id]

    def check(self, member_id: str, target: int) -> str | None:
        """Why moving ``member_id`` to ``target`` is refused, or None when it is legal."""
        if member_id not in self._members:
            return f"unknown member '{member_id}'"
        member = self._members[member_id]
        sequence = SEQUENCES[member.kind]
        current = self.states[member_id]
        if target not in sequence:
            return f"a {member.kind.replace('_', ' ')} is never {STATE_NAMES[target]}"
        here, there = sequence.index(current), sequence.index(target)
        if there <= here:
            return f"'{member_id}' is already {STATE_NAMES[current]}"
        if there != here + 1:
            before = STATE_NAMES[sequence[there - 1]]
            return f"'{member_id}' is {STATE_NAMES[current]}; it must be {before} first"
        return None

    def _move(self, member_id: str, target: int) -> None:
        with self.lock:
            reason = self.check(member_id, target)
            if reason:
                raise TransitionRefused(reason)
            self.states[member_id] = target
            self._commit()

    def place(self, member_id: str) -> None:
        """NOT_PLACED -> PLACED (cross frames, verticals, diagonals)."""
        self._move(member_id, PLACED)

    def rivet(self, member_id: str) -> None:
        """PLACED -> RIVETED (verticals, diagonals), or NOT_PLACED -> RIVETED (foundation rivets)."""
        self._move(member_id, RIVETED)

    def inspect(self, member_id: str) -> None:
        """The last step of the member's sequence -> INSPECTED."""
        self._move(member_id, INSPECTED)

    def override(self, member_id: str, state: int) -> None:
        """Set a member's state directly: the operator's correction of the model from the ground."""
        member = self.member(member_id)
        if state not in SEQUENCES[member.kind]:
            raise TransitionRefused(
                f"a {member.kind.replace('_', ' ')} is never {STATE_NAMES.get(state, state)}"
            )
        with self.lock:
            self.states[member_id] = state
            self._commit()

    def is_done(self, member_id: str) -> bool:
        """Placed and fixed: RIVETED or later (a cross frame: PLACED or later)."""
        member = self.member(member_id)
        needed = PLACED if member.kind == "cross_frame" else RIVETED
        return self.states[member_id] >= needed

    def next_member(self) -> Member | None:
        """The first member in build order that is not done, or None when the tower is built."""
        return next((m for m in self.mission.members if not self.is_done(m.id)), None)

    def bays_built(self) -> int:
        built = 0
        for bay in range(1, self.mission.bay_count + 1):
            if not all(self.is_done(m.id) for m in self.mission.bay_members(bay)):
                break
            built = bay
        return built

    @property
    def tower_built(self) -> bool:
        return all(self.is_done(m) for m in self._members)

    # ----- dispensers -----
    def take_part(self, dispenser: str, count: int = 1) -> None:
        """``count`` parts taken from ``dispenser``; refused if it holds fewer."""
        if dispenser not in self.remaining:
            raise TransitionRefused(f"unknown dispenser '{dispenser}'")
        if count < 1:
            raise TransitionRefused(f"cannot take {count} part(s)")
        with self.lock:
            if self.remaining[dispenser] < count:
                raise TransitionRefused(
                    f"dispenser '{dispenser}' holds {self.remaining[dispenser]} part(s); cannot take {count}"
                )
            self.remaining[dispenser] -= count
            self._commit()

    def discard_part(self, dispenser: str, count: int = 1) -> None:
        """``count`` parts already taken from ``dispenser`` were discarded after a failed inspection."""
        if dispenser not in self.remaining:
            raise TransitionRefused(f"unknown dispenser '{dispenser}'")
        with self.lock:
            taken = self.mission.dispensers[dispenser].count - self.remaining[dispenser]
            if count < 1 or self.discarded[dispenser] + count > taken:
                raise TransitionRefused(
                    f"dispenser '{dispenser}': {taken} part(s) taken,"
                    f" {self.discarded[dispenser]} already discarded;"
                    f" cannot discard {count}"
                )
            self.discarded[dispenser] += count
            self._commit()

    # ----- joints (verification) -----
    def _joint_problem(self, key: str, record: Any) -> str | None:
        """Why ``record`` is not a sound verification record of joint ``key``, or None."""
        member_id, _, joint = key.partition("@")
        member = self._members.get(member_id)
        if member is None or joint not in dict(member.joints):
            return "is no joint of a member of the mission"
        if not isinstance(record, dict) or set(record) != set(JOINT_FIELDS):
            return f"record must have exactly {', '.join(JOINT_FIELDS)}"
        for name, kind in JOINT_FIELDS.items():
            value = record[name]
            if kind is float and isinstance(value, int) and not isinstance(value, bool):
                continue
            if not isinstance(value, kind) or isinstance(value, bool):
                return f"{name} {value!r} is of the wrong type"
        if record["state"] not in JOINT_STATES:
            return f"state {record['state']!r} is not one of {', '.join(JOINT_STATES)}"
        return None

    def record_joint(self, member_id: str, joint: str, record: dict[str, Any]) -> None:
        """Keep how the ARS found ``joint`` of ``member_id`` (``record``: :data:`JOINT_FIELDS`);
        :class:`TransitionRefused` for a joint not of the member or a record that is not sound."""
        key = f"{member_id}@{joint}"
        with self.lock:
            why = self._joint_problem(key, record)
            if why:
                raise TransitionRefused(f"joint '{key}' {why}")
            self.joints[key] = dict(record)
            self._commit()

    def joints_of(self, member_id: str) -> dict[str, dict[str, Any]]:
        """The verification records of ``member_id``'s joints, by joint name."""
        prefix = f"{member_id}@"
        return {k[len(prefix) :]: dict(v) for k, v in self.joints.items() if k.startswith(prefix)}

    def open_joints(self, member_id: str) -> dict[str, dict[str, Any]]:
        """``member_id``'s joints that want the operator (failed, unverified, a retry pending)."""
        return {j: r for j, r in self.joints_of(member_id).items() if r["state"] not in ACCEPTED_JOINTS}

    def decide_joint(self, member_id: str, joint: str, state: str) -> None:
        """The operator's decision on a joint that wants one: ``confirmed`` (good as it stands) or
        ``retry`` (shoot it again); :class:`TransitionRefused` otherwise."""
        key = f"{member_id}@{joint}"
        with self.lock:
            record = self.joints.get(key)
            if record is None or record["state"] in ACCEPTED_JOINTS:
                raise TransitionRefused(f"joint '{key}' wants no decision")
            if state not in ("confirmed", "retry"):
                raise TransitionRefused(
                    f"an operator's decision on a joint is confirmed or retry, not {state!r}"
                )
            self.joints[key] = {**record, "state": state}
            self._commit()

    # ----- corrections from the ground -----
    def done_state(self, member_id: str) -> int:
        """The state in which ``member_id`` stands fixed in the tower (see :meth:`is_done`)."""
        return PLACED if self.member(member_id).kind == "cross_frame" else RIVETED

    def _lower_bay_unbuilt(self, member: Member) -> str | None:
        for other in self.mission.members:
            if other.bay < member.bay and not self.is_done(other.id):
                return (
                    f"bay {other.bay} is not built ('{other.id}' is {STATE_NAMES[self.states[other.id]]}):"
                    f" a member of bay {member.bay} stands on it"
                )
        return None

    def _higher_bay_placed(self, member: Member, why: str) -> str | None:
        for other in self.mission.members:
            if other.bay > member.bay and self.states[other.id] != NOT_PLACED:
                return (
                    f"bay {other.bay} stands on bay {member.bay} ('{other.id}' is"
                    f" {STATE_NAMES[self.states[other.id]]}): {why}"
                )
        return None

    def check_correction(self, member_id: str, mark: str) -> str | None:
        """Why the ground's ``mark`` of ``member_id`` is refused, or None when the model takes it."""
        if member_id not in self._members:
            return f"unknown member '{member_id}'"
        if mark not in MEMBER_MARKS:
            return f"unknown mark {mark!r} (marks: {', '.join(MEMBER_MARKS)})"
        member, state = self._members[member_id], self.states[member_id]
        name = STATE_NAMES[state]
        if mark == "placed":
            if self.is_done(member_id):
                return f"'{member_id}' is already placed ({name})"
            return self._lower_bay_unbuilt(member)
        if mark == "unplaced":
            if state == NOT_PLACED:
                return f"'{member_id}' is already NOT_PLACED"
            return self._higher_bay_placed(member, "unplace those first")
        if mark == "discarded":
            if self.is_done(member_id):
                return f"'{member_id}' is {name} in the tower; mark it unplaced first"
            taken = self.mission.dispensers[member.dispenser].count - self.remaining[member.dispenser]
            if self.discarded[member.dispenser] >= taken:
                return (
                    f"dispenser '{member.dispenser}': {taken} part(s) taken,"
                    f" {self.discarded[member.dispenser]} already discarded; no part of it to discard"
                )
            return None
        # needs_inspection
        if state != INSPECTED:
            if self.is_done(member_id):
                return f"'{member_id}' already waits for its bay's inspection ({name})"
            return f"'{member_id}' is {name}; only an inspected member can need inspection again"
        return self._higher_bay_placed(member, "its bay can no longer be tested")

    def correct_member(self, member_id: str, mark: str) -> None:
        """Apply the ground's ``mark`` of ``member_id``: placed (fixed in the tower: PLACED for a
        cross frame, else RIVETED), unplaced (NOT_PLACED: the tree builds it again), discarded
        (its part thrown away: NOT_PLACED, one more part discarded from its dispenser) or
        needs_inspection (back from INSPECTED: the tree tests its bay again).
        :class:`TransitionRefused` with the reason when :meth:`check_correction` refuses it."""
        with self.lock:
            reason = self.check_correction(member_id, mark)
            if reason:
                raise TransitionRefused(reason)
            if mark in ("placed", "needs_inspection"):
                self.states[member_id] = self.done_state(member_id)
            else:
                self.states[member_id] = NOT_PLACED
                for key in [k for k in self.joints if k.startswith(f"{member_id}@")]:
                    del self.joints[key]  # built again, its joints are shot and looked at anew
            if mark == "discarded":
                self.discarded[self._members[member_id].dispenser] += 1
            self._commit()

    def check_remaining(self, dispenser: str, remaining: Any) -> str | None:
        """Why the ground's count of ``dispenser`` is refused, or None when the model takes it."""
        if dispenser not in self.remaining:
            return f"unknown dispenser '{dispenser}'"
        if isinstance(remaining, bool) or not isinstance(remaining, int) or remaining < 0:
            return f"a dispenser count is a whole number of parts, 0 or more, not {remaining!r}"
        loaded, discarded = self.mission.dispensers[dispenser].count, self.discarded[dispenser]
        if remaining > loaded - discarded:
            return (
                f"dispenser '{dispenser}' can hold at most {loaded - discarded} part(s)"
                f" ({loaded} loaded, {discarded} discarded)"
            )
        if remaining == self.remaining[dispenser]:
            return f"dispenser '{dispenser}' already holds {remaining} part(s)"
        return None

    def set_remaining(self, dispenser: str, remaining: int) -> None:
        """The ground's count of the parts ``dispenser`` holds; :class:`TransitionRefused` with the
        reason when :meth:`check_remaining` refuses it."""
        with self.lock:
            reason = self.check_remaining(dispenser, remaining)
            if reason:
                raise TransitionRefused(reason)
            self.remaining[dispenser] = remaining
            self._commit()

    # ----- ROS messages -----
    def member_states(self) -> list[Any]:
        """Every member as ``tlt_interfaces/MemberState``, in build order."""
        from tlt_interfaces.msg import MemberState

        out = []
        for m in self.mission.members:
            msg = MemberState()
            msg.member_id = m.id
            msg.kind = m.kind_code
            msg.bay = m.bay
            msg.state = self.states[m.id]
            out.append(msg)
        return out

    def dispenser_states(self) -> list[Any]:
        """Every dispenser as ``tlt_interfaces/DispenserState``."""
        from tlt_interfaces.msg import DispenserState

        out = []
        for name, d in self.mission.dispensers.items():
            msg = DispenserState()
            msg.name = name
            msg.part_kind = d.part_kind
            msg.remaining = self.remaining[name]
            msg.discarded = self.discarded[name]
            out.append(msg)
        return out

    def fill_progress(self, msg: Any) -> Any:
        """Fill a ``tlt_interfaces/MissionProgress``'s model fields (mission, bays, members, dispensers)."""
        msg.mission = self.mission.name
        msg.bays_total = self.mission.bay_count
        msg.bays_built = self.bays_built()
        msg.tower_built = self.tower_built
        msg.members = self.member_states()
        msg.dispensers = self.dispenser_states()
        return msg


__all__ = [
    "ACCEPTED_JOINTS",
    "INSPECTED",
    "JOINT_FIELDS",
    "JOINT_STATES",
    "MEMBER_MARKS",
    "NOT_PLACED",
    "PLACED",
    "RIVETED",
    "STATE_NAMES",
    "TowerModel",
    "TowerModelError",
    "TransitionRefused",
    "atomic_write",
]
