"""Every device emulator of the EDU, built from the drivers' own hardware maps and bound to one Scene.

:class:`TwinDevices` reads ``config/hardware/*.yaml`` (the same files the driver nodes read), so ids,
scales and GPIO lines cannot drift apart, and builds:

* the lifter firmware (``config/sim/lifter_firmware.yaml``) on a pty that the twin steps
  (``self_stepping=False``), encoders starting where the model's carriages are;
* the Dynamixel chains ``active_grippers``, ``camera_mounts``, ``ee_x``, ``ee_y`` and the MightyZAP
  chain ``top_grippers``, with ``clock=None`` (advanced by the twin), each shaft starting at the
  model joint's position;
* the two UR controllers (``config/sim/ur_*_controller.yaml``, external clock) on the addresses
  of ``run.yaml``, starting at the model arms' home, each in a child process clocked by the twin
  (:mod:`tlt_sim.twin.ur_host`);
* the EE GPIO chips (the state files the EE drivers open under ``$TLT_RUN_DIR``).

:meth:`start` publishes each pty at ``<run_dir>/<component>`` (the names the stand-alone emulators
use) and opens the UR ports; :meth:`advance` moves every emulator on by ``dt`` of sim time;
:meth:`close` withdraws the links and closes everything. A bad hardware map raises ``ConfigError``.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

from tlt_common.config_schema import load_yaml
from tlt_drivers.dynamixel.config import validate_chain
from tlt_drivers.dynamixel.joint_scale import JointScale
from tlt_drivers.gpio.config import CONFIG_DIR, load_gpio_config
from tlt_drivers.lifter.config import load_lifter_config
from tlt_drivers.mightyzap.config import validate_mightyzap
from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.emulators.dynamixel_servo import DynamixelServo
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip
from tlt_sim.emulators.lifter_firmware import LifterFirmware, load_firmware_config
from tlt_sim.emulators.lifter_pty import PtyFirmwareServer
from tlt_sim.emulators.mightyzap_chain import ADDR_GOAL_POSITION, MightyZapActuator, MightyZapChain
from tlt_sim.emulators.pty_device import publish_link, withdraw_link
from tlt_sim.emulators.ur_controller_config import load_controller_config
from tlt_sim.model import names
from tlt_sim.model.scene import Scene
from tlt_sim.twin.bindings import (
    EEGpioBinding,
    LifterBinding,
    ServoJointBinding,
    URArmBinding,
)
from tlt_sim.twin.settings import REPO, TwinSettings
from tlt_sim.twin.ur_host import URControllerHost

log = logging.getLogger("tlt.twin")

SIM_CONFIG = REPO / "config" / "sim"
DYNAMIXEL_CHAINS = ("active_grippers", "camera_mounts", "ee_x", "ee_y")
# Joint units the model joint may trail its shaft before a stall counts as blocked.
BLOCK_TOLERANCE = {"rad": 0.05, "m": 0.002}
# Where the width carriage starts, m from its limit switch (the driver finds it by calibrating).
WIDTH_START_M = 0.005


def model_joint(component: str, driver_joint: str, hardware: dict) -> str:
    """The model joint a driver joint moves (docs/twin.md, 'Binding the emulators')."""
    if component.startswith("ee_"):
        ee = hardware["ee"]
        if driver_joint == ee["width_joint"]:
            return names.width_joint(ee["ars"])
        side = "ab"[ee["grasp_joints"].index(driver_joint)]
        return names.grasp_joint(ee["ars"], side)
    return driver_joint


class TwinDevices:
    """The emulators and their bindings; see the module docstring."""

    def __init__(
        self, scene: Scene, settings: TwinSettings, run_dir: str | Path, hardware_dir: Path = CONFIG_DIR
    ) -> None:
        self.scene = scene
        self.settings = settings
        self.run_dir = Path(run_dir)
        self.hardware_dir = Path(hardware_dir)
        self.bindings: list = []
        self.servo_bindings: dict[str, ServoJointBinding] = {}  # by model joint
        self.chains: dict[str, DynamixelChain | MightyZapChain] = {}
        #: each serial link's driver control period (sim seconds), from its hardware map
        self.driver_periods: dict[str, float] = {}
        #: the links whose device stops on its own when commands stop coming (sim seconds)
        self.driver_watchdogs: dict[str, float] = {}
        self._links: dict[str, str] = {}
        self._build_lifter()
        for component in DYNAMIXEL_CHAINS:
            self._build_dynamixel(component)
        self._build_mightyzap("top_grippers")
        self.ur: dict[str, URControllerHost] = {}
        for component in ("ur_x", "ur_y"):
            self._build_ur(component)
        self.gpio: dict[str, EEGpioBinding] = {}
        for component in ("ee_x", "ee_y"):
            self._build_gpio(component)

    # --- building ------------------------------------------------------------------------------
    def _build_lifter(self) -> None:
        lifter = load_lifter_config(self.hardware_dir / "lifter.yaml")
        fw_config, _ = load_firmware_config(SIM_CONFIG / "lifter_firmware.yaml")
        joints = [j.name for j in lifter.joints]
        cpm = [j.counts_per_m for j in lifter.joints]
        start = tuple(round(self.scene.position(j) * c) for j, c in zip(joints, cpm, strict=True))
        self.firmware = LifterFirmware(dataclasses.replace(fw_config, initial_positions_counts=start))
        self.lifter_server = PtyFirmwareServer(self.firmware, self_stepping=False)
        self.lifter = LifterBinding(self.firmware, joints, cpm)
        self.driver_periods["lifter"] = lifter.command_period_s
        self.driver_watchdogs["lifter"] = self.firmware.config.watchdog_timeout_s
        self.bindings.append(self.lifter)

    def _build_dynamixel(self, component: str) -> None:
        path = self.hardware_dir / f"{component}.yaml"
        hardware = load_yaml(path)
        cfg = validate_chain(hardware, path)
        servos = []
        for j in cfg["joints"]:
            joint = model_joint(component, j["name"], cfg)
            scale = JointScale(
                j["unit"], j["gear_ratio"], j["lead_m_per_rev"], j["zero_ticks"], j["direction"]
            )
            if joint.endswith("/width"):
                # The shaft's ticks say nothing about the carriage after power-up (the driver
                # calibrates on the limit switch): the carriage is WIDTH_START_M from the switch
                # wherever the shaft happens to stand.
                self.scene.set_joint_state(joint, WIDTH_START_M)
                scale = dataclasses.replace(scale, zero_ticks=scale.zero_ticks + 4096 * 3.25)
            servo = DynamixelServo(
                j["id"],
                position_ticks=scale.zero_ticks
                + scale.direction * self.scene.position(joint) * scale.ticks_per_unit,
            )
            servos.append(servo)
            self._bind_servo(
                joint,
                servo,
                scale.to_ticks,
                scale.from_ticks,
                lambda s=servo: float(s.get("goal_position")),
                BLOCK_TOLERANCE[j["unit"]],
            )
        self.chains[component] = DynamixelChain(servos, clock=None)
        self.driver_periods[component] = 1.0 / cfg["rate_hz"]

    def _build_mightyzap(self, component: str) -> None:
        path = self.hardware_dir / f"{component}.yaml"
        cfg = validate_mightyzap(load_yaml(path), path)
        per_m = cfg["full_stroke_ticks"] / cfg["stroke_m"]
        actuators = []
        for a in cfg["actuators"]:
            joint = a["name"]
            act = MightyZapActuator(a["id"], position=self.scene.position(joint) * per_m)
            actuators.append(act)
            self._bind_servo(
                joint,
                act,
                lambda m: m * per_m,
                lambda t: t / per_m,
                lambda s=act: float(s.get(ADDR_GOAL_POSITION)),
                BLOCK_TOLERANCE["m"],
            )
        self.chains[component] = MightyZapChain(actuators, clock=None)
        self.driver_periods[component] = 1.0 / cfg["rate_hz"]

    def _bind_servo(self, joint, shaft, to_ticks, from_ticks, goal, tolerance) -> None:
        binding = ServoJointBinding(joint, shaft, to_ticks, from_ticks, goal, tolerance)
        self.servo_bindings[joint] = binding
        self.bindings.append(binding)

    def _build_ur(self, component: str) -> None:
        arm = names.ARMS[("ur_x", "ur_y").index(component)]
        config = load_controller_config(SIM_CONFIG / f"{component}_controller.yaml")
        joints = names.arm_joints(arm)
        config = dataclasses.replace(
            config,
            host=self.settings.ur_hosts[component],
            clock="external",
            q0=[self.scene.position(j) for j in joints],
        )
        host = URControllerHost(config)
        self.ur[component] = host
        self.bindings.append(URArmBinding(host.positions, joints))

    def _build_gpio(self, component: str) -> None:
        hardware = validate_chain(load_yaml(self.hardware_dir / f"{component}.yaml"))
        ee = hardware["ee"]
        gpio = load_gpio_config(self.hardware_dir / ee["gpio_config"])
        lines = {spec.name: spec for spec in gpio.lines}
        switch = lines[ee["limit_switch_input"]]
        guns = {
            lines[name].line: ("ab"[i], lines[name].active_low)
            for i, name in enumerate(ee["rivet_gun_outputs"])
        }
        # The state file lives in the run folder, as the EE driver resolves it.
        state = self.run_dir / Path(gpio.emulator_state).name
        binding = EEGpioBinding(EmulatedGpioChip(state), ee["ars"], switch.line, switch.active_low, guns)
        binding.sense(self.scene, 0.0)
        self.gpio[component] = binding
        self.bindings.append(binding)

    # --- running ---------------------------------------------------------------------------------
    def start(self) -> None:
        """Serve every link and publish it under the run folder."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.lifter_server.start()
        self._links["lifter"] = self.lifter_server.path
        for component, chain in self.chains.items():
            self._links[component] = chain.start()
        for host in self.ur.values():
            host.start()
        for component, target in self._links.items():
            publish_link(self.run_dir / component, target)

    def link_traffic(self) -> dict[str, int]:
        """Frames or packets each serial link has received from its driver so far."""
        counts = {"lifter": self.firmware.frames_received}
        counts.update({name: chain.packets_seen for name, chain in self.chains.items()})
        return counts

    def advance(self, dt: float) -> None:
        """Move every emulator on by ``dt`` seconds of sim time (the model is stepped by the caller)."""
        self.firmware.step(dt, integrate=False)
        for chain in self.chains.values():
            chain.advance(dt)
        for host in self.ur.values():
            host.advance(dt)

    def drive(self, dt: float) -> None:
        for binding in self.bindings:
            binding.drive(self.scene, dt)

    def sense(self, dt: float) -> None:
        for binding in self.bindings:
            binding.sense(self.scene, dt)

    def close(self) -> None:
        for component, target in self._links.items():
            withdraw_link(self.run_dir / component, target)
        self._links.clear()
        self.lifter_server.stop()
        for chain in self.chains.values():
            chain.stop()
        for host in self.ur.values():
            host.close()
        for binding in self.gpio.values():
            binding.chip.close()


__all__ = ["DYNAMIXEL_CHAINS", "TwinDevices", "model_joint"]
