"""Start, watch, restart and stop the processes of a launch set.

Every process runs in its own process group, so a signal reaches it and anything it started; each
also asks the kernel to send it SIGTERM if the launcher dies, so even a SIGKILLed launcher leaves
no orphan. Output lines are prefixed with the process name; with a log folder, each process's
output also goes, unprefixed, to ``<folder>/<name>.log`` (with the launcher's lines about it, each
starting ``[launch]``), which restarts append to and a new launcher run starts afresh. Shutdown
(Ctrl-C, SIGTERM, or a required process that died for good) sends SIGINT, then SIGTERM, then
SIGKILL, each after the set's grace period; a second Ctrl-C skips the waiting. The exit status is
0 after a clean stop, 1 when a required process died, 2 when a process marked ``on_refusal:
shutdown`` refused to run (exited 2: a mission its arm cannot reach, say), and a process's own when
it ends the set (``on_exit: shutdown``), also when a signal stopped it along with the rest: a
mission job interrupted during a build says so. A refusal's reason, the last line the process
wrote, is said again once every process has stopped, so that it is the set's last word and not
lost above the others' output.

A set that declares hosts gets its emulated network (``hosts.HostNetwork``) before any process
starts and loses it after every process has stopped; a process with a host is moved into that
host's network namespace between fork and exec and given the Fast DDS profile of the network.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any, TextIO

from tlt_common.launch.dds_profile import host_environment, render_profile
from tlt_common.launch.hosts import HostNetwork, HostsError, default_run_name, enter_namespace, namespace_name
from tlt_common.launch.launch_set import REFUSED, LaunchSet, ProcessSpec

_POLL_S = 0.05
_LAST_LINES = 15

# A signal's handler as signal.signal takes and returns it.
_Handler = Callable[[int, FrameType | None], Any] | int | None

_prctl: Callable[..., int] | None
try:
    _prctl = ctypes.CDLL("libc.so.6", use_errno=True).prctl
except OSError:  # not Linux: no parent-death signal, the process groups still get signalled
    _prctl = None


def _die_with_parent() -> None:
    # Runs in the child between fork and exec; PR_SET_PDEATHSIG = 1.
    if _prctl is not None:
        _prctl(1, signal.SIGTERM)


def _lower_priority(nice: int) -> None:
    """Runs in the child after it became a session leader: ``nice`` for its threads, and for its
    autogroup. With the kernel's autogroups (``kernel.sched_autogroup_enabled``, on in Debian's
    kernels) the scheduler first shares the CPU equally between groups, one per session, and a
    thread's niceness only counts inside its group: every launched process leads a session of its
    own, so without the group's niceness a niced process would still get as much CPU as any other."""
    os.nice(nice)
    with contextlib.suppress(OSError), open("/proc/self/autogroup", "w") as group:  # none: no autogroups
        group.write(str(nice))


def _preexec(namespace: str | None, nice: int) -> Callable[[], None]:
    """A preexec_fn: die with the launcher, run inside the host's network namespace if given, and
    at the given niceness (set before exec, so every thread the process starts inherits it)."""

    def preexec() -> None:
        _die_with_parent()
        if namespace:
            enter_namespace(namespace)
        if nice:
            _lower_priority(nice)

    return preexec


def default_log_dir(environ: Mapping[str, str]) -> Path:
    """The run folder's ``logs``: ``$TLT_RUN_DIR/logs``, the run folder being ``/tmp/tlt-run`` when
    ``TLT_RUN_DIR`` is unset, as in every launch set of ``config/launch``."""
    return Path(environ.get("TLT_RUN_DIR") or "/tmp/tlt-run") / "logs"


def describe_exit(returncode: int) -> str:
    """'exit code 3' or 'signal SIGKILL'."""
    if returncode < 0:
        try:
            return f"signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"signal {-returncode}"
    return f"exit code {returncode}"


@dataclass
class _Proc:
    spec: ProcessSpec
    popen: subprocess.Popen[bytes] | None = None
    started_at: float = 0.0
    restarts: int = 0
    restart_at: float | None = None
    waiting_since: float | None = None
    returncode: int | None = None
    reader: threading.Thread | None = None
    log: TextIO | None = None  # <log folder>/<name>.log, open from its first start to the launcher's end
    last_lines: collections.deque[str] = field(default_factory=lambda: collections.deque(maxlen=_LAST_LINES))

    @property
    def running(self) -> bool:
        return self.popen is not None and self.returncode is None


