"""ur-rtde's register command protocol executed by the emulated control script, tick by tick."""

from __future__ import annotations

import pytest
from tlt_sim.emulators.ur_arm import HOME, UR10eArm
from tlt_sim.emulators.ur_control_script import DONE, READY, ControlScript, Registers

DT = 0.002


def setup(offset: int = 0):
    arm = UR10eArm(HOME)
    reg = Registers()
    stops: list[str] = []
    return arm, reg, ControlScript(arm, reg, offset=offset, on_protective_stop=stops.append), stops


def command(reg: Registers, code: int, *, ints=(), doubles=(), offset: int = 0) -> None:
    reg.in_int[offset] = code
    for i, v in enumerate(ints, start=1):
        reg.in_int[offset + i] = v
    for i, v in enumerate(doubles):
        reg.in_double[offset + i] = v


def tick(arm: UR10eArm, script: ControlScript, n: int = 1) -> None:
    for _ in range(n):
        arm.step(DT)
        script.tick()


def test_synchronous_movej_answers_done_only_when_the_arm_arrives() -> None:
    arm, reg, script, _ = setup()
    assert reg.out_int[0] == READY
    target = list(HOME)
    target[0] += 0.2
    command(reg, 1, ints=(0,), doubles=(*target, 1.0, 4.0))
    tick(arm, script)
    assert reg.out_int[0] == READY and arm.moving  # still executing
    tick(arm, script, 300)
    assert not arm.moving and reg.out_int[0] == DONE
    command(reg, 0)
    tick(arm, script)
    assert reg.out_int[0] == READY
    assert arm.positions() == pytest.approx(target)


def test_asynchronous_movej_is_done_at_once_and_reports_progress() -> None:
    arm, reg, script, _ = setup()
    target = list(HOME)
    target[5] += 1.0
    command(reg, 1, ints=(1,), doubles=(*target, 1.0, 2.0))
    tick(arm, script)
    assert reg.out_int[0] == DONE
    assert reg.out_int[2] & 0x8000  # running bit of the progress word
    command(reg, 0)
    tick(arm, script, 1000)
    assert not arm.moving
    assert not reg.out_int[2] & 0x8000


def test_servoj_is_streamed_without_the_done_handshake() -> None:
    arm, reg, script, _ = setup()
    target = list(HOME)
    target[2] += 0.05
    command(reg, 11, doubles=(*target, 0.0, 0.0, 0.008, 0.03, 2000))
    tick(arm, script, 100)
    assert reg.out_int[0] == READY
    assert arm.positions() == pytest.approx(target, abs=1e-3)


def test_stopj_waits_until_the_arm_is_at_rest() -> None:
    arm, reg, script, _ = setup()
    command(reg, 9, doubles=(0.5, 0, 0, 0, 0, 0, 5.0, 0.0))  # speedJ
    tick(arm, script, 200)
    command(reg, 0)
    tick(arm, script)
    command(reg, 34, ints=(0,), doubles=(2.0,))  # stopJ, synchronous
    tick(arm, script)
    assert reg.out_int[0] == READY and arm.moving
    tick(arm, script, 200)
    assert reg.out_int[0] == DONE and not arm.moving


def test_stop_script_ends_the_program() -> None:
    arm, reg, script, _ = setup()
    command(reg, 255)
    tick(arm, script)
    assert not script.running


def test_protective_stop_command_reaches_the_controller() -> None:
    arm, reg, script, stops = setup()
    command(reg, 31)
    tick(arm, script)
    assert stops and "protective_stop" in stops[0]


def test_unimplemented_command_stops_the_program_instead_of_succeeding() -> None:
    arm, reg, script, _ = setup()
    command(reg, 6)  # forceMode
    tick(arm, script)
    assert not script.running and "not implemented" in script.error
    assert reg.out_int[0] != DONE


def test_kinematics_commands_use_the_output_registers() -> None:
    arm, reg, script, _ = setup()
    command(reg, 43)  # forward kinematics of the actual joints
    tick(arm, script)
    assert reg.out_double[:6] == pytest.approx(arm.tcp_pose())
    command(reg, 0)
    tick(arm, script)
    command(reg, 46, doubles=tuple(arm.tcp_pose()))  # inverse, nearest the actual joints
    tick(arm, script)
    assert reg.out_double[:6] == pytest.approx(list(HOME), abs=1e-6)


def test_upper_register_range_offset() -> None:
    arm, reg, script, _ = setup(offset=24)
    assert reg.out_int[24] == READY and reg.out_int[0] == 0
    target = list(HOME)
    target[0] += 0.1
    command(reg, 1, ints=(1,), doubles=(*target, 1.0, 2.0), offset=24)
    tick(arm, script)
    assert reg.out_int[24] == DONE and arm.moving
