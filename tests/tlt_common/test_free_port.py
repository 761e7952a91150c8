"""A port for another process to bind later is drawn where the kernel does not hand ports out."""

from __future__ import annotations

import socket

from tlt_common import free_port
from tlt_common.free_port import free_udp_port


def test_the_port_lies_above_the_ephemeral_range_and_can_be_bound():
    high = int(free_port.EPHEMERAL_RANGE.read_text().split()[1])
    ports = {free_udp_port() for _ in range(20)}
    if high < 65535:
        assert all(high < p <= 65535 for p in ports), ports
    assert len(ports) > 10  # drawn at random, not the same one each time
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", ports.pop()))


def test_a_port_held_is_not_given_and_a_full_range_falls_back_to_the_kernels_choice(monkeypatch):
    held = []
    try:
        for port in free_port._above_ephemeral()[:3]:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                sock.close()
                continue
            held.append(sock)
        taken = {s.getsockname()[1] for s in held}
        monkeypatch.setattr(free_port, "_above_ephemeral", lambda: range(min(taken), max(taken) + 1))
        monkeypatch.setattr(free_port, "TRIES", 20)
        port = free_udp_port()  # every port of the range held: the kernel picks one
        assert port not in taken
        low, high = map(int, free_port.EPHEMERAL_RANGE.read_text().split())
        assert low <= port <= high
    finally:
        for sock in held:
            sock.close()
