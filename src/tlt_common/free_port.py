"""A UDP port for another process to bind later: one the kernel does not hand out meanwhile.

The usual way (bind port 0, read the port, close) returns a port from the kernel's ephemeral
range, which the next socket bound to port 0 anywhere on the machine may get before the process
meant to bind it does, and that process then fails with "address already in use" before it sends
anything. Ports above that range are never
handed out for port 0, so a port drawn there at random and found free stays free but for another
such draw.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")
TRIES = 200


def _above_ephemeral() -> range:
    try:
        high = int(EPHEMERAL_RANGE.read_text().split()[1])
    except (OSError, IndexError, ValueError):
        high = 60999  # Linux's default
    return range(high + 1, 65536)


def free_udp_port(host: str = "127.0.0.1") -> int:
    """A UDP port on ``host`` that nothing holds now, above the kernel's ephemeral range when it
    leaves room there, else one the kernel chose."""
    ports = _above_ephemeral()
    rng = random.SystemRandom()
    for _ in range(TRIES if len(ports) else 0):
        port = rng.choice(ports)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind((host, port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind((host, 0))
        return sock.getsockname()[1]


__all__ = ["free_udp_port"]
