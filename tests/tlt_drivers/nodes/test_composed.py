"""Several driver nodes in one process (``tlt-drivers``): every driver's arguments checked before
anything starts; one node stuck in a callback holds only its own thread; one whose callback raises
takes the process down with exit code 1 after every node was shut down; and the real lifter and
Top Grippers drivers against their emulators, side by side in one process."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
from tlt_interfaces.msg import GripperState, LifterState
from tlt_sim.emulators.lifter_firmware import FirmwareConfig, LifterFirmware
from tlt_sim.emulators.lifter_pty import PtyFirmwareServer
from tlt_sim.emulators.mightyzap_chain import MightyZapChain

from tlt_drivers.lifter.config import DEFAULT_CONFIG as LIFTER_CONFIG
from tlt_drivers.node_main import DriverStartError
from tlt_drivers.nodes.composed import main, parse_drivers

TIMEOUT_S = 30.0

# Toy nodes for spin_drivers: each publishes a count on /probe/<name> at 20 Hz; at its tenth tick
# a "stuck" one blocks in its callback for good and a "raise" one raises.
PROBE = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from rclpy.node import Node
    from std_msgs.msg import String
    from tlt_drivers.node_main import Driver, spin_drivers

    out = Path(sys.argv[1])

    class Probe(Node):
        def __init__(self, name, mode):
            super().__init__(name)
            self.name, self.mode, self.ticks = name, mode, 0
            self.pub = self.create_publisher(String, f"/probe/{name}", 10)
            self.create_timer(0.05, self.tick)

        def tick(self):
            self.ticks += 1
            if self.ticks == 10 and self.mode == "stuck":
                (out / f"{self.name}.stuck").touch()
                time.sleep(3600)
            if self.ticks == 10 and self.mode == "raise":
                raise RuntimeError("the probe's callback failed")
            self.pub.publish(String(data=str(self.ticks)))

        def shutdown(self):
            (out / f"{self.name}.shutdown").touch()

    pairs = [a.split("=") for a in sys.argv[2:]]
    sys.exit(spin_drivers("probe", [Driver(n, lambda n=n, m=m: Probe(n, m)) for n, m in pairs], []))
""")


