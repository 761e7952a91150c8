"""One arm's RTDE server side: the client connection with its recipes, the answers to RTDE
messages, and the values of the output variables streamed from the arm's state (UR RTDE guide)."""

from __future__ import annotations

import contextlib
import logging
import socket
import struct
import threading
import time

from tlt_sim.emulators import rtde_wire as wire
from tlt_sim.emulators.ur_arm import UR10eArm
from tlt_sim.emulators.ur_control_script import ControlScript, Registers
from tlt_sim.emulators.ur_controller_config import URControllerConfig

log = logging.getLogger("tlt.sim.ur")

# RTDE enumerations (UR RTDE guide).
ROBOT_MODE_RUNNING = 7
JOINT_MODE_RUNNING = 253
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
SAFETY_BIT_NORMAL = 1 << 0
SAFETY_BIT_PROTECTIVE_STOP = 1 << 2
SAFETY_BIT_STOPPED_DUE_TO_SAFETY = 1 << 10
ROBOT_BIT_POWER_ON = 1 << 0
ROBOT_BIT_PROGRAM_RUNNING = 1 << 1


def _zero(kind: str) -> object:
    if kind.startswith("VECTOR"):
        return [0.0 if kind.endswith("D") else 0] * int(kind[6])
    return 0.0 if kind == "DOUBLE" else (False if kind == "BOOL" else 0)


# Variables the emulator has no model for read as zero of their type, never NOT_FOUND.
OUTPUT_DEFAULTS = {name: _zero(kind) for name, kind in wire.OUTPUT_TYPES.items()}


def runtime_state(program_running: bool) -> int:
    return RUNTIME_PLAYING if program_running else RUNTIME_STOPPED


def safety_status_bits(protective_stopped: bool) -> int:
    if protective_stopped:
        return SAFETY_BIT_PROTECTIVE_STOP | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
    return SAFETY_BIT_NORMAL


def output_values(
    arm: UR10eArm, timestamp: float, program: ControlScript | None, protective_stopped: bool
) -> dict[str, object]:
    """Every output variable's current value, by RTDE name."""
    q, qd = arm.positions(), arm.velocities()
    tcp = arm.tcp_pose()
    target_q = arm.target_q.tolist()
    running = program is not None and program.running
    robot_bits = ROBOT_BIT_POWER_ON | (ROBOT_BIT_PROGRAM_RUNNING if running else 0)
    zeros6 = [0.0] * 6
    values: dict[str, object] = dict(OUTPUT_DEFAULTS)
    values.update(
        {
            "timestamp": timestamp,
            "target_q": target_q,
            "target_qd": qd,
            "target_qdd": zeros6,
            "target_current": zeros6,
            "target_moment": zeros6,
            "actual_q": q,
            "actual_qd": qd,
            "actual_qdd": zeros6,
            "actual_current": zeros6,
            "actual_current_window": zeros6,
            "actual_moment": zeros6,
            "joint_control_output": zeros6,
            "actual_TCP_pose": tcp,
            "actual_TCP_speed": zeros6,
            "actual_TCP_force": zeros6,
            "target_TCP_pose": tcp,
            "target_TCP_speed": zeros6,
            "actual_digital_input_bits": 0,
            "joint_temperatures": [30.0] * 6,
            "actual_execution_time": 0.2,
            "robot_mode": ROBOT_MODE_RUNNING,
            "joint_mode": [JOINT_MODE_RUNNING] * 6,
            "safety_mode": SAFETY_MODE_PROTECTIVE_STOP if protective_stopped else SAFETY_MODE_NORMAL,
            "safety_status": SAFETY_MODE_PROTECTIVE_STOP if protective_stopped else SAFETY_MODE_NORMAL,
            "actual_tool_accelerometer": [0.0, 0.0, 9.81],
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            "actual_momentum": 0.0,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0,
            "actual_robot_current": 0.5,
            "actual_joint_voltage": [48.0] * 6,
            "actual_digital_output_bits": 0,
            "runtime_state": runtime_state(running),
            "elbow_position": [0.0, 0.0, 0.0],
            "elbow_velocity": [0.0, 0.0, 0.0],
            "robot_status_bits": robot_bits,
            "safety_status_bits": safety_status_bits(protective_stopped),
            "payload": program.payload[0] if program else 0.0,
            "payload_cog": program.payload[1] if program else [0.0, 0.0, 0.0],
            "payload_inertia": zeros6,
            "ft_raw_wrench": zeros6,
            "script_control_line": 0,
        }
    )
    return values


