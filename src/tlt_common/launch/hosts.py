"""Emulated hosts: Linux network namespaces joined by virtual Ethernet, one per Jetson of the EDU.

On the real unit the CRS and each ARS run on their own computer and talk over DDS. To run (and test)
that on one machine, each host becomes a network namespace ``tlt-<run>-<host>`` with its own
loopback and one interface ``eth0`` holding the host's address. The ``eth0`` of every host is one end
of a veth pair whose other end, ``p-<host>``, is a port of the bridge ``br0`` in a namespace of its
own, ``tlt-<run>-switch``. Nothing is created in the machine's own network namespace, so the
emulated network can neither disturb nor reach the real one, and deleting the namespaces removes
every veth and the bridge with them.

The switch forwards no multicast unless asked to (``multicast=True``): many real networks do not
carry it well (Wi-Fi, managed switches), and the DDS configuration of the hosts must work without it,
so the emulation proves that it does.

Cutting a host's link sets its switch port down: the host's ``eth0`` loses carrier while keeping
its address, as when its cable is pulled; healing sets the port up again. Each host ignores routes
whose link is down, as the EDU's computers are to (config/sysctl/60-tlt-link-down.conf), so a cut
host's sends to the others fail at once instead of blocking its processes.

A run holds an exclusive lock on ``<tmp>/tlt-hosts/<run>.lock`` while its network exists. Whatever
a run of the same name left behind (a launcher killed with SIGKILL) is removed when the next one
creates its network.

Everything here runs ``ip`` (iproute2) and needs root, or CAP_NET_ADMIN and CAP_SYS_ADMIN. When
that is missing, :class:`HostsUnavailable` names the command that failed and the kernel's answer,
so a test can skip with that reason.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import ipaddress
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

NETNS_DIR = Path("/run/netns")
SWITCH = "switch"
_CLONE_NEWNET = 0x40000000
_IP_TIMEOUT_S = 10.0
# Interface names are at most 15 characters; the switch port is "p-<host>".
MAX_HOST_NAME = 13
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

try:  # loaded once here: a child between fork and exec should not have to load a library
    _libc: ctypes.CDLL | None = ctypes.CDLL("libc.so.6", use_errno=True)
except OSError:
    _libc = None


class HostsError(RuntimeError):
    """The emulated hosts could not be set up or changed; the message says which step and why."""


class HostsUnavailable(HostsError):
    """This machine cannot create network namespaces (not root, no CAP_NET_ADMIN, no iproute2)."""


@dataclass(frozen=True)
class HostSpec:
    """One emulated host: its name and its address with prefix length (``10.77.0.11/24``)."""

    name: str
    address: str
    extra_addresses: tuple[str, ...] = ()

    @property
    def ip(self) -> str:
        """The host's primary address without prefix length."""
        return str(ipaddress.ip_interface(self.address).ip)


def check_host_name(name: str) -> str | None:
    """Why ``name`` cannot name a host, or None when it can."""
    if not _NAME.match(name):
        return f"expected a name of letters, digits and '_' starting with a letter, got {name!r}"
    if len(name) > MAX_HOST_NAME:
        return f"a host name has at most {MAX_HOST_NAME} characters (interface names are short), got {name!r}"
    if name == SWITCH:
        return f"{SWITCH!r} is the name of the emulated network's switch"
    return None


def check_run_name(run: str) -> None:
    """Raise :class:`HostsError` unless ``run`` can prefix namespace names unambiguously."""
    if not _NAME.match(run):
        raise HostsError(f"run name {run!r}: expected letters, digits and '_' starting with a letter")


def default_run_name(environ: dict[str, str] | os._Environ[str] = os.environ) -> str:
    """``TLT_HOSTS_RUN`` if set, else ``d<ROS_DOMAIN_ID>``: a run's domain id is already claimed
    exclusively (tlt_common.ros.isolation), so two runs on one machine get different networks."""
    return environ.get("TLT_HOSTS_RUN") or f"d{environ.get('ROS_DOMAIN_ID') or 0}"


