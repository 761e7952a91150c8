"""Reason codes carried by acknowledgement and event packets of the ground link.

The numeric value is the wire code. ``config/ccsds/definitions.yaml`` lists the same names under
``enums.reason`` in the same order, and loading the definitions fails if the two disagree, so the
ground displays exactly the reasons the CRS sends.
"""

from __future__ import annotations

import enum


class Reason(enum.IntEnum):
    """Why a datagram or a command was rejected, or why a command failed."""

    NONE = 0
    MALFORMED = 1
    TRUNCATED = 2
    OVERSIZED = 3
    BAD_CRC = 4
    UNKNOWN_APID = 5
    WRONG_PACKET_TYPE = 6
    BAD_VERSION = 7
    UNKNOWN_COMMAND = 8
    BAD_AUTH = 9
    UNKNOWN_KEY = 10
    REPLAY = 11
    BAD_PARAMETER_TYPE = 12
    BAD_PARAMETER_RANGE = 13
    REFUSED = 14
    EXECUTION_FAILED = 15
    INTERNAL_ERROR = 16
    # Dropped unparsed: the datagram came from an address the receiver's accept_from does not name.
    SOURCE = 17

    @property
    def label(self) -> str:
        return self.name.lower()


class AckStage(enum.IntEnum):
    """Stages of a command acknowledgement; ACCEPTED or REJECTED first, then COMPLETED or FAILED."""

    ACCEPTED = 0
    REJECTED = 1
    COMPLETED = 2
    FAILED = 3

    @property
    def label(self) -> str:
        return self.name.lower()

    @property
    def final(self) -> bool:
        return self is not AckStage.ACCEPTED


class Severity(enum.IntEnum):
    """Event severities (the values of tlt_interfaces/Event)."""

    DEBUG = 0
    INFO = 1
    WARNING = 2
    ERROR = 3
    CRITICAL = 4


__all__ = ["AckStage", "Reason", "Severity"]
