"""The working data of one ARS request, and the file that keeps across a restart what the ARS
must not forget: the part in its gripper, a rivet in its gun, the step that sets a member while it
is in doubt, and the last request that set its member.

A member is set (the rivet fired, the cross frame released where it belongs) before the gripper
lets go and the arm retreats from the tower. An ARS killed in between comes back knowing nothing of
it, and the CRS, which never heard the result, sends the same request again: run afresh, it would
fetch another part for a place that is taken. And an ARS killed, or a request failed, while a part
is held would otherwise plan the next request's motions without that part and open the jaws on it
at a dispenser; and one whose gun holds a rivet would push the loaded gun into the rivet feeder.
And an ARS killed while the step that sets the member runs (the gun firing, a cross frame let go of
at its place), or whose gun was never seen to stop, does not know whether the member is set: a held
member discarded then would be torn out of the tower, a cross frame fetched again would meet the
one in place. So the ARS's state file (``state_file`` in the ARS file, ``--state-file``) is written
when a part is taken into the gripper or a rivet into the gun, when the part is let go of, just
before that step (with the arm's joints then), and when a request sets its member, and read back at
start-up: :class:`tlt_ars.context.ArsContext` finishes the kept request when it is sent again
(after a step left in doubt, by doing it again from where the arm still stands: a spent gun fires
empty, open jaws stay open), has a held part discarded before anything else, and looks for the kept
rivet before loading one. What the file keeps is what that needs: the request, what it set or was
setting, the part held and its dispenser, the rivet, and the targets its approaches chose (the
retreat goes back along the one its fine move took), and the shots at its joint and the looks at it
(Verify Joint), reported again when it is finished. It is removed once none is left.

The file is JSON, written whole (:func:`tlt_common.mission.tower_model.atomic_write`); one that
cannot be read, is not such a file, or belongs to another mission or ARS raises
:class:`RequestFileError` with the path and the reason: the ARS then refuses to start, as the CRS
does with its tower model, since guessing would risk the very double placement the file prevents.
"""

from __future__ import annotations

import contextlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tlt_ars.config import PART_KINDS
from tlt_ars.mission_state import Request
from tlt_ars.planning.targets import Target
from tlt_common.mission.schema import Member, Mission
from tlt_common.mission.tower_model import atomic_write

FILE_FORMAT = 1
RECORDS = ("placed", "affixed", "riveted")
HELD_KINDS = tuple(k for k in PART_KINDS if k != "rivet")  # a rivet rides in the gun


@dataclass(frozen=True)
class JointLook:
    """One look at the request's joint after its ``shot``-th shot (VerifyJoint): the verdict, why,
    and the figures it rests on (m; the head's world position when one was seen)."""

    joint: str
    shot: int
    verdict: str
    reason: str
    height: float = 0.0
    along: float = 0.0
    pixels: int = 0
    head: tuple[float, float, float] | None = None
    camera: str = ""


@dataclass
class RequestData:
    """Working data of one request; a fresh one for every request."""

    request: Request | None = None
    member: Member | None = None
    holding: str | None = None  # part kind in the gripper, for the collision scene
    dispenser: str | None = None  # the dispenser the held part came from
    discarded_from: list[str] = field(default_factory=list)  # the dispenser of each part discarded
    targets: dict[str, Any] = field(default_factory=dict)  # approach name -> chosen Target
    recorded: str = ""  # what the request set in the mission state: placed, affixed, riveted
    rivet_in_gun: bool = False  # seen loaded (Verify Rivet Loaded) and not fired since
    # What the step that sets the member (the gun's shot, a cross frame let go of at its place)
    # sets, from just before that step until the record, and the arm's joints (planning order) then.
    setting: str = ""
    setting_q: tuple[float, ...] | None = None
    located: dict[str, np.ndarray] = field(default_factory=dict)  # dispenser -> world pose from its tag
    alignment: Any = None  # the latest CheckAlignment response
    shots: int = 0  # rivet shots at the request's joint (Verify Joint counts them)
    looks: list[JointLook] = field(default_factory=list)  # every look at that joint, in order

    @property
    def parts_discarded(self) -> int:
        return len(self.discarded_from)

    def worth_keeping(self) -> bool:
        """Whether a restart must know of this request: it holds a part or a rivet, or has set
        its member or may have."""
        return bool(self.unfinished() or self.holding or self.rivet_in_gun)

    def unfinished(self) -> bool:
        """Whether the request set its member, or may have (the step that sets it left in doubt):
        sent again, it is finished, never run afresh."""
        return bool(self.recorded or self.setting)


class RequestFileError(RuntimeError):
    """A state file the ARS cannot resume from (unreadable, not such a file, another mission)."""