def namespace_name(run: str, host: str) -> str:
    return f"tlt-{run}-{host}"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return _iproute2("ip", args, check)


def _bridge(*args: str) -> subprocess.CompletedProcess[str]:
    return _iproute2("bridge", args, True)


def _iproute2(tool: str, args: tuple[str, ...], check: bool) -> subprocess.CompletedProcess[str]:
    exe = shutil.which(tool) or shutil.which(tool, path="/usr/sbin:/sbin:/usr/bin:/bin")
    if exe is None:
        raise HostsUnavailable(f"the `{tool}` command (iproute2) is not installed")
    cmd = [exe, *args]
    try:
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=_IP_TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        raise HostsError(f"`{tool} {' '.join(args)}` did not finish within {_IP_TIMEOUT_S:g} s") from exc
    if check and result.returncode != 0:
        reason = (result.stderr or result.stdout).strip() or f"exit code {result.returncode}"
        raise HostsError(f"`{tool} {' '.join(args)}` failed: {reason}")
    return result


def run_namespaces(run: str) -> list[str]:
    """Names of the namespaces that exist now for ``run`` (hosts and switch)."""
    prefix = f"tlt-{run}-"
    result = _ip("netns", "list", check=False)
    names = [line.split()[0] for line in result.stdout.splitlines() if line.strip()]
    return sorted(name for name in names if name.startswith(prefix))


def _kill_namespace_processes(namespace: str) -> None:
    # A namespace that still holds a process outlives `ip netns del` (and keeps its veth): the
    # processes go first. They are ours: nothing else is started in a run's namespaces.
    pids = [int(p) for p in _ip("netns", "pids", namespace, check=False).stdout.split() if p.isdigit()]
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    deadline = time.monotonic() + 2.0
    while pids and time.monotonic() < deadline:
        pids = [p for p in pids if Path(f"/proc/{p}").exists() and not _is_zombie(p)]
        time.sleep(0.02)


def _is_zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1].startswith("Z")
    except (OSError, IndexError):
        return True


def remove_run(run: str) -> list[str]:
    """Delete every namespace of ``run`` (and so its veths and bridge); return their names.

    Used at teardown and, before a run creates its network, on whatever a crashed run of the same
    name left. Hosts go before the switch so no veth end is left waiting for its peer.
    """
    check_run_name(run)
    names = run_namespaces(run)
    switch = namespace_name(run, SWITCH)
    for name in sorted(names, key=lambda n: n == switch):
        _kill_namespace_processes(name)
        result = _ip("netns", "del", name, check=False)
        if result.returncode != 0 and name in run_namespaces(run):
            raise HostsError(f"`ip netns del {name}` failed: {result.stderr.strip()}")
    return names


def set_link(run: str, host: str, up: bool) -> None:
    """Connect (``up``) or disconnect a host's cable at the switch; works from any process."""
    _ip("-n", namespace_name(run, SWITCH), "link", "set", f"p-{host}", "up" if up else "down")


def cut_link(run: str, host: str) -> None:
    """Pull the host's cable: its ``eth0`` loses carrier, its address stays."""
    set_link(run, host, False)


def heal_link(run: str, host: str) -> None:
    """Plug the host's cable back in."""
    set_link(run, host, True)


def enter_namespace(namespace: str) -> None:
    """Move the calling process (single-threaded: a child between fork and exec) into ``namespace``."""
    # Plain string work only: this runs between fork and exec, where little is safe to do.
    fd = os.open(f"{NETNS_DIR}/{namespace}", os.O_RDONLY | os.O_CLOEXEC)
    try:
        if _libc is None:
            raise OSError(0, "setns: libc not found (not Linux)")
        if _libc.setns(fd, _CLONE_NEWNET) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"setns into {namespace}: {os.strerror(err)}")
    finally:
        os.close(fd)


