"""Keep ROS 2 traffic of one run away from every other run on the same machine.

Two test sessions (or a test session and a main job) on one machine would otherwise discover each
other over DDS and exchange messages. Each run claims a ROS domain id that no other run on this
machine holds, by an exclusive lock on a file per domain, and restricts discovery to localhost.
The lock is held for the life of the process and released by the OS when it exits, even on a crash.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

# Domains 1..101 keep Fast DDS port numbers in the range Linux leaves unallocated; 0 is left to
# people running ROS by hand.
FIRST_DOMAIN = 1
LAST_DOMAIN = 101
_held: list[IO[bytes]] = []


def claim_domain(lock_dir: str | Path | None = None) -> int:
    """Claim a free ROS domain id for this process and return it.

    Raises ``RuntimeError`` when every domain in the range is held by another process.
    """
    lock_dir = Path(lock_dir or Path(tempfile.gettempdir()) / "tlt-ros-domains")
    lock_dir.mkdir(parents=True, exist_ok=True)
    start = FIRST_DOMAIN + os.getpid() % (LAST_DOMAIN - FIRST_DOMAIN + 1)
    span = LAST_DOMAIN - FIRST_DOMAIN + 1
    for i in range(span):
        domain = FIRST_DOMAIN + (start - FIRST_DOMAIN + i) % span
        handle = open(lock_dir / f"domain-{domain}.lock", "wb")  # noqa: SIM115 - held open on purpose
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        _held.append(handle)
        return domain
    raise RuntimeError(f"every ROS domain {FIRST_DOMAIN}..{LAST_DOMAIN} is held by another run")


def isolate(environ: dict[str, str] | os._Environ[str] = os.environ) -> int:
    """Claim a domain and set this process's environment (inherited by children) to use it."""
    domain = claim_domain()
    environ["ROS_DOMAIN_ID"] = str(domain)
    environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return domain
