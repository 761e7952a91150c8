"""The launcher against real processes: real rclpy nodes exchanging an action over DDS, restarts,
required processes, start-up failures and a clean shutdown that leaves no child behind."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

PAIR = Path(__file__).with_name("action_pair.py")
TLT = Path(sys.executable).with_name("tlt")


class Launcher:
    """``tlt launch`` as a subprocess, with its output collected line by line and the processes'
    log files in ``log_dir``."""

    def __init__(self, launch_file: Path, log_dir: Path) -> None:
        self.proc = subprocess.Popen(
            [str(TLT), "launch", "--log-dir", str(log_dir), str(launch_file)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        self._changed = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()

    def wait_for(self, pattern: str, timeout: float = 30.0, after: int = 0) -> re.Match[str]:
        """The first line (from index ``after``) matching ``pattern``."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                for line in self.lines[after:]:
                    if match := regex.search(line):
                        return match
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no line matching {pattern!r} in:\n" + "\n".join(self.lines))
                self._changed.wait(left)

    def pid_of(self, name: str, after: int = 0) -> int:
        return int(self.wait_for(rf"\[launch\] started {name} \(pid (\d+)\)", after=after).group(1))

    def finish(self, timeout: float = 60.0) -> int:
        return self.proc.wait(timeout=timeout)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie is dead for our purpose (waiting for its parent to reap it).
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().split(") ")[1][0] != "Z"
    except (FileNotFoundError, IndexError):
        return False


