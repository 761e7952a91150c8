"""Float seconds into ``builtin_interfaces`` Time/Duration fields (``sec``, ``nanosec``).

Sim time is a float summed step by step, so a whole second often arrives as 36.99999999996:
splitting that into ``int(t)`` seconds and the rounded rest gives 36 s and 1e9 ns, and wrapping
the nanoseconds then stamps the moment a full second early. The twin's /clock did exactly that at
about four whole seconds in ten, and every node's clock jumped back a second for a sync period.
Rounding to whole nanoseconds first, then splitting, cannot.
"""

from __future__ import annotations

from typing import Any

NS_PER_S = 1_000_000_000


def split_seconds(t: float) -> tuple[int, int]:
    """``t`` seconds as (sec, nanosec), nanosec in [0, 1e9), floor semantics for negatives."""
    return divmod(round(t * NS_PER_S), NS_PER_S)


def set_stamp(stamp: Any, t: float) -> None:
    """Write ``t`` seconds into a Time or Duration message's ``sec`` and ``nanosec``."""
    stamp.sec, stamp.nanosec = split_seconds(t)


def stamp_seconds(stamp: Any) -> float:
    """A Time or Duration message as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9