@dataclass
class HostNetwork:
    """The emulated hosts of one run: create them, run processes in them, cut links, tear down.

    ``create()`` succeeds when every namespace, veth pair, address and the bridge exist and are up;
    it raises :class:`HostsUnavailable` (nothing is left behind) when the machine does not allow
    namespaces, and :class:`HostsError` for any other failure, such as a run of the same name held
    by a live process. ``teardown()`` kills what still runs in the namespaces and deletes them; it is
    safe to call twice. Use it as a context manager to get both.
    """

    run: str
    hosts: Sequence[HostSpec]
    multicast: bool = False
    lock_dir: Path = field(default_factory=lambda: Path(tempfile.gettempdir()) / "tlt-hosts")
    _lock: IO[bytes] | None = field(default=None, init=False, repr=False)
    removed_stale: list[str] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        check_run_name(self.run)
        names = [h.name for h in self.hosts]
        if not names:
            raise HostsError("no hosts to create")
        for name in names:
            if reason := check_host_name(name):
                raise HostsError(f"host {name!r}: {reason}")
        if len(set(names)) != len(names):
            raise HostsError(f"duplicate host names in {names}")
        check_addresses(self.hosts)

    # --- names ------------------------------------------------------------------------------------
    def namespace(self, host: str) -> str:
        if host not in self.host_names:
            raise HostsError(f"no host {host!r} in run {self.run!r} (hosts: {', '.join(self.host_names)})")
        return namespace_name(self.run, host)

    @property
    def host_names(self) -> list[str]:
        return [h.name for h in self.hosts]

    @property
    def switch(self) -> str:
        return namespace_name(self.run, SWITCH)

    def exec_argv(self, host: str, argv: Iterable[str]) -> list[str]:
        """``argv`` run inside ``host`` by ``ip netns exec`` (for shells and people)."""
        return ["ip", "netns", "exec", self.namespace(host), *argv]

    def preexec(self, host: str) -> Callable[[], None]:
        """A ``subprocess`` ``preexec_fn`` that moves the child into ``host`` before exec."""
        namespace = self.namespace(host)
        return lambda: enter_namespace(namespace)

    # --- life cycle -------------------------------------------------------------------------------
    def create(self) -> None:
        self._take_lock()
        try:
            self.removed_stale = remove_run(self.run)
            self._build()
        except HostsUnavailable:
            self.teardown()
            raise
        except HostsError as exc:
            self.teardown()
            if _looks_unprivileged(str(exc)):
                raise HostsUnavailable(
                    f"cannot create network namespaces: {exc} "
                    "(needs root, or CAP_NET_ADMIN and CAP_SYS_ADMIN)"
                ) from exc
            raise

    def teardown(self) -> None:
        try:
            remove_run(self.run)
        finally:
            if self._lock is not None:
                # Removed while still held, so no other run can hold the same file meanwhile.
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(self._lock_path)
                self._lock.close()
                self._lock = None

    def cut(self, host: str) -> None:
        self.namespace(host)
        cut_link(self.run, host)

    def heal(self, host: str) -> None:
        self.namespace(host)
        heal_link(self.run, host)

    def __enter__(self) -> HostNetwork:
        self.create()
        return self

    def __exit__(self, *exc: object) -> None:
        self.teardown()

    # --- inside -------------------------------------------------------------------------------------
    @property
    def _lock_path(self) -> Path:
        return self.lock_dir / f"{self.run}.lock"

    def _take_lock(self) -> None:
        self.lock_dir.mkdir(parents=True, exist_ok=True)
        path = self._lock_path
        for _ in range(10):
            handle = open(path, "ab")  # noqa: SIM115 - held open for the life of the network
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                handle.close()
                raise HostsError(
                    f"hosts run {self.run!r} is in use by another process (lock {path}); "
                    "set TLT_HOSTS_RUN to use another name"
                ) from None
            # The previous holder removes the file at teardown: a lock on a file that is no longer
            # the one at the path guards nothing, so take the new one.
            try:
                current = os.stat(path).st_ino == os.fstat(handle.fileno()).st_ino
            except FileNotFoundError:
                current = False
            if current:
                self._lock = handle
                return
            handle.close()
        raise HostsError(f"could not lock {path}: it keeps being replaced")

    def _build(self) -> None:
        switch = self.switch
        _ip("netns", "add", switch)
        # Without snooping every multicast frame is "unknown", and mcast_flood decides it per port.
        snooping = "1" if self.multicast else "0"
        _ip(
            "-n",
            switch,
            "link",
            "add",
            "br0",
            "type",
            "bridge",
            "forward_delay",
            "0",
            "stp_state",
            "0",
            "mcast_snooping",
            snooping,
        )
        _ip("-n", switch, "link", "set", "br0", "up")
        for host in self.hosts:
            ns = namespace_name(self.run, host.name)
            port = f"p-{host.name}"
            _ip("netns", "add", ns)
            _ip("-n", ns, "link", "set", "lo", "up")
            # Both ends are created straight inside their namespaces: no name ever appears in the
            # machine's own namespace, where it could clash with another run's.
            _ip("link", "add", "eth0", "netns", ns, "type", "veth", "peer", "name", port, "netns", switch)
            for address in (host.address, *host.extra_addresses):
                _ip("-n", ns, "addr", "add", address, "dev", "eth0")
            _ignore_routes_with_linkdown(ns)
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", switch, "link", "set", port, "master", "br0")
            if not self.multicast:
                _bridge("-n", switch, "link", "set", "dev", port, "mcast_flood", "off")
            _ip("-n", switch, "link", "set", port, "up")


