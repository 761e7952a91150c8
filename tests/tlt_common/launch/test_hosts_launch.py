"""The launcher with emulated hosts: real rclpy processes in different network namespaces exchange a
ROS 2 action over UDP, a cut link makes the server vanish from the client's graph and a healed one
brings it back with nothing lost, and the hosts go when the set ends, even after a SIGKILLed
launcher (the next start removes what it left) or a start without privileges (a clear reason).

Where this machine cannot create network namespaces the tests skip with the reason it gave."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from tlt_common.launch import Supervisor, load_launch_set
from tlt_common.launch.hosts import NETNS_DIR, run_namespaces, unavailable_reason

PAIR = Path(__file__).with_name("hosts_pair.py")
TLT = Path(sys.executable).with_name("tlt")
DOMAIN = os.environ.get("ROS_DOMAIN_ID", "0")


@pytest.fixture(scope="module", autouse=True)
def namespaces_available():
    reason = unavailable_reason(f"l{DOMAIN}probe")
    if reason:
        pytest.skip(f"network namespaces are not available here: {reason}")


class Lines:
    """A text sink for the supervisor's output that can be waited on, line by line."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._partial = ""

    def write(self, text: str) -> None:
        with self._changed:
            self._partial += text
            *done, self._partial = self._partial.split("\n")
            self.lines += done
            self._changed.notify_all()

    def flush(self) -> None:
        pass

    def wait_for(self, pattern: str, timeout: float) -> re.Match[str]:
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                for line in self.lines:
                    if match := regex.search(line):
                        return match
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no line matching {pattern!r} in:\n" + "\n".join(self.lines))
                self._changed.wait(left)


def pair_set(tmp_path: Path, hold_s: float) -> Path:
    path = tmp_path / "pair_on_hosts.yaml"
    path.write_text(
        textwrap.dedent(f"""
        name: pair_on_hosts
        grace_period_s: 3
        hosts:
          - {{name: crs, address: 10.77.0.11/24}}
          - {{name: ars_x, address: 10.77.0.12/24}}
          - {{name: ground, address: 10.77.0.14/24}}
        processes:
          - name: server
            executable: python
            args: ["{PAIR}", server]
            host: ars_x
          - name: client
            executable: python
            args: ["{PAIR}", client, "{hold_s}"]
            host: crs
            on_exit: shutdown
    """)
    )
    return path


def net_namespace(pid: int) -> int:
    return os.stat(f"/proc/{pid}/ns/net").st_ino


def gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][0]
    except (FileNotFoundError, IndexError):
        return True
    return state == "Z"


def test_an_action_crosses_hosts_and_a_cut_link_loses_nothing(tmp_path):
    run = f"l{DOMAIN}"
    out = Lines()
    supervisor = Supervisor(load_launch_set(pair_set(tmp_path, hold_s=4.0)), out=out, run_name=run)
    result: list[int] = []
    thread = threading.Thread(target=lambda: result.append(supervisor.run()), daemon=True)
    thread.start()
    try:
        server = int(out.wait_for(r"\[launch\] started server \(pid (\d+)\) on host ars_x", 30).group(1))
        client = int(out.wait_for(r"\[launch\] started client \(pid (\d+)\) on host crs", 30).group(1))
        # Each process really is inside its host's namespace, not the machine's.
        assert net_namespace(server) == os.stat(NETNS_DIR / f"tlt-{run}-ars_x").st_ino
        assert net_namespace(client) == os.stat(NETNS_DIR / f"tlt-{run}-crs").st_ino
        assert net_namespace(server) != net_namespace(os.getpid())

        # The round trip across hosts.
        out.wait_for(r"^\[client\] result m0 success=True reason=placed m0$", 60)
        # The server's host loses its cable while it holds goal m1.
        out.wait_for(r"^\[server\] server accepted m1$", 30)
        assert supervisor.network is not None
        supervisor.network.cut("ars_x")
        cut_at = time.monotonic()
        # The lease of the profile is 3 s; the Fast DDS default would be 20 s.
        out.wait_for(r"^\[client\] server lost$", 30)
        lost_after = time.monotonic() - cut_at
        assert lost_after < 15, f"the server left the graph only {lost_after:.1f} s after the cut"
        # The server went on and finished the goal on its side of the cut.
        out.wait_for(r"^\[server\] server finished m1$", 30)
        supervisor.network.heal("ars_x")
        # The result of the goal in flight at the cut is still delivered, and a new goal succeeds.
        out.wait_for(r"^\[client\] result m1 success=True reason=placed m1$", 30)
        out.wait_for(r"^\[client\] result m2 success=True reason=placed m2$", 30)
        thread.join(timeout=30)
        assert result == [0], "\n".join(out.lines)
    finally:
        supervisor.request_shutdown()
        thread.join(timeout=30)
    out.wait_for(rf"\[launch\] removed the hosts of run {run}", 1)
    assert run_namespaces(run) == []
    assert gone(server) and gone(client)