class Listener:
    """A private ROS context counting what arrives on some topics."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("composed_probe_listener", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.heard: dict[str, list] = {}

    def listen(self, msg_type: type, topic: str) -> list:
        heard = self.heard.setdefault(topic, [])
        self.node.create_subscription(msg_type, topic, heard.append, 50)
        return heard

    def spin_until(self, predicate: Callable[[], bool], what: str, proc: subprocess.Popen) -> None:
        deadline = time.monotonic() + TIMEOUT_S
        while not predicate():
            assert proc.poll() is None, f"the process exited ({proc.returncode}) before {what}"
            assert time.monotonic() < deadline, f"no {what} within {TIMEOUT_S:g} s"
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def listener():
    listener = Listener()
    yield listener
    listener.close()


def start_probe(tmp_path: Path, *nodes: str) -> subprocess.Popen:
    script = tmp_path / "probe.py"
    script.write_text(PROBE)
    return subprocess.Popen(
        [sys.executable, str(script), str(tmp_path), *nodes],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def stop(proc: subprocess.Popen) -> tuple[int, str]:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        code = proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return code, proc.stdout.read()


def test_a_node_stuck_in_a_callback_holds_only_its_own_thread(tmp_path, listener):
    alive = listener.listen(String, "/probe/alive")
    proc = start_probe(tmp_path, "alive=publish", "stuck=stuck")
    try:
        listener.spin_until(lambda: (tmp_path / "stuck.stuck").exists(), "the stuck node's block", proc)
        heard_when_stuck = len(alive)
        # On one executor the other node would not publish again; on its own thread it goes on.
        listener.spin_until(lambda: len(alive) >= heard_when_stuck + 10, "ten more counts", proc)
    finally:
        code, output = stop(proc)
    assert code == 0, output
    assert (tmp_path / "alive.shutdown").exists(), output


def test_a_callback_that_raises_stops_every_node_and_exits_1(tmp_path, listener):
    proc = start_probe(tmp_path, "alive=publish", "broken=raise")
    try:
        code = proc.wait(timeout=TIMEOUT_S)
    finally:
        code, output = stop(proc)
    assert code == 1, output
    assert "driver broken stopped on an error" in output and "the probe's callback failed" in output
    assert (tmp_path / "alive.shutdown").exists() and (tmp_path / "broken.shutdown").exists(), output


def test_every_drivers_arguments_are_checked_and_a_bad_one_named(tmp_path, capsys):
    with pytest.raises(DriverStartError, match="must start with --driver KIND"):
        parse_drivers(["--port", "/dev/x"])
    with pytest.raises(DriverStartError, match="--driver #2: 'gripper' is not a driver"):
        parse_drivers(["--driver", "lifter", "--driver", "gripper"])
    with pytest.raises(DriverStartError, match=r"--driver lifter \(#1\): --answer-timeout-s must be in"):
        parse_drivers(["--driver", "lifter", "--answer-timeout-s", "0", "--driver", "top-grippers"])
    with pytest.raises(DriverStartError, match="two drivers would be node ee_x"):
        parse_drivers(["--driver", "ee-x", "--driver", "ee-x"])
    missing = tmp_path / "nope.yaml"
    assert main(["--driver", "top-grippers", "--driver", "camera-mounts", "--config", str(missing)]) == 2
    assert "tlt-drivers: --driver camera-mounts (#2):" in capsys.readouterr().err
    drivers = parse_drivers(["--driver", "lifter", "--driver", "ur", "--driver", "ee-y", "--port", "/tmp/p"])
    assert [d.name for d in drivers] == ["lifter", "ur_x", "ee_y"]


def test_the_lifter_and_top_grippers_drivers_in_one_process(tmp_path, listener):
    firmware = LifterFirmware(FirmwareConfig(init_duration_s=0.05))
    lifter_config = tmp_path / "lifter.yaml"  # the link timeout widened for a loaded test machine
    lifter_config.write_text(
        LIFTER_CONFIG.read_text().replace("link_timeout_s: 0.2\n", "link_timeout_s: 1.0\n")
    )
    lifter_states = listener.listen(LifterState, "/lifter/state")
    gripper_states = listener.listen(GripperState, "/top_grippers/state")
    chain = MightyZapChain([1, 2, 3, 4])
    chain.start()
    try:
        with PtyFirmwareServer(firmware, link_path=tmp_path / "lifter") as server:
            proc = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "tlt_drivers.nodes.composed",
                    "--driver",
                    "lifter",
                    "--config",
                    str(lifter_config),
                    "--port",
                    str(server.link_path),
                    "--driver",
                    "top-grippers",
                    "--port",
                    chain.port,
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            try:
                listener.spin_until(
                    lambda: (
                        lifter_states
                        and lifter_states[-1].link_ok
                        and lifter_states[-1].state == LifterState.STATE_HARDWARE_CONTROL
                    ),
                    "healthy LifterState",
                    proc,
                )
                listener.spin_until(
                    lambda: (
                        gripper_states and gripper_states[-1].torque_enabled and not gripper_states[-1].fault
                    ),
                    "healthy Top Grippers' state",
                    proc,
                )
                # A board that stops answering faults its own driver; the lifter's keeps its link.
                chain.drop_link()
                listener.spin_until(lambda: gripper_states[-1].fault, "the Top Grippers' fault", proc)
                seen = len(lifter_states)
                listener.spin_until(lambda: len(lifter_states) >= seen + 25, "LifterState going on", proc)
                assert lifter_states[-1].link_ok, lifter_states[-1]
            finally:
                code, output = stop(proc)
    finally:
        chain.stop()
    assert code == 0, output