class Supervisor:
    """Runs one launch set until it ends, is stopped, or a required process dies."""

    def __init__(
        self,
        launch_set: LaunchSet,
        out: TextIO | None = None,
        run_name: str | None = None,
        log_dir: str | Path | None = None,
    ) -> None:
        """``log_dir``: the folder of the per-process log files (created when needed); None: none."""
        self.launch_set = launch_set
        self.out = out or sys.stdout
        self.run_name = run_name or default_run_name(os.environ)
        self.log_dir = Path(log_dir) if log_dir is not None else None
        self.network: HostNetwork | None = None
        self._profile: str | None = None
        self._procs = [_Proc(spec) for spec in launch_set.processes]
        self._out_lock = threading.Lock()
        self._shutdown = threading.Event()
        self._hurry = threading.Event()
        self._signals = 0  # SIGINT/SIGTERM received (see _on_signal)
        self._exit_code = 0
        self._refusals: list[tuple[str, str]] = []  # (process, its reason) that stopped the set

    # --- public -----------------------------------------------------------------------------------
    def run(self) -> int:
        """Run until done; return the exit code (non-zero when a required process died)."""
        installed = self._install_signal_handlers()
        try:
            self._say(
                f"launch set '{self.launch_set.name}' ({self.launch_set.source}): "
                f"{len(self._procs)} process(es)"
            )
            self._open_log_dir()
            if self.launch_set.hosts and not self._create_hosts():
                return 1
            for proc in self._procs:
                if proc.spec.wait_for_path:
                    proc.waiting_since = time.monotonic()
                    self._say(f"{proc.spec.name} waits for {proc.spec.wait_for_path}")
                else:
                    self._start(proc)
            while not self._shutdown.is_set() and not self._signals:
                self._watch()
                if self._refusals:
                    break
                if not any(
                    p.running or p.restart_at is not None or p.waiting_since is not None for p in self._procs
                ):
                    failed = [p for p in self._procs if p.returncode not in (0, None)]
                    self._say("every process has ended")
                    return 1 if failed else self._exit_code
                self._shutdown.wait(_POLL_S)
            if self._signals:
                self._stop_all()
                self._exit_code = self._exit_code or self._decided_on_stop()
            if self._refusals:
                self._stop_all()
                for name, reason in self._refusals:
                    self._say(f"the launch set stopped because {name} refused to run: {reason}")
            return self._exit_code
        finally:
            self._stop_all()
            self._remove_hosts()
            self._close_logs()
            if installed:
                for sig, handler in installed.items():
                    signal.signal(sig, handler)

    def _decided_on_stop(self) -> int:
        """The exit code of a process that ends the set (``on_exit: shutdown``: a mission job, a
        bring-up check) and ended badly while a signal stopped the set, else 0: a build stopped
        halfway is not a success, and the launcher's status says what that process said."""
        for proc in self._procs:
            rc = proc.returncode
            if proc.spec.on_exit == "shutdown" and rc not in (None, 0):
                assert rc is not None
                return rc if rc >= 0 else 128 - rc
        return 0

    def request_shutdown(self) -> None:
        """Stop every process (callable from any thread; a signal handler uses _on_signal)."""
        if self._shutdown.is_set():
            self._hurry.set()
        self._shutdown.set()

    def pids(self) -> dict[str, int]:
        """PIDs of the processes now running, by name."""
        return {p.spec.name: p.popen.pid for p in self._procs if p.running and p.popen}

    # --- hosts ---------------------------------------------------------------------------------------
    def _create_hosts(self) -> bool:
        """Create the set's emulated hosts and render its DDS profile; False (said why) on failure."""
        network = HostNetwork(self.run_name, self.launch_set.hosts, multicast=self.launch_set.host_multicast)
        try:
            network.create()
            assert self.launch_set.dds_profile is not None
            self._profile = str(
                render_profile(
                    self.launch_set.dds_profile,
                    [h.ip for h in network.hosts],
                    network.lock_dir / f"{self.run_name}-fastdds.xml",
                )
            )
        except (HostsError, OSError) as exc:
            network.teardown()
            self._say(f"cannot create the hosts: {exc}")
            self._exit_code = 1
            return False
        self.network = network
        if network.removed_stale:
            self._say(f"removed namespaces a previous run left: {', '.join(network.removed_stale)}")
        for host in network.hosts:
            extra = f" (+ {', '.join(host.extra_addresses)})" if host.extra_addresses else ""
            self._say(f"host {host.name}: {host.address}{extra} in netns {network.namespace(host.name)}")
        self._say(f"DDS profile for the hosts: {self._profile}")
        return True

    def _remove_hosts(self) -> None:
        if self.network is None:
            return
        try:
            self.network.teardown()
            self._say(f"removed the hosts of run {self.run_name}")
        except HostsError as exc:
            self._say(f"could not remove every host: {exc}")
        finally:
            self.network = None
        if self._profile:
            with contextlib.suppress(OSError):
                os.unlink(self._profile)

    # --- log files -----------------------------------------------------------------------------------
    def _open_log_dir(self) -> None:
        if self.log_dir is None:
            return
        try:
            self.log_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            self._say(f"no log files: cannot create {self.log_dir}: {exc}")
            self.log_dir = None
            return
        self._say(f"each process's output also goes to {self.log_dir}/<name>.log")

    def _open_log(self, proc: _Proc) -> None:
        """Open the process's log file at its first start (a restart appends to it)."""
        if self.log_dir is None or proc.log is not None:
            return
        path = self.log_dir / f"{proc.spec.name}.log"
        try:
            proc.log = open(path, "w", encoding="utf-8", buffering=1)  # noqa: SIM115 (open until the end)
        except OSError as exc:
            self._say(f"no log file for {proc.spec.name}: {exc}")

    def _close_logs(self) -> None:
        with self._out_lock:
            for proc in self._procs:
                if proc.log is not None:
                    with contextlib.suppress(OSError):
                        proc.log.close()
                    proc.log = None

    # --- starting and watching ----------------------------------------------------------------------
    def _start(self, proc: _Proc) -> None:
        spec = proc.spec
        env = {**os.environ, **spec.env}
        namespace = None
        if spec.host:
            assert self._profile is not None
            env = host_environment(self._profile, env)
            namespace = namespace_name(self.run_name, spec.host)
        elif proc.restarts:
            # Fast DDS 2.14 can leave the shared-memory port of a process that died (SIGKILL) so
            # that its restarted successor matches every topic and receives nothing on some
            # (eProsima/Fast-DDS#5053, #2811): a restarted ARS may then never get /clock and never
            # tick. Over UDP it does.
            env.setdefault("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4")
        proc.restart_at = None
        proc.returncode = None
        proc.last_lines.clear()
        self._open_log(proc)
        try:
            proc.popen = subprocess.Popen(
                spec.argv,
                cwd=spec.cwd,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                preexec_fn=_preexec(namespace, spec.nice),
            )
        except (OSError, subprocess.SubprocessError) as exc:
            proc.popen = None
            proc.returncode = 127
            reason = getattr(exc, "strerror", None) or exc
            where = f" in host {spec.host}" if spec.host else ""
            self._say(f"{spec.name} cannot start{where}: {' '.join(spec.argv)}: {reason}", proc)
            self._after_exit(proc, early=True)
            return
        proc.started_at = time.monotonic()
        where = f" on host {spec.host}" if spec.host else ""
        # Said before its output is relayed, so that no line of the process comes before it.
        self._say(f"started {spec.name} (pid {proc.popen.pid}){where}", proc)
        proc.reader = threading.Thread(
            target=self._pump, args=(proc, proc.popen), daemon=True, name=f"launch-{spec.name}"
        )
        proc.reader.start()

    def _pump(self, proc: _Proc, popen: subprocess.Popen[bytes]) -> None:
        assert popen.stdout is not None
        prefix = f"[{proc.spec.name}] "
        for raw in popen.stdout:
            line = raw.decode("utf-8", errors="replace").rstrip("\n")
            proc.last_lines.append(line)
            self._write(prefix + line, proc, line)
        popen.stdout.close()

    def _watch(self) -> None:
        now = time.monotonic()
        for proc in self._procs:
            if proc.waiting_since is not None:
                self._check_wait(proc, now)
            elif proc.restart_at is not None and now >= proc.restart_at:
                proc.restarts += 1
                self._say(f"restarting {proc.spec.name} ({proc.restarts} of {proc.spec.max_restarts})", proc)
                self._start(proc)
            elif proc.running:
                assert proc.popen is not None
                rc = proc.popen.poll()
                if rc is not None:
                    proc.returncode = rc
                    if proc.reader:
                        proc.reader.join(timeout=1.0)
                    self._after_exit(proc, early=now - proc.started_at < proc.spec.startup_s)

    def _check_wait(self, proc: _Proc, now: float) -> None:
        spec = proc.spec
        assert proc.waiting_since is not None and spec.wait_for_path
        if os.path.exists(spec.wait_for_path):
            proc.waiting_since = None
            self._start(proc)
        elif now - proc.waiting_since > spec.wait_timeout_s:
            proc.waiting_since = None
            proc.returncode = 1
            self._say(
                f"{spec.name} cannot start: {spec.wait_for_path} did not appear "
                f"within {spec.wait_timeout_s:g} s"
            )
            if spec.required or spec.on_exit == "shutdown":
                self._exit_code = 1
                self._shutdown.set()

    def _after_exit(self, proc: _Proc, *, early: bool) -> None:
        spec, rc = proc.spec, proc.returncode
        assert rc is not None
        failed = rc != 0
        if failed or early:
            when = " during start-up" if early else ""
            self._say(f"{spec.name} exited with {describe_exit(rc)}{when}", proc)
            if proc.last_lines:
                self._say(f"last output of {spec.name}:")
                for line in proc.last_lines:
                    self._write(f"    | {line}")
        else:
            self._say(f"{spec.name} exited with {describe_exit(rc)}", proc)
        if spec.on_exit == "shutdown":
            self._say(f"{spec.name} ended the launch set ({describe_exit(rc)})")
            self._exit_code = rc if rc >= 0 else 128 - rc
            self._shutdown.set()
            return
        if rc == REFUSED and spec.on_refusal == "shutdown":
            # Started again it would refuse again (the same configuration, the same mission).
            reason = next((line.strip() for line in reversed(proc.last_lines) if line.strip()), "no output")
            self._say(f"{spec.name} refused to run: stopping the launch set")
            self._refusals.append((spec.name, reason))
            if not self._shutdown.is_set():
                self._exit_code = REFUSED
            self._shutdown.set()
            return
        wants_restart = spec.restart == "always" or (spec.restart == "on-failure" and failed)
        if wants_restart and proc.restarts < spec.max_restarts:
            proc.restart_at = time.monotonic() + spec.restart_delay_s
            return
        if wants_restart:
            self._say(f"{spec.name} has used all {spec.max_restarts} restart(s)")
        if spec.required:
            self._say(f"required process {spec.name} is down: stopping the launch set")
            self._exit_code = 1
            self._shutdown.set()

    # --- stopping -------------------------------------------------------------------------------------
    def _stop_all(self) -> None:
        for proc in self._procs:
            proc.restart_at = proc.waiting_since = None
        running = [p for p in self._procs if p.running]
        if running:
            self._say(f"stopping {', '.join(p.spec.name for p in running)}")
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            running = [p for p in self._procs if p.running]
            if not running:
                break
            if sig != signal.SIGINT:
                self._say(f"{sig.name} to {', '.join(p.spec.name for p in running)}")
            for proc in running:
                self._signal_group(proc, sig)
            self._wait_for(running, 2.0 if sig == signal.SIGKILL else self.launch_set.grace_period_s)
        # Anything a process left behind in its group goes too.
        for proc in self._procs:
            if proc.popen is not None:
                self._signal_group(proc, signal.SIGKILL)
                if proc.reader:
                    proc.reader.join(timeout=1.0)

    def _wait_for(self, procs: list[_Proc], timeout: float) -> None:
        deadline = time.monotonic() + timeout
        signals = self._signals  # one more while waiting hurries, as request_shutdown does
        while time.monotonic() < deadline and not self._hurry.is_set() and self._signals == signals:
            for proc in procs:
                if proc.running and proc.popen and proc.popen.poll() is not None:
                    proc.returncode = proc.popen.returncode
                    self._say(f"{proc.spec.name} stopped ({describe_exit(proc.returncode)})", proc)
            if not any(p.running for p in procs):
                return
            time.sleep(_POLL_S)
        self._hurry.clear()

    @staticmethod
    def _signal_group(proc: _Proc, sig: signal.Signals) -> None:
        assert proc.popen is not None
        try:
            os.killpg(proc.popen.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    # --- signals and output -----------------------------------------------------------------------------
    def _install_signal_handlers(self) -> dict[int, _Handler]:
        if threading.current_thread() is not threading.main_thread():
            return {}
        previous: dict[int, _Handler] = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, self._on_signal)
        return previous

    def _on_signal(self, *_: object) -> None:
        # Only counted: a handler runs in the main thread between two of its bytecodes, and the
        # main thread lives in Event.wait, whose lock Event.set would take again and never get (the
        # launcher would then sit through SIGINT and SIGTERM without a word until SIGKILL).
        self._signals += 1

    def _say(self, text: str, proc: _Proc | None = None) -> None:
        """A launcher line on the console, and in ``proc``'s log file when it is about one."""
        line = f"[launch] {text}"
        self._write(line, proc, line)

    def _write(self, line: str, proc: _Proc | None = None, logged: str | None = None) -> None:
        """``line`` to the console and ``logged`` (if given) to ``proc``'s log file."""
        with self._out_lock:
            try:
                self.out.write(line + "\n")
                self.out.flush()
            except (OSError, ValueError):
                pass  # our own stdout is gone (a closed pipe); the processes still get stopped
            if proc is not None and proc.log is not None and logged is not None:
                try:
                    proc.log.write(logged + "\n")
                except (OSError, ValueError) as exc:  # a full disk: the console still has it
                    proc.log = None
                    self.out.write(f"[launch] {proc.spec.name}'s log file stopped: {exc}\n")