def _ignore_routes_with_linkdown(namespace: str) -> None:
    """Make a host's sends to the other hosts fail at once while its ``eth0`` has no carrier.

    Linux keeps using a route whose link is down: each datagram to another host waits for an ARP
    answer that cannot come, queued up to ``unres_qlen_bytes`` per neighbour (as large as a socket's
    whole send buffer) and charged to the sending socket until resolution fails some 3 s later. Fast
    DDS sends everything of a participant through one blocking socket, so during a cut its writes and
    discovery announcements, to the processes of its own host too, stall for most of a cut. Past
    the 3 s lease participants of one host can drop each other, and after the heal an ARS can stay
    deaf to its own driver. A real Jetson with its cable pulled does the same
    (docs/deployment.md).
    """
    # /proc/sys/net is the namespace's own inside it; "all" counts for every interface.
    setting = "/proc/sys/net/ipv4/conf/all/ignore_routes_with_linkdown"
    _ip("netns", "exec", namespace, "sh", "-c", f"echo 1 > {setting}")


def _looks_unprivileged(message: str) -> bool:
    return any(s in message for s in ("Operation not permitted", "Permission denied", "not permitted"))


def check_addresses(hosts: Sequence[HostSpec]) -> None:
    """Raise :class:`HostsError` unless every address is valid IPv4, unique, and on one subnet."""
    network = None
    seen: dict[str, str] = {}
    for host in hosts:
        for address in (host.address, *host.extra_addresses):
            try:
                iface = ipaddress.IPv4Interface(address)
            except ValueError as exc:
                raise HostsError(f"host {host.name!r}: {address!r} is not an IPv4 address: {exc}") from None
            if iface.network.prefixlen == 32 and "/" not in address:
                raise HostsError(f"host {host.name!r}: {address!r} needs a prefix length, e.g. {address}/24")
            if iface.ip in (iface.network.network_address, iface.network.broadcast_address):
                raise HostsError(f"host {host.name!r}: {address} is the network or broadcast address")
            network = network or iface.network
            if iface.network != network:
                raise HostsError(f"host {host.name!r}: {address} is not on {network}, the hosts' network")
            if str(iface.ip) in seen:
                raise HostsError(
                    f"host {host.name!r}: {iface.ip} is already the address of {seen[str(iface.ip)]!r}"
                )
            seen[str(iface.ip)] = host.name


def unavailable_reason(run: str | None = None) -> str | None:
    """Why this machine cannot run emulated hosts, or None when it can (creates and removes two)."""
    hosts = [HostSpec("a", "10.77.0.1/24"), HostSpec("b", "10.77.0.2/24")]
    probe = HostNetwork(run or f"probe{os.getpid()}", hosts)
    try:
        probe.create()
    except HostsError as exc:
        return str(exc)
    finally:
        probe.teardown()
    return None