def _launch(path: Path, env: dict[str, str], setpriv: bool = False) -> subprocess.Popen[str]:
    argv = [str(TLT), "launch", str(path)]
    if setpriv:
        argv = ["setpriv", "--bounding-set=-all", "--inh-caps=-all", *argv]
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)


def _sleepers(tmp_path: Path) -> Path:
    path = tmp_path / "sleepers.yaml"
    path.write_text(
        textwrap.dedent("""
        grace_period_s: 1
        hosts:
          - {name: a, address: 10.77.0.11/24}
          - {name: b, address: 10.77.0.12/24}
        processes:
          - {name: one, executable: python, args: ["-c", "{SLEEP}"], host: a}
          - {name: two, executable: python, args: ["-c", "{SLEEP}"], host: b}
    """).replace("{SLEEP}", "import time; print('up', flush=True); time.sleep(60)")
    )
    return path


def _read_until(proc: subprocess.Popen[str], pattern: str, timeout: float) -> list[str]:
    """Lines of ``proc`` up to the first matching ``pattern`` (a timer kills it if none comes)."""
    assert proc.stdout is not None
    timer = threading.Timer(timeout, proc.kill)
    timer.start()
    lines = []
    try:
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if re.search(pattern, line):
                return lines
    finally:
        timer.cancel()
    raise AssertionError(f"no line matching {pattern!r} in:\n" + "\n".join(lines))


def test_the_next_start_removes_what_a_sigkilled_launcher_left(tmp_path):
    run = f"k{DOMAIN}"
    env = {**os.environ, "TLT_HOSTS_RUN": run}
    first = _launch(_sleepers(tmp_path), env)
    try:
        lines = _read_until(first, r"^\[two\] up$", 60)
        pids = [int(m.group(1)) for line in lines if (m := re.search(r"started \w+ \(pid (\d+)\)", line))]
        first.kill()
        first.wait()
    finally:
        if first.poll() is None:
            first.kill()
    # The processes die with the launcher (parent-death signal); its namespaces cannot.
    deadline = time.monotonic() + 10
    while not all(gone(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert len(pids) == 2 and all(gone(pid) for pid in pids)
    assert run_namespaces(run) == [f"tlt-{run}-a", f"tlt-{run}-b", f"tlt-{run}-switch"]

    second = _launch(_sleepers(tmp_path), env)
    try:
        lines = _read_until(second, r"^\[two\] up$", 60)
        left = f"tlt-{run}-a, tlt-{run}-b, tlt-{run}-switch"
        assert f"[launch] removed namespaces a previous run left: {left}" in lines
        second.send_signal(signal.SIGINT)
        rest, _ = second.communicate(timeout=30)
    finally:
        if second.poll() is None:
            second.kill()
    assert second.returncode == 0
    assert f"[launch] removed the hosts of run {run}" in rest
    assert run_namespaces(run) == []


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="setpriv (util-linux) is not installed")
def test_without_privileges_the_set_does_not_start_and_says_why(tmp_path):
    run = f"k{DOMAIN}"
    proc = _launch(_sleepers(tmp_path), {**os.environ, "TLT_HOSTS_RUN": run}, setpriv=True)
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 1, output
    assert (
        f"[launch] cannot create the hosts: cannot create network namespaces: "
        f"`ip netns add tlt-{run}-switch` failed: "
    ) in output
    assert "Operation not permitted" in output
    assert "[launch] started" not in output
    assert run_namespaces(run) == []
