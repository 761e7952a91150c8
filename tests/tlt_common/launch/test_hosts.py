"""Emulated hosts as network namespaces: packets cross the switch, a cut link stops them and a healed
one carries them again, multicast stays off the switch, and nothing is left behind: not after a
teardown, not after a crash (the next run of the same name removes it), not after a failure.

Where this machine cannot create network namespaces the tests skip with the reason it gave."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from tlt_common.launch.hosts import (
    HostNetwork,
    HostsError,
    HostSpec,
    run_namespaces,
    unavailable_reason,
)
from tlt_common.launch.hosts_cli import main as hosts_main

RUN = f"u{os.environ.get('ROS_DOMAIN_ID', '0')}"
HOSTS = [HostSpec("a", "10.77.0.11/24"), HostSpec("b", "10.77.0.12/24", ("10.77.0.21/24",))]


@pytest.fixture(scope="module", autouse=True)
def namespaces_available():
    reason = unavailable_reason(f"{RUN}probe")
    if reason:
        pytest.skip(f"network namespaces are not available here: {reason}")


@pytest.fixture
def network():
    net = HostNetwork(RUN, HOSTS)
    net.create()
    yield net
    net.teardown()
    assert run_namespaces(RUN) == []


class Receiver:
    """A UDP (optionally multicast) receiver inside a host, printing each datagram it gets."""

    def __init__(self, net: HostNetwork, host: str, bind: str, port: int, group: str | None = None) -> None:
        join = ""
        if group:
            join = (
                f"s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, "
                f"socket.inet_aton('{group}') + socket.inet_aton('{bind}'))\n"
            )
        code = (
            textwrap.dedent(f"""
            import socket
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(('{"0.0.0.0" if group else bind}', {port}))
            """)
            + join
            + textwrap.dedent("""
            print('ready', flush=True)
            while True:
                print(s.recv(100).decode(), flush=True)
            """)
        )
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, preexec_fn=net.preexec(host)
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "ready"
        self.got: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.got.append(line.strip())

    def received(self, message: str, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if message in self.got:
                return True
            time.sleep(0.05)
        return message in self.got

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait()


def send(net: HostNetwork, host: str, source: str, to: str, port: int, message: str, repeat: int = 5) -> None:
    """Send ``message`` a few times from ``host`` (UDP may lose the first while ARP resolves)."""
    code = textwrap.dedent(f"""
        import socket, time
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton('{source}'))
        for _ in range({repeat}):
            try:
                s.sendto(b'{message}', ('{to}', {port}))
            except OSError:
                pass  # no route while the link is down: the datagram is lost, as it would be
            time.sleep(0.05)
        """)
    subprocess.run([sys.executable, "-c", code], check=True, timeout=30, preexec_fn=net.preexec(host))


def test_hosts_reach_each_other_and_a_cut_link_drops_their_packets(network):
    receiver = Receiver(network, "b", "10.77.0.21", 47001)
    try:
        send(network, "a", "10.77.0.11", "10.77.0.21", 47001, "before")
        assert receiver.received("before", timeout=10)

        network.cut("b")
        link = subprocess.run(
            ["ip", "-n", network.namespace("b"), "addr", "show", "eth0"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        assert "NO-CARRIER" in link and "10.77.0.12/24" in link  # a pulled cable: the address stays
        send(network, "a", "10.77.0.11", "10.77.0.21", 47001, "while-cut")
        assert not receiver.received("while-cut", timeout=1.0)

        network.heal("b")
        send(network, "a", "10.77.0.11", "10.77.0.21", 47001, "after")
        assert receiver.received("after", timeout=10)
        assert "while-cut" not in receiver.got
    finally:
        receiver.stop()


def test_a_cut_host_fails_its_sends_to_other_hosts_at_once_and_still_reaches_itself(network):
    # Were the route kept while the link is down, the datagram would be queued for an ARP answer
    # that cannot come, blocking the sender once its socket's buffer is full (hosts.py).
    code = textwrap.dedent("""
        import errno, socket
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.sendto(b'x' * 2000, ('10.77.0.11', 47002))
            print('queued')
        except OSError as exc:
            print(errno.errorcode[exc.errno])
        r = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        r.bind(('10.77.0.12', 47003))
        r.settimeout(5)
        s.sendto(b'self', ('10.77.0.12', 47003))
        print(r.recv(10).decode())
        """)
    network.cut("b")
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
        preexec_fn=network.preexec("b"),
    ).stdout.split()
    assert out == ["ENETUNREACH", "self"], out


@pytest.mark.parametrize("multicast", [False, True])
def test_the_switch_forwards_multicast_only_when_asked(multicast):
    with HostNetwork(RUN, HOSTS, multicast=multicast) as net:
        receiver = Receiver(net, "b", "10.77.0.12", 47002, group="239.255.77.1")
        try:
            send(net, "a", "10.77.0.11", "10.77.0.12", 47002, "unicast")
            assert receiver.received("unicast", timeout=10)
            send(net, "a", "10.77.0.11", "239.255.77.1", 47002, "multicast", repeat=10)
            assert receiver.received("multicast", timeout=1.0 if not multicast else 10) is multicast
        finally:
            receiver.stop()
    assert run_namespaces(RUN) == []


def _root_links() -> set[str]:
    out = subprocess.run(["ip", "-o", "link", "show"], capture_output=True, text=True, check=True).stdout
    return {line.split(":")[1].strip() for line in out.splitlines()}


def test_teardown_ends_what_runs_inside_and_leaves_nothing():
    links_before = _root_links()
    net = HostNetwork(RUN, HOSTS)
    net.create()
    assert run_namespaces(RUN) == [f"tlt-{RUN}-a", f"tlt-{RUN}-b", f"tlt-{RUN}-switch"]
    assert _root_links() == links_before  # nothing of the emulated network in the machine's own
    sleeper = subprocess.Popen(
        [sys.executable, "-c", "import time; time.sleep(60)"], preexec_fn=net.preexec("a")
    )
    net.teardown()
    assert sleeper.wait(timeout=10) == -9
    assert run_namespaces(RUN) == []
    assert _root_links() == links_before
    assert not (net.lock_dir / f"{RUN}.lock").exists()
    net.teardown()  # a second time is harmless


def test_a_crashed_run_is_removed_by_the_next_run_of_the_same_name():
    crash = textwrap.dedent(f"""
        import os
        from tlt_common.launch.hosts import HostNetwork, HostSpec
        HostNetwork({RUN!r}, [HostSpec('a', '10.77.0.11/24')]).create()
        os._exit(9)  # no teardown, as after a SIGKILL
        """)
    assert subprocess.run([sys.executable, "-c", crash], timeout=60).returncode == 9
    left = run_namespaces(RUN)
    assert left == [f"tlt-{RUN}-a", f"tlt-{RUN}-switch"]
    with HostNetwork(RUN, HOSTS) as net:
        assert net.removed_stale == left
        assert run_namespaces(RUN) == [f"tlt-{RUN}-a", f"tlt-{RUN}-b", f"tlt-{RUN}-switch"]
    assert run_namespaces(RUN) == []


def test_a_run_held_by_a_live_network_is_refused_and_left_alone(network):
    with pytest.raises(HostsError, match=f"hosts run '{RUN}' is in use by another process"):
        HostNetwork(RUN, HOSTS).create()
    assert len(run_namespaces(RUN)) == 3  # the live run's network is untouched


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="setpriv (util-linux) is not installed")
def test_without_privileges_creation_fails_naming_what_failed():
    attempt = textwrap.dedent(f"""
        from tlt_common.launch.hosts import HostNetwork, HostSpec, HostsUnavailable
        try:
            HostNetwork({RUN!r}, [HostSpec('a', '10.77.0.11/24')]).create()
        except HostsUnavailable as exc:
            print(exc)
        """)
    # Root without any capability: what an unprivileged CI container looks like.
    result = subprocess.run(
        ["setpriv", "--bounding-set=-all", "--inh-caps=-all", sys.executable, "-c", attempt],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert f"cannot create network namespaces: `ip netns add tlt-{RUN}-switch` failed:" in result.stdout
    assert "Operation not permitted" in result.stdout
    assert "needs root, or CAP_NET_ADMIN and CAP_SYS_ADMIN" in result.stdout
    assert run_namespaces(RUN) == []


def test_the_hosts_command_cuts_heals_and_lists(network, capsys):
    assert hosts_main(["--run", RUN, "list"]) == 0
    assert capsys.readouterr().out.split() == [f"tlt-{RUN}-a", f"tlt-{RUN}-b", f"tlt-{RUN}-switch"]
    eth0 = ["ip", "-n", network.namespace("b"), "link", "show", "eth0"]
    assert hosts_main(["--run", RUN, "cut", "b"]) == 0
    assert "NO-CARRIER" in subprocess.run(eth0, capture_output=True, text=True, check=True).stdout
    assert hosts_main(["--run", RUN, "heal", "b"]) == 0
    assert "NO-CARRIER" not in subprocess.run(eth0, capture_output=True, text=True, check=True).stdout
    capsys.readouterr()
    assert hosts_main(["--run", RUN, "cut", "c"]) == 1
    assert f"tlt hosts: no host 'c' in run '{RUN}'" in capsys.readouterr().err
