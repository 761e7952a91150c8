"""The harness of the system tests: the whole system on the twin (config/launch/system_twin.yaml)
started by the project's launcher, and the ground station's end of the CCSDS link in the test.

``SystemRun`` starts ``tlt launch --isolated config/launch/system_twin.yaml`` as a subprocess in a
process group of its own, with a private run directory (``TLT_RUN_DIR``), the twin's UR
controllers on private loopback addresses, free UDP ports for the ground link and, optionally, a
twin scenario. A scenario whose members start ``built`` in the twin gets a CRS tower model that
says so (``<run>/tower_model.json``, as the CRS would have persisted it: the members placed and
riveted, their parts and rivets taken), so the run begins late in the bay. With ``hosts`` the
launch set is config/launch/system_hosts_twin.yaml instead: every computer of the EDU an emulated
host (a network namespace, docs/deployment.md), and the test's ground station on the ground host.
The arms move at their full speed limits (``TLT_ARM_VELOCITY_SCALE`` 1, as the ARS tests
run them): the build's steps are the same as at the ARS files' 0.5, in less sim time (a test
that times a twin fault against a step passes ``env={"TLT_ARM_VELOCITY_SCALE": ""}`` for the
files' speed). The
launcher's output goes to ``<run>/launch.log``. ``start()`` waits until the
CRS's ``hk_mission`` telemetry arrives over the ground link, and ``start_build()`` until an
authenticated Start is accepted (the CRS refuses Start with "not ready: ..." until its
drivers report; it is sent again until it is not).

``stop()`` always stops the launcher: SIGINT (the launcher's own orderly stop), then SIGTERM and
SIGKILL of its process group, each after a bound. Used as a context manager, a failure inside the
``with`` block gets the tail of the launch output appended to its message.

Nothing here waits without a bound: every wait takes a timeout and fails with what it saw last.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from action_msgs.msg import GoalStatus

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import Packet
from tlt_common.ccsds.definitions import Definitions, load_definitions
from tlt_common.ccsds.reasons import AckStage
from tlt_common.free_port import free_udp_port
from tlt_common.launch.hosts import enter_namespace, namespace_name
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import TowerModel
from tlt_gsw.link import Ack, GswLink, SentCommand

ROOT = Path(__file__).resolve().parents[2]
TLT = Path(sys.executable).with_name("tlt")
LAUNCH_SET = ROOT / "config/launch/system_twin.yaml"
HOSTS_SET = ROOT / "config/launch/system_hosts_twin.yaml"

# Loopback addresses of the twin's UR controllers: away from those of every other test
# (127.0.0.x emulators, 127.0.77-79.x twin tests) and of a developer's twin (127.0.0.2/.3).
UR_X_HOST = "127.0.83.2"
UR_Y_HOST = "127.0.83.3"


def _launcher_dies_with_test() -> None:
    # Runs in the launcher between fork and exec: a session of its own (its group is signalled as
    # a whole), and SIGTERM (its orderly stop) if the test process dies without stopping it.
    os.setsid()
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def _in_namespace(namespace: str, make: Callable[[], Any]) -> Any:
    """``make()`` run on a thread of its own moved into network namespace ``namespace``: a socket
    it opens stays in that namespace, whichever thread uses it later."""
    out: list[Any] = []

    def run() -> None:
        try:
            enter_namespace(namespace)
            out.append(make())
        except BaseException as exc:  # handed to the caller
            out.append(exc)

    thread = threading.Thread(target=run, name=f"in {namespace}")
    thread.start()
    thread.join()
    if isinstance(out[0], BaseException):
        raise out[0]
    return out[0]


def late_bay_scenario(mission: Any, last: str) -> dict[str, Any]:
    """A twin scenario with every member of bay 1 but ``last`` built (the run begins with it)."""
    built = [m.id for m in mission.bay_members(1) if m.id != last]
    return {"name": "late_bay", "description": f"bay 1 built but {last}", "built": built, "faults": {}}


class SystemRun:
    """One run of the whole system on the twin, and a ground station in the test process.

    ``packets`` holds every telemetry packet received, in order (acks and events included).
    """

    def __init__(
        self,
        run_dir: Path,
        *,
        scenario: Mapping[str, Any] | None = None,
        mission: str | None = None,
        rtf: float | None = None,
        env: Mapping[str, str] | None = None,
        hosts: bool = False,
    ) -> None:
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.run_dir / "launch.log"
        self.mission = load_mission(ROOT / "missions" / f"{mission or 'one_bay'}.yaml")
        scenario_file = ""
        if scenario is not None:  # a twin scenario (config/twin/scenarios/ has the format)
            scenario_file = str(self.run_dir / "twin_scenario.yaml")
            Path(scenario_file).write_text(yaml.safe_dump(dict(scenario)))
            if scenario.get("built"):
                self._tower_model(scenario["built"])
        self.crs_port = free_udp_port()
        self.gsw_port = free_udp_port()
        while self.gsw_port == self.crs_port:
            self.gsw_port = free_udp_port()
        self.launch_set = HOSTS_SET if hosts else LAUNCH_SET
        # The ground link's ends: loopback on one machine; on emulated hosts, the CRS host and the
        # ground host, whose namespace the test's ground station opens its socket in.
        self.hosts_run = f"t{os.getpid() % 100000}" if hosts else None
        self.crs_host = self.gsw_host = "127.0.0.1"
        if hosts:
            layout = yaml.safe_load(HOSTS_SET.read_text())
            self.crs_host = layout["env"]["TLT_GROUND_CRS_HOST"]
            self.gsw_host = layout["env"]["TLT_GROUND_GSW_HOST"]
        self.env = {
            **os.environ,
            "TLT_RUN_DIR": str(self.run_dir),
            "TLT_UR_X_HOST": UR_X_HOST,
            "TLT_UR_Y_HOST": UR_Y_HOST,
            "TLT_GROUND_CRS_PORT": str(self.crs_port),
            "TLT_GROUND_GSW_PORT": str(self.gsw_port),
            "TLT_TWIN_SCENARIO": scenario_file,
            "TLT_ARM_VELOCITY_SCALE": "1",
            **({"TLT_HOSTS_RUN": self.hosts_run} if hosts else {}),
            **({"TLT_MISSION": mission} if mission else {}),
            **({"TLT_TWIN_RTF": str(rtf)} if rtf is not None else {}),
            **(env or {}),
        }
        self.defs: Definitions = load_definitions()
        self.proc: subprocess.Popen[bytes] | None = None
        self.gsw: GswLink | None = None
        self.packets: list[Packet] = []
        self.exit_code: int | None = None

    def _tower_model(self, built: list[str]) -> None:
        model = TowerModel(self.mission, self.run_dir / "tower_model.json")
        for member in (m for m in self.mission.members if m.id in built):
            model.take_part(member.dispenser)
            for rivet in member.rivets:
                model.take_part(rivet.dispenser)
            model.place(member.id)
            if member.kind != "cross_frame":
                model.rivet(member.id)

    # -- life cycle -------------------------------------------------------------------------
    def __enter__(self) -> SystemRun:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.stop()
        if exc is None:
            return
        tail = f"--- launch output (tail) ---\n{self.launch_tail()}"
        if isinstance(exc, AssertionError):
            exc.args = (f"{exc.args[0] if exc.args else ''}\n{tail}",)
        elif isinstance(exc, Exception):
            exc.add_note(tail)

    def start(self, timeout: float = 150.0) -> SystemRun:
        """Start the launch set and wait until the CRS's ``hk_mission`` telemetry arrives."""
        log = self.log_path.open("wb")
        try:
            self.proc = subprocess.Popen(
                [str(TLT), "launch", "--isolated", str(self.launch_set)],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=self.env,
                cwd=ROOT,
                preexec_fn=_launcher_dies_with_test,
            )
        finally:
            log.close()
        key_file = self.run_dir / "ground.key"
        self._wait(
            lambda: key_file.exists() and key_file.stat().st_size > 0,
            60.0,
            "the run's ground key was not written",
        )

        def link() -> GswLink:
            return GswLink(
                self.defs,
                KeyRing.load(key_file),
                1,
                (self.crs_host, self.crs_port),
                bind=(self.gsw_host, self.gsw_port),
                on_packet=self._keep,
                # As config/ccsds/link_twin.yaml's default gsw.accept_from: the CRS's own socket.
                accept_from=[(self.crs_host, self.crs_port)],
            )

        if self.hosts_run is None:
            self.gsw = link()
        else:
            self.gsw = _in_namespace(namespace_name(self.hosts_run, "ground"), link)
        self.wait_packet(lambda p: p.kind == "hk_mission", timeout, "hk_mission telemetry from the CRS")
        return self

    def wait_ready(self, timeout: float = 150.0) -> None:
        """Wait until both ARSs tick (their tree status reaches the ground through the CRS) and
        the CRS reports the lifter, both arms and both end effectors (calibrated, no fault): a
        Start sent sooner reaches ARSs still starting up."""
        needed = {
            ("tree_status", "ars_x"),
            ("tree_status", "ars_y"),
            ("hk_arm_joints", "ars_x"),
            ("hk_arm_joints", "ars_y"),
            ("hk_ee", "ars_x"),
            ("hk_ee", "ars_y"),
            ("hk_lifter", None),
        }
        deadline = time.monotonic() + timeout
        seen = 0
        while needed:
            for packet in self.packets[seen:]:
                agent = packet.fields.get("agent", packet.fields.get("ars"))
                if packet.kind == "hk_ee" and (packet.fields["fault"] or not packet.fields["calibrated"]):
                    continue  # an end effector whose driver has not configured yet
                needed.discard((packet.kind, agent if packet.kind != "hk_lifter" else None))
            seen = len(self.packets)
            if not needed:
                break
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"the system was not ready within {timeout:g} s: no {sorted(needed, key=str)}"
                )
            self.check_running()
            self.link.poll(0.2)

    def start_build(self, timeout: float = 120.0) -> Ack:
        """Send Start until the CRS accepts it (it refuses while its drivers have not reported);
        return the final acknowledgement of the Start that was accepted (COMPLETED expected).

        A copy refused as "already started" after an earlier one got no answer in time means the
        earlier one was accepted: its acks are then awaited."""
        deadline = time.monotonic() + timeout
        last: Ack | None = None
        unanswered: list[SentCommand] = []
        while time.monotonic() < deadline:
            self.check_running()
            sent = self.link.send_command("start")
            ack = self.link.wait_ack(sent, final=True, timeout=5.0)
            if ack is None and sent.acks:  # accepted, still being carried out
                ack = self.link.wait_ack(sent, final=True, timeout=30.0)
            if ack is None:
                unanswered.append(sent)  # not heard in time (the CRS busy or still binding)
                continue
            if ack.detail.startswith("not ready"):
                last = ack
                self.link.poll(1.0)
                continue
            if ack.detail == "already started" and unanswered:
                # An earlier copy was accepted late: its own final ack is the answer.
                for earlier in unanswered:
                    found = self.link.wait_ack(earlier, final=True, timeout=10.0)
                    if found is not None and found.stage is not AckStage.REJECTED:
                        return found
            return ack
        raise AssertionError(f"Start was not accepted within {timeout:g} s (last answer: {last})")

    def stop(self, grace: float = 20.0) -> int | None:
        """Stop the launcher (SIGINT, then SIGTERM and SIGKILL of its group after bounds) and
        close the ground link; return the launcher's exit code."""
        if self.gsw is not None:
            self.gsw.close()
            self.gsw = None
        if self.proc is None:
            return self.exit_code
        if self.proc.poll() is None:
            for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
                try:
                    # SIGINT to the launcher alone: it stops its processes in order. The later
                    # signals go to its whole group, in case the launcher itself is stuck.
                    if sig == signal.SIGINT:
                        self.proc.send_signal(sig)
                    else:
                        os.killpg(self.proc.pid, sig)
                except ProcessLookupError:
                    break
                try:
                    self.proc.wait(timeout=wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
        self.exit_code = self.proc.poll()
        self.proc = None
        return self.exit_code

    def wait_exit(self, timeout: float) -> int:
        """Wait for the launcher to end by itself; return its exit code."""
        assert self.proc is not None
        try:
            self.exit_code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            raise AssertionError(f"the launcher did not end within {timeout:g} s") from exc
        return self.exit_code

    def check_running(self) -> None:
        if self.proc is not None and self.proc.poll() is not None:
            raise AssertionError(f"the launcher ended early (exit code {self.proc.returncode})")

    # -- launch output ----------------------------------------------------------------------
    def launch_output(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def launch_tail(self, chars: int = 8000) -> str:
        return self.launch_output()[-chars:]

    def wait_output(self, text: str, timeout: float) -> str:
        """Wait until ``text`` appears in the launch output; return the output."""
        deadline = time.monotonic() + timeout
        while True:
            out = self.launch_output()
            if text in out:
                return out
            if time.monotonic() > deadline:
                raise AssertionError(f"{text!r} not in the launch output within {timeout:g} s")
            if self.gsw is not None:
                self.gsw.poll(0.2)
            else:
                time.sleep(0.2)

    def pid(self, name: str) -> int:
        """The pid of the launch set's process ``name`` as last started (the launcher says
        "started <name> (pid N)" on every start and restart)."""
        found = re.findall(rf"started {re.escape(name)} \(pid (\d+)\)", self.launch_output())
        assert found, f"the launcher has not started {name}"
        return int(found[-1])

    # -- ground link ------------------------------------------------------------------------
    @property
    def link(self) -> GswLink:
        assert self.gsw is not None, "the run is not started"
        return self.gsw

    def _keep(self, result: object) -> None:
        if isinstance(result, Packet):
            self.packets.append(result)

    def send(self, name: str, params: Mapping[str, Any] | None = None) -> SentCommand:
        return self.link.send_command(name, params)

    def command(self, name: str, params: Mapping[str, Any] | None = None, timeout: float = 20.0) -> Ack:
        """Send a command and return its final acknowledgement (rejected/completed/failed)."""
        sent = self.send(name, params)
        ack = self.link.wait_ack(sent, final=True, timeout=timeout)
        if ack is None:
            raise AssertionError(
                f"no final acknowledgement of {name} within {timeout:g} s "
                f"(acks so far: {[a.stage.name for a in sent.acks]})"
            )
        return ack

    def wait_ack(self, sent: SentCommand, stage: AckStage, timeout: float = 20.0) -> Ack:
        deadline = time.monotonic() + timeout
        while True:
            found = next((a for a in sent.acks if a.stage is stage), None)
            if found is not None:
                return found
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"no {stage.name} ack of {sent.name} within {timeout:g} s "
                    f"(got {[a.stage.name for a in sent.acks]})"
                )
            self.link.poll(0.2)

    def poll(self, seconds: float) -> None:
        """Receive telemetry for ``seconds``."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.link.poll(min(left, 0.2))

    def wait_packet(
        self, predicate: Callable[[Packet], bool], timeout: float, what: str, *, since: int = 0
    ) -> Packet:
        """Wait for a packet (at index ``since`` or later in ``packets``) that satisfies
        ``predicate``; fail with ``what`` and the last packet of each kind otherwise."""
        deadline = time.monotonic() + timeout
        seen = since
        while True:
            for packet in self.packets[seen:]:
                if predicate(packet):
                    return packet
            seen = max(seen, len(self.packets))
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"{what}: not seen within {timeout:g} s; last telemetry: {self.last_of_each()}"
                )
            self.check_running()
            self.link.poll(0.2)

    def wait_kind(
        self,
        kind: str,
        predicate: Callable[[Mapping[str, Any]], bool],
        timeout: float,
        what: str,
        *,
        since: int = 0,
    ) -> Mapping[str, Any]:
        """Wait for a ``kind`` packet whose fields satisfy ``predicate``; return its fields."""
        return self.wait_packet(
            lambda p: p.kind == kind and predicate(p.fields), timeout, what, since=since
        ).fields

    def of_kind(self, kind: str, *, since: int = 0) -> list[Mapping[str, Any]]:
        return [p.fields for p in self.packets[since:] if p.kind == kind]

    def last(self, kind: str) -> Mapping[str, Any] | None:
        return next((p.fields for p in reversed(self.packets) if p.kind == kind), None)

    def events(self, *, since: int = 0, code: str | None = None) -> list[Mapping[str, Any]]:
        return [f for f in self.of_kind("event", since=since) if code is None or f["code"] == code]

    def last_of_each(self) -> dict[str, Mapping[str, Any]]:
        out: dict[str, Mapping[str, Any]] = {}
        for packet in reversed(self.packets):
            if packet.kind not in out and packet.kind not in ("tree_status",):
                out[packet.kind] = packet.fields
        return out

    # -- arms -------------------------------------------------------------------------------
    def arm_q(self, ars: str, *, since: int = 0) -> list[tuple[float, ...]]:
        """The joint positions of one arm in every ``hk_arm_joints`` packet since ``since``."""
        return [
            tuple(f[f"q{i}"] for i in range(6))
            for f in self.of_kind("hk_arm_joints", since=since)
            if f["ars"] == ars
        ]

    def wait_arm_moving(
        self,
        ars: str,
        timeout: float,
        *,
        tolerance: float = 0.01,
        start: tuple[float, ...] | None = None,
        since: int = 0,
    ) -> tuple[float, ...]:
        """Wait until ``ars``'s arm stands more than ``tolerance`` rad (in some joint) from
        ``start`` (by default where it stood first); return where it stands then."""
        if start is None:
            if not self.arm_q(ars):
                self.wait_kind("hk_arm_joints", lambda f: f["ars"] == ars, timeout, f"{ars} joints")
            start = self.arm_q(ars)[0]
        ref = start
        fields = self.wait_kind(
            "hk_arm_joints",
            lambda f: f["ars"] == ars and max(abs(f[f"q{i}"] - ref[i]) for i in range(6)) > tolerance,
            timeout,
            f"{ars}'s arm moving away from {ref}",
            since=since,
        )
        return tuple(fields[f"q{i}"] for i in range(6))

    def wait_through_faults(
        self,
        predicate: Callable[[Packet], bool],
        timeout: float,
        what: str,
        *,
        clear_faults: int = 2,
        since: int | None = None,
    ) -> tuple[Packet, list[str]]:
        """Wait for a packet that satisfies ``predicate``. A fault raised meanwhile (on this loaded
        machine an end-effector servo sometimes misses a read and the ARS fails its request) is
        cleared from the ground, as an operator would, up to ``clear_faults`` times; the tree then
        sends the request again. A lifter link fault, which clears itself, is waited out.
        Returns the packet and the faults cleared."""
        cleared: list[str] = []
        deadline = time.monotonic() + timeout
        since = len(self.packets) if since is None else since
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(
                    f"{what}: not seen within {timeout:g} s (faults cleared: {cleared}); "
                    f"last: {self.last_of_each()}"
                )
            packet = self.wait_packet(
                lambda p: predicate(p) or (p.kind == "hk_mission" and p.fields["run_state"] == "fault"),
                left,
                what,
                since=since,
            )
            since = len(self.packets)
            if predicate(packet):
                return packet, cleared
            if packet.fields["fault"].startswith("lifter link down"):
                continue  # it clears itself when the link is back; the ground cannot clear it
            if len(cleared) >= clear_faults:
                raise AssertionError(
                    f"the build faulted before {what}: {packet.fields['fault']} "
                    f"(faults cleared before: {cleared})"
                )
            cleared.append(packet.fields["fault"])
            ack = self.command("set_blackboard_value", {"key": "clear_fault", "value": True})
            assert ack.stage is AckStage.COMPLETED, ack
            self.wait_kind(
                "hk_mission", lambda f: f["run_state"] != "fault", 30, "the fault cleared", since=since
            )
            since = len(self.packets)

    def wait_build_moves_arm(self, ars: str, timeout: float, *, clear_faults: int = 2) -> list[str]:
        """Wait until ``ars``'s arm moves in the build, clearing faults on the way
        (:meth:`wait_through_faults`); return the faults cleared."""
        start = self.arm_q(ars)[0] if self.arm_q(ars) else None
        _, cleared = self.wait_through_faults(
            lambda p: (
                p.kind == "hk_arm_joints"
                and p.fields["ars"] == ars
                and start is not None
                and max(abs(p.fields[f"q{i}"] - start[i]) for i in range(6)) > 0.01
            ),
            timeout,
            f"{ars}'s arm moving",
            clear_faults=clear_faults,
        )
        return cleared

    def wait_arm_still(
        self, ars: str, timeout: float, *, samples: int = 5, tolerance: float = 1e-3
    ) -> tuple[float, ...]:
        """Wait until ``samples`` consecutive ``hk_arm_joints`` packets of ``ars`` agree within
        ``tolerance`` rad; return where the arm stands."""
        deadline = time.monotonic() + timeout
        since = len(self.packets)
        while True:
            qs = self.arm_q(ars, since=since)[-samples:]
            if len(qs) == samples and all(
                max(abs(a - b) for a, b in zip(q, qs[0], strict=True)) <= tolerance for q in qs
            ):
                return qs[-1]
            if time.monotonic() > deadline:
                raise AssertionError(f"{ars}'s arm did not stand still within {timeout:g} s: {qs}")
            self.check_running()
            self.link.poll(0.2)

    # -- the run's recording ------------------------------------------------------------------
    def last_ground_truth(self) -> dict[str, np.ndarray]:
        """Where the twin last had each object (``tower``, ``part/<dispenser>/<i>``, ...), world
        position, from the recording's ``/twin/ground_truth``."""
        last: dict[str, np.ndarray] = {}
        for msg in self.recorded("/twin/ground_truth"):
            for tf in msg.transforms:
                t = tf.transform.translation
                last[tf.child_frame_id] = np.array([t.x, t.y, t.z])
        return last

    def tower_model(self) -> dict[str, Any]:
        """The CRS's persisted tower model (``<run_dir>/tower_model.json``) as it stands."""
        return json.loads((self.run_dir / "tower_model.json").read_text())

    def goal_statuses(self, action: str) -> dict[bytes, int]:
        """The last status (``action_msgs/GoalStatus``) of every goal of the action server
        ``action`` (``/ars_x/add_member``) in the recording, by goal id."""
        last: dict[bytes, int] = {}
        for status in self.recorded(f"{action}/_action/status"):
            for entry in status.status_list:
                last[bytes(entry.goal_info.goal_id.uuid)] = entry.status
        return last

    def goals_succeeded(self, action: str) -> int:
        """How many goals of the action server ``action`` ended SUCCEEDED."""
        return sum(s == GoalStatus.STATUS_SUCCEEDED for s in self.goal_statuses(action).values())

    def recorded(self, topic: str, *, times: bool = False) -> list[Any]:
        """The decoded messages of ``topic`` in the run's MCAP recording (complete once the
        launcher has stopped: the recorder closes the file on its way out); with ``times``, as
        (time, message) pairs, the time the recorder's ROS time in s (the twin's clock)."""
        from mcap.exceptions import McapError

        from tlt_common.recording.reading import read_messages

        path = self.run_dir / "recording.mcap"
        try:
            messages = read_messages(path, topics=[topic])
            if times:
                return [(m.log_time * 1e-9, decoded) for _s, _c, m, decoded in messages]
            return [decoded for _s, _c, _m, decoded in messages]
        except McapError as exc:
            said = [
                line
                for line in self.log_path.read_text(errors="replace").splitlines()
                if line.startswith("[recorder]") or (line.startswith("[launch]") and "recorder" in line)
            ]
            raise AssertionError(
                f"{path} is not a complete recording ({exc}); what the launch log "
                "says of the recorder:\n" + "\n".join(said[-40:])
            ) from exc

    # -- helpers ----------------------------------------------------------------------------
    def _wait(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            self.check_running()
            if time.monotonic() > deadline:
                raise AssertionError(f"{what} within {timeout:g} s")
            time.sleep(0.2)


__all__ = ["UR_X_HOST", "UR_Y_HOST", "SystemRun", "late_bay_scenario"]