class Connection:
    """One accepted socket with a send lock (replies and streamed data share it)."""

    def __init__(self, sock: socket.socket, kind: str) -> None:
        self.sock = sock
        self.kind = kind
        self.send_lock = threading.Lock()
        self.closed = False
        # RTDE only
        self.output: wire.Recipe | None = None
        self.inputs: dict[int, wire.Recipe] = {}
        self.period = 0.002
        self.next_send = 0.0
        self.started = False

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self.sock.sendall(data)

    def close(self) -> None:
        self.closed = True
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self.sock.close()


def handle_message(
    conn: Connection,
    kind: int,
    payload: bytes,
    config: URControllerConfig,
    registers: Registers,
    unknown_names: list[str],
) -> None:
    """Answer one RTDE message of a client (``DATA_PACKAGE``: its inputs go to ``registers``); the
    names a recipe asks for that the emulator does not know are added to ``unknown_names``."""
    if kind == wire.REQUEST_PROTOCOL_VERSION:
        conn.send(wire.frame(kind, b"\x01"))
    elif kind == wire.GET_URCONTROL_VERSION:
        conn.send(wire.frame(kind, struct.pack(">IIII", *config.version)))
    elif kind == wire.SETUP_OUTPUTS:
        (frequency,) = struct.unpack(">d", payload[:8])
        recipe = wire.Recipe(1, wire.parse_names(payload[8:]), wire.OUTPUT_TYPES)
        if recipe.unknown:
            log.error("%s: unknown output names %s", config.host, recipe.unknown)
            unknown_names.extend(recipe.unknown)
        conn.output = recipe
        conn.period = 1.0 / frequency if frequency > 0 else 1.0 / config.tick_hz
        conn.send(wire.frame(kind, recipe.answer()))
    elif kind == wire.SETUP_INPUTS:
        recipe = wire.Recipe(len(conn.inputs) + 1, wire.parse_names(payload), wire.INPUT_TYPES)
        if recipe.unknown:
            unknown_names.extend(recipe.unknown)
        conn.inputs[recipe.recipe_id] = recipe
        conn.send(wire.frame(kind, recipe.answer()))
    elif kind == wire.START:
        ok = conn.output is not None and conn.output.valid
        conn.send(wire.frame(kind, b"\x01" if ok else b"\x00"))
        conn.next_send = time.monotonic()
        conn.started = ok
    elif kind == wire.PAUSE:
        conn.started = False
        conn.send(wire.frame(kind, b"\x01"))
    elif kind == wire.DATA_PACKAGE:
        recipe = conn.inputs.get(payload[0]) if payload else None
        if recipe is None or not recipe.valid:
            log.warning("%s: data package for unknown input recipe", config.host)
            return
        apply_inputs(registers, recipe.unpack(payload))
    else:
        log.warning("%s: unknown RTDE message type %d", config.host, kind)


def apply_inputs(registers: Registers, values: dict[str, object]) -> None:
    """Write the input registers an RTDE input package names."""
    with registers.lock:
        for name, value in values.items():
            reg = wire.register_index(name)
            if reg is None:
                continue
            kind, index = reg
            if kind == "int":
                registers.in_int[index] = int(value)
            else:
                registers.in_double[index] = float(value)


__all__ = [
    "OUTPUT_DEFAULTS",
    "Connection",
    "apply_inputs",
    "handle_message",
    "output_values",
    "runtime_state",
    "safety_status_bits",
]
