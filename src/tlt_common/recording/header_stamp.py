"""Read a message's ``header.stamp`` straight from its CDR bytes, without deserializing it.

For a type whose first field is ``std_msgs/Header``, the stamp (``int32 sec``, ``uint32 nanosec``)
is the first thing after the 4-byte encapsulation header, in the byte order that header names.
"""

from __future__ import annotations

import struct

# Encapsulation identifiers (first two bytes) of plain CDR and XCDR2, big- and little-endian.
_BIG_ENDIAN = {b"\x00\x00", b"\x00\x06", b"\x00\x10"}
_LITTLE_ENDIAN = {b"\x00\x01", b"\x00\x07", b"\x00\x11"}


def header_stamp_ns(data: bytes) -> int | None:
    """The stamp of a serialized message that starts with a Header, in nanoseconds.

    Returns None when the bytes are too short, the encapsulation is not one this reads, or the
    stamp is zero or negative (unset), so the caller falls back to the receive time.
    """
    if len(data) < 12:
        return None
    kind = bytes(data[0:2])
    if kind in _LITTLE_ENDIAN:
        sec, nanosec = struct.unpack_from("<iI", data, 4)
    elif kind in _BIG_ENDIAN:
        sec, nanosec = struct.unpack_from(">iI", data, 4)
    else:
        return None
    if sec < 0 or (sec == 0 and nanosec == 0) or nanosec >= 1_000_000_000:
        return None
    return sec * 1_000_000_000 + nanosec