class RequestFile:
    """The state file of one ARS (``path``) for ``mission``; see the module docstring."""

    def __init__(self, path: str | Path, mission: Mission, ars: str) -> None:
        self.path = Path(path)
        self.mission = mission
        self.ars = ars

    def save(self, data: RequestData) -> None:
        """Keep ``data``, a request that holds a part or a rivet, or has set its member."""
        if data.request is None or not data.worth_keeping():
            raise ValueError("only a request that holds a part or a rivet, or has set its member, is kept")
        document = {
            "format": FILE_FORMAT,
            "mission": self.mission.name,
            "mission_hash": self.mission.hash,
            "ars": self.ars,
            "request": asdict(data.request),
            "recorded": data.recorded,
            "holding": data.holding,
            "dispenser": data.dispenser,
            "rivet_in_gun": data.rivet_in_gun,
            "setting": data.setting,
            "setting_q": list(data.setting_q) if data.setting_q is not None else None,
            "shots": data.shots,
            "looks": [asdict(look) for look in data.looks],
            "targets": {
                key: {"label": t.label, "pose": t.pose.tolist(), "pre_pose": t.pre_pose.tolist()}
                for key, t in data.targets.items()
            },
        }
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(self.path, json.dumps(document, indent=1).encode())

    def clear(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()

    def load(self) -> RequestData | None:
        """The request kept in the file, or None without a file; :class:`RequestFileError` when
        the file cannot be resumed from."""
        for stale in self.path.parent.glob(f".{self.path.name}.*.tmp"):  # writers killed mid-write
            with contextlib.suppress(OSError):
                stale.unlink()
        try:
            text = self.path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise self._error(f"cannot be read: {exc.strerror or exc}") from exc
        try:
            document = json.loads(text)
        except (ValueError, UnicodeDecodeError) as exc:
            raise self._error(f"is not valid JSON ({exc}); it may be corrupt") from exc
        if not isinstance(document, dict) or document.get("format") != FILE_FORMAT:
            raise self._error(f"is not an ARS state file of format {FILE_FORMAT}")
        if document.get("mission_hash") != self.mission.hash:
            raise self._error(
                f"belongs to mission '{document.get('mission')}', not to '{self.mission.name}'"
                f" ({self.mission.hash[:12]})"
            )
        if document.get("ars") != self.ars:
            raise self._error(f"belongs to '{document.get('ars')}', not to '{self.ars}'")
        try:
            request = Request(**document["request"])
            member = self.mission.member(request.member_id)
            targets = {
                key: Target(str(t["label"]), _pose(t["pose"]), _pose(t["pre_pose"]))
                for key, t in document["targets"].items()
            }
            recorded, holding, dispenser = document["recorded"], document["holding"], document["dispenser"]
            rivet_in_gun = document["rivet_in_gun"]
            # Files written before the step that sets the member was kept have neither.
            setting, setting_q = document.get("setting", ""), document.get("setting_q")
            if setting_q is not None:
                setting_q = tuple(float(v) for v in setting_q)
            # Files written without joint verification have no shots or looks.
            shots = int(document.get("shots", 0))
            looks = [_look(entry) for entry in document.get("looks", [])]
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise self._error(f"has a bad entry: {type(exc).__name__}: {exc}") from exc
        if recorded not in ("", *RECORDS):
            raise self._error(f"'recorded' is {recorded!r}, not one of {', '.join(RECORDS)} or empty")
        if holding not in (None, *HELD_KINDS):
            raise self._error(f"'holding' is {holding!r}, not one of {', '.join(HELD_KINDS)} or null")
        if setting not in ("", *RECORDS):
            raise self._error(f"'setting' is {setting!r}, not one of {', '.join(RECORDS)} or empty")
        if setting and (setting_q is None or not np.all(np.isfinite(setting_q))):
            raise self._error(f"'setting' is {setting!r} but 'setting_q' is {setting_q!r}, not joints")
        if not isinstance(rivet_in_gun, bool):
            raise self._error(f"'rivet_in_gun' is {rivet_in_gun!r}, not true or false")
        if dispenser is not None and dispenser not in self.mission.dispensers:
            raise self._error(f"'dispenser' is {dispenser!r}, not one of mission '{self.mission.name}'")
        return RequestData(
            request=request,
            member=member,
            holding=holding,
            dispenser=dispenser,
            targets=targets,
            recorded=recorded,
            rivet_in_gun=rivet_in_gun,
            setting=setting,
            setting_q=setting_q if setting else None,
            shots=shots,
            looks=looks,
        )

    def _error(self, reason: str) -> RequestFileError:
        return RequestFileError(f"{self.path}: ARS state file {reason}")


def _look(entry: Any) -> JointLook:
    look = JointLook(**entry)
    head = None if look.head is None else tuple(float(v) for v in look.head)
    if head is not None and len(head) != 3:
        raise ValueError(f"a look's head must be 3 numbers, got {look.head!r}")
    return JointLook(
        str(look.joint), int(look.shot), str(look.verdict), str(look.reason),
        float(look.height), float(look.along), int(look.pixels), head, str(look.camera),
    )  # fmt: skip


def _pose(value: Any) -> np.ndarray:
    pose = np.asarray(value, dtype=float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError(f"a pose must be 4x4 finite numbers, got shape {pose.shape}")
    return pose


__all__ = ["JointLook", "RequestData", "RequestFile", "RequestFileError"]
