"""Start, watch, restart and stop the processes of a launch set.

Every process runs in its own process group, so a signal reaches it and anything it started; each
also asks the kernel to send it SIGTERM if the launcher dies, so even a SIGKILLed launcher leaves
no orphan. Output lines are prefixed with the process name. Shutdown (Ctrl-C, SIGTERM, or a
required process that died for good) sends SIGINT, then SIGTERM, then SIGKILL, each after the set's
grace period; a second Ctrl-C skips the waiting.
"""

from __future__ import annotations

import collections
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import TextIO

from tlt_common.launch.launch_set import LaunchSet, ProcessSpec

_POLL_S = 0.05
_LAST_LINES = 15

try:
    _prctl = ctypes.CDLL("libc.so.6", use_errno=True).prctl
except OSError:  # not Linux: no parent-death signal, the process groups still get signalled
    _prctl = None


def _die_with_parent() -> None:
    # Runs in the child between fork and exec; PR_SET_PDEATHSIG = 1.
    if _prctl is not None:
        _prctl(1, signal.SIGTERM)


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
    last_lines: collections.deque[str] = field(default_factory=lambda: collections.deque(maxlen=_LAST_LINES))

    @property
    def running(self) -> bool:
        return self.popen is not None and self.returncode is None


class Supervisor:
    """Runs one launch set until it ends, is stopped, or a required process dies."""

    def __init__(self, launch_set: LaunchSet, out: TextIO | None = None) -> None:
        self.launch_set = launch_set
        self.out = out or sys.stdout
        self._procs = [_Proc(spec) for spec in launch_set.processes]
        self._out_lock = threading.Lock()
        self._shutdown = threading.Event()
        self._hurry = threading.Event()
        self._exit_code = 0

    # --- public -----------------------------------------------------------------------------------
    def run(self) -> int:
        """Run until done; return the exit code (non-zero when a required process died)."""
        installed = self._install_signal_handlers()
        try:
            self._say(f"launch set '{self.launch_set.name}' ({self.launch_set.source}): "
                      f"{len(self._procs)} process(es)")
            for proc in self._procs:
                if proc.spec.wait_for_path:
                    proc.waiting_since = time.monotonic()
                    self._say(f"{proc.spec.name} waits for {proc.spec.wait_for_path}")
                else:
                    self._start(proc)
            while not self._shutdown.is_set():
                self._watch()
                if not any(p.running or p.restart_at is not None or p.waiting_since is not None
                           for p in self._procs):
                    failed = [p for p in self._procs if p.returncode not in (0, None)]
                    self._say("every process has ended")
                    return 1 if failed else self._exit_code
                self._shutdown.wait(_POLL_S)
            return self._exit_code
        finally:
            self._stop_all()
            if installed:
                for sig, handler in installed.items():
                    signal.signal(sig, handler)

    def request_shutdown(self) -> None:
        """Stop every process (callable from any thread or a signal handler)."""
        if self._shutdown.is_set():
            self._hurry.set()
        self._shutdown.set()

    def pids(self) -> dict[str, int]:
        """PIDs of the processes now running, by name."""
        return {p.spec.name: p.popen.pid for p in self._procs if p.running and p.popen}

    # --- starting and watching ----------------------------------------------------------------------
    def _start(self, proc: _Proc) -> None:
        spec = proc.spec
        env = {**os.environ, **spec.env}
        proc.restart_at = None
        proc.returncode = None
        proc.last_lines.clear()
        try:
            proc.popen = subprocess.Popen(
                spec.argv,
                cwd=spec.cwd,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                preexec_fn=_die_with_parent,
            )
        except OSError as exc:
            proc.popen = None
            proc.returncode = 127
            self._say(f"{spec.name} cannot start: {' '.join(spec.argv)}: {exc.strerror or exc}")
            self._after_exit(proc, early=True)
            return
        proc.started_at = time.monotonic()
        proc.reader = threading.Thread(target=self._pump, args=(proc, proc.popen), daemon=True,
                                       name=f"launch-{spec.name}")
        proc.reader.start()
        self._say(f"started {spec.name} (pid {proc.popen.pid})")

    def _pump(self, proc: _Proc, popen: subprocess.Popen[bytes]) -> None:
        assert popen.stdout is not None
        prefix = f"[{proc.spec.name}] "
        for raw in popen.stdout:
            line = raw.decode("utf-8", errors="replace").rstrip("\n")
            proc.last_lines.append(line)
            self._write(prefix + line)
        popen.stdout.close()

    def _watch(self) -> None:
        now = time.monotonic()
        for proc in self._procs:
            if proc.waiting_since is not None:
                self._check_wait(proc, now)
            elif proc.restart_at is not None and now >= proc.restart_at:
                proc.restarts += 1
                self._say(f"restarting {proc.spec.name} ({proc.restarts} of {proc.spec.max_restarts})")
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
            self._say(f"{spec.name} cannot start: {spec.wait_for_path} did not appear "
                      f"within {spec.wait_timeout_s:g} s")
            if spec.required or spec.on_exit == "shutdown":
                self._exit_code = 1
                self._shutdown.set()

    def _after_exit(self, proc: _Proc, *, early: bool) -> None:
        spec, rc = proc.spec, proc.returncode
        assert rc is not None
        failed = rc != 0
        if failed or early:
            when = " during start-up" if early else ""
            self._say(f"{spec.name} exited with {describe_exit(rc)}{when}")
            if proc.last_lines:
                self._say(f"last output of {spec.name}:")
                for line in proc.last_lines:
                    self._write(f"    | {line}")
        else:
            self._say(f"{spec.name} exited with {describe_exit(rc)}")
        if spec.on_exit == "shutdown":
            self._say(f"{spec.name} ended the launch set ({describe_exit(rc)})")
            self._exit_code = rc if rc >= 0 else 128 - rc
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
        while time.monotonic() < deadline and not self._hurry.is_set():
            for proc in procs:
                if proc.running and proc.popen and proc.popen.poll() is not None:
                    proc.returncode = proc.popen.returncode
                    self._say(f"{proc.spec.name} stopped ({describe_exit(proc.returncode)})")
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
    def _install_signal_handlers(self) -> dict[int, object]:
        if threading.current_thread() is not threading.main_thread():
            return {}
        previous = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: self.request_shutdown())
        return previous

    def _say(self, text: str) -> None:
        self._write(f"[launch] {text}")

    def _write(self, line: str) -> None:
        with self._out_lock:
            try:
                self.out.write(line + "\n")
                self.out.flush()
            except (OSError, ValueError):
                pass  # our own stdout is gone (a closed pipe); the processes still get stopped