def write_set(tmp_path: Path, body: str, name: str = "set.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return path


@pytest.fixture
def launcher(tmp_path):
    started: list[Launcher] = []

    def start(path: Path) -> Launcher:
        started.append(Launcher(path, tmp_path / "logs"))
        return started[-1]

    yield start
    for item in started:
        item.stop()


def pair_set(tmp_path: Path, client_restart: str = "on-failure", server_required: bool = True) -> Path:
    return write_set(
        tmp_path,
        f"""
        name: pair
        grace_period_s: 3
        processes:
          - name: server
            executable: python
            args: ["{PAIR}", server]
            required: {str(server_required).lower()}
          - name: client
            executable: python
            args: ["{PAIR}", client]
            restart: {client_restart}
            restart_delay_s: 0.2
    """,
    )


def test_two_nodes_exchange_an_action_and_ctrl_c_stops_everything(tmp_path, launcher):
    run = launcher(pair_set(tmp_path))
    server, client = run.pid_of("server"), run.pid_of("client")
    run.wait_for(r"^\[client\] result success=True reason=placed m\d+$")
    run.wait_for(r"^\[server\] server up$")
    run.proc.send_signal(signal.SIGINT)
    assert run.finish() == 0
    assert not alive(server) and not alive(client)
    assert any("stopped" in line for line in run.lines)
    server_log = (tmp_path / "logs" / "server.log").read_text().splitlines()
    assert server_log[0] == f"[launch] started server (pid {server})"
    assert "server up" in server_log and server_log[-1].startswith("[launch] server stopped (")


def test_a_killed_process_with_a_restart_policy_comes_back(tmp_path, launcher):
    run = launcher(pair_set(tmp_path))
    first = run.pid_of("client")
    run.wait_for(r"^\[client\] result success=True")
    os.kill(first, signal.SIGKILL)
    run.wait_for(r"\[launch\] client exited with signal SIGKILL")
    mark = len(run.lines)
    run.wait_for(r"\[launch\] restarting client \(1 of 5\)", after=0)
    second = run.pid_of("client", after=mark)
    assert second != first
    # The new client talks to the same server again, over UDP (a restarted process's DDS shuns
    # the shared memory its predecessor may have left unusable).
    run.wait_for(r"^\[client\] result success=True", after=mark)
    environ = Path(f"/proc/{second}/environ").read_bytes().split(b"\0")
    assert b"FASTDDS_BUILTIN_TRANSPORTS=UDPv4" in environ
    run.proc.send_signal(signal.SIGTERM)
    assert run.finish() == 0
    assert not alive(second)


def test_a_required_process_that_dies_stops_the_set_with_an_error(tmp_path, launcher):
    run = launcher(pair_set(tmp_path))
    server, client = run.pid_of("server"), run.pid_of("client")
    run.wait_for(r"^\[client\] result success=True")
    os.kill(server, signal.SIGKILL)
    assert run.finish() != 0
    run.wait_for(r"required process server is down: stopping the launch set")
    assert not alive(client)


def test_a_process_that_cannot_start_is_named_with_its_last_output(tmp_path, launcher):
    path = write_set(
        tmp_path,
        """
        processes:
          - name: broken
            executable: python
            args: ["-c", "print('loading config'); import tlt_no_such_module"]
            required: true
          - name: bystander
            executable: python
            args: ["-c", "import time; time.sleep(60)"]
    """,
    )
    run = launcher(path)
    bystander = run.pid_of("bystander")
    assert run.finish() != 0
    run.wait_for(r"\[launch\] broken exited with exit code 1 during start-up")
    text = "\n".join(run.lines)
    assert "last output of broken:" in text
    assert "    | loading config" in text
    assert "ModuleNotFoundError: No module named 'tlt_no_such_module'" in text
    assert not alive(bystander)


def test_a_process_that_refuses_to_run_stops_the_set_at_once_with_its_reason(tmp_path, launcher):
    """An ARS refuses a mission its arm cannot reach (exit 2) and would refuse it again when
    restarted: the set stops at once with status 2, the job that ends it (the ground's mission
    job) says its last word, and the refusal's reason is the set's own last word."""
    job = tmp_path / "job.py"
    job.write_text(
        textwrap.dedent("""
        import signal, sys, time
        def stop(*_):
            print("summary: nothing built", flush=True)
            sys.exit(130)
        signal.signal(signal.SIGINT, stop)
        print("asking for Start", flush=True)
        open(sys.argv[1], "w").close()
        time.sleep(120)
    """)
    )
    asking = tmp_path / "asking"
    reason = "ars: mission 'narrow': 2 unreachable step(s): bay1/diagonal/face_y0: ars_x cannot place"
    refuse = tmp_path / "refuse.py"
    refuse.write_text(
        "import sys\nprint('loading the mission', flush=True)\n"
        f"print({reason!r}, file=sys.stderr, flush=True)\nsys.exit(2)\n"
    )
    path = write_set(
        tmp_path,
        f"""
        grace_period_s: 2
        processes:
          - name: ars_x
            executable: python
            args: ["{refuse}"]
            wait_for_path: {asking}
            restart: on-failure
            restart_delay_s: 0.1
            on_refusal: shutdown
          - name: bystander
            executable: python
            args: ["-c", "import time; time.sleep(60)"]
            restart: on-failure
          - name: job
            executable: python
            args: ["{job}", "{asking}"]
            on_exit: shutdown
    """,
    )
    began = time.monotonic()
    run = launcher(path)
    bystander = run.pid_of("bystander")
    run.wait_for(r"^\[job\] asking for Start$")
    assert run.finish(timeout=20) == 2
    assert time.monotonic() - began < 15
    run.wait_for(r"\[launch\] ars_x exited with exit code 2")
    assert f"    | {reason}" in run.lines  # its last output, as for any failure
    assert not [line for line in run.lines if "restarting ars_x" in line]
    run.wait_for(r"the launch set stopped because")
    assert run.lines[-1] == f"[launch] the launch set stopped because ars_x refused to run: {reason}"
    assert run.lines.index("[job] summary: nothing built") < len(run.lines) - 1
    assert not alive(bystander)


def test_by_default_a_refusal_is_a_failure_the_restart_policy_restarts(tmp_path, launcher):
    path = write_set(
        tmp_path,
        """
        processes:
          - name: driver
            executable: python
            args: ["-c", "import sys; print('no device yet', file=sys.stderr); sys.exit(2)"]
            restart: on-failure
            max_restarts: 1
            restart_delay_s: 0.1
    """,
    )
    run = launcher(path)
    assert run.finish(timeout=20) == 1  # every process has ended, one of them failed
    run.wait_for(r"\[launch\] restarting driver \(1 of 1\)")
    assert not [line for line in run.lines if "refused to run" in line]


def test_shutdown_escalates_to_sigterm_and_sigkill_and_leaves_no_grandchild(tmp_path, launcher):
    stubborn = tmp_path / "stubborn.py"
    stubborn.write_text(
        textwrap.dedent("""
        import signal, subprocess, sys, time
        ignored = [signal.SIGINT] + ([signal.SIGTERM] if sys.argv[1] == "both" else [])
        for sig in ignored:
            signal.signal(sig, signal.SIG_IGN)
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
        print(f"grandchild {child.pid}", flush=True)
        time.sleep(120)
    """)
    )
    path = write_set(
        tmp_path,
        f"""
        grace_period_s: 0.5
        processes:
          - name: ignores_int
            executable: python
            args: ["{stubborn}", "int"]
          - name: ignores_both
            executable: python
            args: ["{stubborn}", "both"]
    """,
    )
    run = launcher(path)
    pids = [run.pid_of("ignores_int"), run.pid_of("ignores_both")]
    for name in ("ignores_int", "ignores_both"):
        pids.append(int(run.wait_for(rf"^\[{name}\] grandchild (\d+)").group(1)))
    run.proc.send_signal(signal.SIGINT)
    assert run.finish() == 0
    run.wait_for(r"SIGTERM to .*ignores_int")
    run.wait_for(r"SIGKILL to ignores_both")
    assert [pid for pid in pids if alive(pid)] == []


def test_ctrl_c_during_a_job_that_ends_the_set_exits_with_the_jobs_status(tmp_path, launcher):
    """A mission job interrupted during a build exits 130 (not built): so does the launcher, and so
    scripts/main.sh; a plain set stopped by Ctrl-C still exits 0 (the tests above)."""
    job = tmp_path / "job.py"
    job.write_text(
        textwrap.dedent("""
        import signal, sys, time
        signal.signal(signal.SIGINT, lambda *_: sys.exit(130))
        print("building", flush=True)
        time.sleep(120)
    """)
    )
    path = write_set(
        tmp_path,
        f"""
        processes:
          - name: job
            executable: python
            args: ["{job}"]
            on_exit: shutdown
    """,
    )
    run = launcher(path)
    run.wait_for(r"^\[job\] building$")
    run.proc.send_signal(signal.SIGINT)
    assert run.finish() == 130


def test_children_die_with_a_killed_launcher(tmp_path, launcher):
    run = launcher(pair_set(tmp_path))
    server, client = run.pid_of("server"), run.pid_of("client")
    run.proc.kill()
    run.proc.wait()
    deadline = time.monotonic() + 10
    while (alive(server) or alive(client)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not alive(server) and not alive(client)


def test_a_bad_launch_set_starts_nothing(tmp_path):
    path = write_set(
        tmp_path,
        """
        processes:
          - name: a
            executable: python
            restart: sometimes
    """,
    )
    result = subprocess.run([str(TLT), "launch", str(path)], capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert (
        f"{path}: processes[0].restart: expected one of 'never', 'on-failure', 'always', got 'sometimes'"
        in result.stderr
    )
    assert "[launch] started" not in result.stdout


@pytest.mark.parametrize("code", [0, 3])
def test_a_job_with_on_exit_shutdown_ends_the_set_with_its_exit_code(tmp_path, launcher, code):
    path = write_set(
        tmp_path,
        f"""
        processes:
          - name: service
            executable: python
            args: ["-c", "import time; time.sleep(60)"]
          - name: job
            executable: python
            args: ["-c", "import time, sys; time.sleep(0.5); print('job done'); sys.exit({code})"]
            on_exit: shutdown
    """,
    )
    run = launcher(path)
    service = run.pid_of("service")
    assert run.finish() == code
    run.wait_for(rf"\[launch\] job ended the launch set \(exit code {code}\)")
    assert not alive(service)


def test_a_process_waits_for_its_device_path(tmp_path, launcher):
    link = tmp_path / "device"
    path = write_set(
        tmp_path,
        f"""
        processes:
          - name: driver
            executable: python
            args: ["-c", "print('driver up', flush=True); import time; time.sleep(60)"]
            wait_for_path: {link}
          - name: emulator
            executable: python
            args: ["-c", "import time, pathlib; time.sleep(1); pathlib.Path('{link}').touch(); time.sleep(9)"]
    """,
    )
    run = launcher(path)
    run.wait_for(rf"\[launch\] driver waits for {link}")
    run.pid_of("emulator")
    run.wait_for(r"^\[driver\] driver up$")
    assert link.exists()
    run.proc.send_signal(signal.SIGINT)
    assert run.finish() == 0


def test_a_process_runs_every_thread_and_its_autogroup_at_its_niceness(tmp_path, launcher):
    # A thread's niceness is in field 19 of its /proc stat line: the process's own and one it starts.
    report = (
        "import os, threading, pathlib; "
        "nice = lambda tid: int(pathlib.Path(f'/proc/self/task/{tid}/stat').read_text()"
        ".rsplit(')', 1)[1].split()[16]); "
        "t = threading.Thread(target=lambda: print('thread', nice(threading.get_native_id()), "
        "flush=True)); t.start(); t.join(); "
        "print('main', nice(threading.get_native_id()), flush=True); "
        "group = pathlib.Path('/proc/self/autogroup'); "
        "print('group', group.read_text().split()[-1] if group.exists() else 'none', flush=True)"
    )
    path = write_set(
        tmp_path,
        f"""
        processes:
          - {{name: yielding, executable: python, args: ["-c", "{report}"], nice: 7}}
          - {{name: plain, executable: python, args: ["-c", "{report}"]}}
    """,
    )
    own = os.nice(0)
    run = launcher(path)
    assert run.finish() == 0
    for name, expected in (("yielding", min(own + 7, 19)), ("plain", own)):
        run.wait_for(rf"^\[{name}\] thread {expected}$")
        run.wait_for(rf"^\[{name}\] main {expected}$")
    if Path("/proc/self/autogroup").exists():
        # Each process leads a session, so an autogroup, of its own: the group's niceness is
        # what the scheduler weighs against the other processes.
        run.wait_for(r"^\[yielding\] group 7$")
        run.wait_for(r"^\[plain\] group 0$")


def test_a_device_path_that_never_appears_fails_a_required_process(tmp_path, launcher):
    path = write_set(
        tmp_path,
        f"""
        processes:
          - name: driver
            executable: python
            args: ["-c", "import time; time.sleep(60)"]
            wait_for_path: {tmp_path / "never"}
            wait_timeout_s: 0.5
            required: true
    """,
    )
    run = launcher(path)
    assert run.finish() == 1
    run.wait_for(r"driver cannot start: .*never did not appear within 0.5 s")


def test_the_signal_handler_takes_no_lock_the_main_thread_may_hold(tmp_path):
    """A handler runs in the main thread between two of its bytecodes, and the launcher's main
    thread lives in Event.wait: a handler that set the event would take the event's lock again
    while wait held it, and hang the launcher through SIGINT and SIGTERM (seen once, at the end of
    a system test). The installed handler is called here with that lock held."""
    from tlt_common.launch.launch_set import load_launch_set
    from tlt_common.launch.supervisor import Supervisor

    path = write_set(
        tmp_path,
        """
        processes:
          - name: a
            executable: python
    """,
    )
    supervisor = Supervisor(load_launch_set(path), out=sys.stdout)
    previous = supervisor._install_signal_handlers()
    try:
        handler = signal.getsignal(signal.SIGINT)
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
    returned = threading.Event()

    def signalled_inside_wait() -> None:
        with supervisor._shutdown._cond:  # what Event.wait holds around its checks
            handler(signal.SIGINT, None)
        returned.set()

    threading.Thread(target=signalled_inside_wait, daemon=True).start()
    assert returned.wait(5.0), "the handler blocked on the lock its own thread held"
    assert supervisor._signals == 1
