"""The emulated controller's configuration, configured faults and dashboard, in-process with plain
sockets (no ur-rtde client, so no need for a second process)."""

from __future__ import annotations

import dataclasses
import socket
import time

import pytest
import yaml
from tlt_sim.emulators.ur_controller import URControllerEmulator
from tlt_sim.emulators.ur_controller_config import CONFIG_DIR, load_controller_config

from tlt_common.config_schema import ConfigError
from tlt_drivers.ur.rtde_link import probe_rtde

HOST = "127.0.0.6"


def _config(**changes):
    base = load_controller_config(CONFIG_DIR / "ur_x_controller.yaml")
    return dataclasses.replace(base, host=HOST, **changes)


def _dashboard(request: str) -> str:
    with socket.create_connection((HOST, 29999), timeout=2.0) as sock:
        stream = sock.makefile("rw", newline="\n")
        assert stream.readline().startswith("Connected: Universal Robots Dashboard Server")
        stream.write(request + "\n")
        stream.flush()
        return stream.readline().strip()


@pytest.mark.parametrize("arm,host", [("x", "127.0.0.2"), ("y", "127.0.0.3")])
def test_shipped_configs_load(arm: str, host: str) -> None:
    config = load_controller_config(CONFIG_DIR / f"ur_{arm}_controller.yaml")
    assert config.host == host and config.version[:2] == (5, 11)


def test_bad_config_names_the_key(tmp_path) -> None:
    doc = yaml.safe_load((CONFIG_DIR / "ur_x_controller.yaml").read_text())
    doc["q0"] = [0.0, 1.0]
    path = tmp_path / "emu.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        load_controller_config(path)
    assert err.value.key == "q0"


def test_configured_link_down_refuses_connections_until_restored() -> None:
    with URControllerEmulator(_config(fault_link_down=True)) as emu:
        assert "unreachable" in probe_rtde(HOST, 0.3)
        emu.restore_link()
        assert probe_rtde(HOST, 0.3) is None


def test_configured_no_answer_holds_requests_until_it_ends() -> None:
    with URControllerEmulator(_config(fault_no_answer=True)) as emu:
        assert "did not answer" in probe_rtde(HOST, 0.3)
        emu.set_no_answer(False)
        assert probe_rtde(HOST, 0.3) is None


def test_configured_protective_stop_and_the_unlock_delay() -> None:
    with URControllerEmulator(_config(fault_protective_stop=True, unlock_delay_s=0.3)) as emu:
        assert _dashboard("safetymode") == "Safetymode: PROTECTIVE_STOP"
        assert emu.safety_status_bits() & (1 << 2)
        assert _dashboard("unlock protective stop").startswith("Cannot unlock protective stop")
        time.sleep(0.35)
        assert _dashboard("unlock protective stop") == "Protective stop releasing"
        assert _dashboard("safetymode") == "Safetymode: NORMAL"


def test_dashboard_answers() -> None:
    with URControllerEmulator(_config(remote_control=False)):
        assert _dashboard("PolyscopeVersion").startswith("URSoftware 5.11.0")
        assert _dashboard("is in remote control") == "false"
        assert _dashboard("get serial number").isdigit()
        assert _dashboard("programState") == "STOPPED rtde_control"
        assert _dashboard("fly to the moon") == "could not understand: 'fly to the moon'"


def test_external_clock_moves_the_arm_only_when_the_twin_advances_it() -> None:
    with URControllerEmulator(_config(clock="external")) as emu:
        target = list(emu.arm.positions())
        target[0] += 0.5  # at v=1, a=2: 0.5 s ramp and 0.5 s to the end, 1.0 s in all
        emu.arm.move_joints(target, 1.0, 2.0)
        time.sleep(0.1)
        assert emu.arm.positions()[0] == pytest.approx(target[0] - 0.5)
        assert emu.timestamp() == 0.0
        for _ in range(250):
            emu.advance(0.002)
        assert emu.timestamp() == pytest.approx(0.5)
        assert emu.arm.positions()[0] == pytest.approx(target[0] - 0.25)
        for _ in range(250):
            emu.advance(0.002)
        assert emu.arm.positions()[0] == pytest.approx(target[0]) and not emu.arm.moving
