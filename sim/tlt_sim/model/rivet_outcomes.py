"""How a rivet shot turns out in the twin: a good joint, or one of the ways a rivet fails.

Each joint a shot reaches (a strut end at a cross frame corner, or a corner on a foundation pad)
gets one of :data:`KINDS`. A scenario's injected fault for that joint and shot decides it
(:class:`RivetFaultPlan`); otherwise where the gun stands does (:func:`judge_geometry`): a muzzle
within ``rivets.max_offset`` of the hole and a bar within ``rivets.max_angle_deg`` of the member's
axis (``config/twin/edu.yaml``) set a good rivet; a muzzle farther off leaves the head proud, a bar
askew grips only partly.

What each kind leaves (:data:`EFFECTS`), mechanically and to a camera:

======================  ==============================  ==========================================
kind                    joint (weld or connect)         head, gun
======================  ==============================  ==========================================
``good``                ``physics.rivet_solref``         seated in its hole; gun spent
``proud_head``          ``rivets.unseated_solref``       ``proud_height`` out, its shank showing
``partial_grip``        ``rivets.unseated_solref``       ``partial_grip_height`` out, shank showing
``loose``               ``rivets.loose_solref``          seated (only the compression test shows it)
``wrong_hole``          none                             seated in the neighbouring hole
``no_rivet``            none                             none; the gun fires empty (rivet lost)
``misfire``             none                             none; the rivet stays in the gun
======================  ==============================  ==========================================

``no_rivet`` and ``misfire`` are faults of the whole shot: injected at any joint the gun reaches,
they spoil every joint of that shot. A later shot at a joint replaces its outcome (the bad rivet
drilled out), so a second shot can repair what the first did wrong.

The outcomes are the twin's truth, for judging only: nothing in the system under test reads them.
"""

from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

KINDS = ("good", "proud_head", "partial_grip", "loose", "wrong_hole", "no_rivet", "misfire")
FAULT_KINDS = KINDS[1:]
SHOT_KINDS = ("no_rivet", "misfire")  # the whole shot fails


@dataclass(frozen=True)
class Effect:
    """What a kind of outcome leaves at the joint: whether the rivet joins it (a weld at a strut
    end, a connect at the foundation), the ``rivets`` solref key of a joint that holds more softly
    than a good one (None: as built, ``physics.rivet_solref`` / ``hold_solref``), the head
    (``seated``, ``proud``, ``partial``, ``wrong_hole``; None: no head) and whether the rivet left
    the gun."""

    joins: bool
    softer: str | None
    head: str | None
    spent: bool = True


EFFECTS = {
    "good": Effect(True, None, "seated"),
    "proud_head": Effect(True, "unseated_solref", "proud"),
    "partial_grip": Effect(True, "unseated_solref", "partial"),
    "loose": Effect(True, "loose_solref", "seated"),
    "wrong_hole": Effect(False, None, "wrong_hole"),
    "no_rivet": Effect(False, None, None),
    "misfire": Effect(False, None, None, spent=False),
}


def judge_geometry(offset_m: float, angle_deg: float, rivets: dict[str, Any]) -> tuple[str, str]:
    """The outcome of a shot whose muzzle stands ``offset_m`` from the hole with its bar
    ``angle_deg`` off the member's axis, under the tolerances ``rivets`` (edu.yaml ``rivets``):
    the kind and why."""
    if offset_m > rivets["max_offset"]:
        return (
            "proud_head",
            f"gun {1000 * offset_m:.1f} mm off the hole (tolerates {1000 * rivets['max_offset']:.1f})",
        )
    if angle_deg > rivets["max_angle_deg"]:
        return (
            "partial_grip",
            f"gun {angle_deg:.1f} deg off the member's axis (tolerates {rivets['max_angle_deg']:.1f})",
        )
    return "good", "within tolerance"


def bar_angle_deg(bar: np.ndarray, axis: np.ndarray) -> float:
    """Angle (deg, 0 to 90) between the gun's bar and a member's axis, either way along each."""
    cos = abs(float(bar @ axis)) / float(np.linalg.norm(bar) * np.linalg.norm(axis))
    return float(np.degrees(np.arccos(min(1.0, cos))))


@dataclass(frozen=True)
class RandomRivetFaults:
    """Faults drawn at random: each joint's first shot fails with probability ``rate``, as one of
    ``kinds`` (equally likely). The draw depends on the seed and the joint alone, not on the order
    the joints are riveted in, so a run and its repetition fail the same joints."""

    rate: float
    seed: int
    kinds: tuple[str, ...] = FAULT_KINDS

    def draw(self, member: str, joint: str) -> str | None:
        rng = np.random.default_rng([self.seed, zlib.crc32(f"{member}@{joint}".encode())])
        if rng.random() >= self.rate:
            return None
        return self.kinds[int(rng.integers(len(self.kinds)))]


@dataclass(frozen=True)
class RivetFaultPlan:
    """A scenario's rivet faults: ``chosen`` ((member id, joint id, shot number) -> kind) and,
    for first shots that none is chosen for, ``random``."""

    chosen: dict[tuple[str, str, int], str]
    random: RandomRivetFaults | None = None

    def injected(self, member: str, joint: str, shot: int) -> str | None:
        """The fault injected at shot number ``shot`` (1 = first) on ``joint`` of ``member``."""
        kind = self.chosen.get((member, joint, shot))
        if kind is None and shot == 1 and self.random is not None:
            kind = self.random.draw(member, joint)
        return kind


NO_FAULTS = RivetFaultPlan({})


@dataclass(frozen=True)
class RivetJoint:
    """One joint's outcome as the twin knows it (its latest shot; ``cause``: geometry, injected,
    staged). ``member`` and ``joint`` are the mission's ids ('' where the part stands at no place
    of the mission); ``equality`` the weld or connect it makes or would have made."""

    member: str
    joint: str
    equality: str
    kind: str
    cause: str
    reason: str
    shot: int  # shots at this joint so far, this one included
    arm: str = ""
    side: str = ""
    time: float = 0.0
    offset_m: float = 0.0
    angle_deg: float = 0.0

    @property
    def good(self) -> bool:
        return self.kind == "good"

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def describe(self) -> str:
        where = f"{self.member} at {self.joint}" if self.member else self.equality
        return f"{where}: {self.kind} ({self.cause}: {self.reason})"


__all__ = [
    "EFFECTS",
    "FAULT_KINDS",
    "KINDS",
    "NO_FAULTS",
    "SHOT_KINDS",
    "Effect",
    "RandomRivetFaults",
    "RivetFaultPlan",
    "RivetJoint",
    "bar_angle_deg",
    "judge_geometry",
]
