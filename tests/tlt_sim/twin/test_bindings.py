"""Each emulator drives its model joints and the model's state comes back into the device.

The devices are driven the way their drivers drive them (control-table writes, firmware frames,
GPIO lines, UR motion commands); the bring-up test does the same through the real driver nodes.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest
from tlt_sim.emulators.dynamixel_servo import HW_OVERLOAD, DynamixelServo
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip
from tlt_sim.model import ik, names
from tlt_sim.model.scene import Scene
from tlt_sim.twin.bindings import ServoJointBinding, URArmBinding

from tlt_common import json_lines
from tlt_common.geometry.transforms import frame_from_axes
from tlt_drivers.gpio.config import CONFIG_DIR, load_gpio_config
from tlt_drivers.gpio.shared_memory import SharedMemoryLines
from tlt_drivers.lifter.protocol import FirmwareState, Mode, VelocityCommand

# MX-106(2.0) control table addresses the EE driver writes.
OPERATING_MODE, TORQUE, GOAL_CURRENT, GOAL_POSITION = 11, 64, 102, 116


def _write(servo, address: int, value: int, size: int) -> None:
    servo.write(address, int(value).to_bytes(size, "little", signed=True))


def _grasp_mode(servo, goal_ticks: int) -> None:
    _write(servo, TORQUE, 0, 1)
    _write(servo, OPERATING_MODE, 5, 1)  # current-based position, as config/hardware/ee_x.yaml
    _write(servo, GOAL_CURRENT, 357, 2)  # 1200 mA
    _write(servo, TORQUE, 1, 1)
    _write(servo, GOAL_POSITION, goal_ticks, 4)


def test_a_grasp_on_a_tube_shows_as_a_blocked_shaft_pressing_with_current(make_twin, caplog):
    caplog.set_level(logging.INFO, logger="tlt.twin")
    twin = make_twin()
    scene = twin.scene
    arm = "ars_x"
    part = next(p for p in scene.info.parts.values() if p.kind == "vertical")
    centre, axis = scene.assembly.grasp_line(arm)
    x = np.cross(axis, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-6 else np.array([1.0, 0.0, 0.0])
    rot = np.column_stack([x, np.cross(axis, x), axis])
    point, _ = part.grasps[0]
    scene.place_part(part.name, centre - rot @ point, rot)

    chain = twin.devices.chains["ee_x"]
    left, right = chain.servo(1), chain.servo(2)
    # 1.4 rad on each jaw: grasp_left turns positive, grasp_right (direction -1) negative.
    _grasp_mode(left, 2048 + round(1.4 * 4096 / (2 * np.pi)))
    _grasp_mode(right, 2048 - round(1.4 * 4096 / (2 * np.pi)))
    twin.run_for(1.5)

    assert scene.holding(arm) == part.body
    for servo, sign in ((left, 1), (right, -1)):
        jaw = sign * (servo.get("present_position") - 2048) * 2 * np.pi / 4096
        assert jaw == pytest.approx(scene.edu["end_effector"]["jaw_contact"], abs=0.03)
        current = servo.get("present_current")
        assert sign * current >= 0.9 * 357, "the jaw presses on the tube with its goal current"
    # Opening again frees the shaft: the jaw follows the servo back and the part is let go.
    _write(left, GOAL_POSITION, 2048, 4)
    _write(right, GOAL_POSITION, 2048, 4)
    twin.run_for(1.5)
    assert abs(left.get("present_position") - 2048) < 10
    assert scene.position(names.grasp_joint(arm, "a")) == pytest.approx(0.0, abs=0.02)
    assert scene.holding(arm) is None
    # The release is on the run's record, judged by the truth: let go of where it was grasped,
    # far from the tower, the strut was placed nowhere.
    (record,) = json_lines.read(twin.placements_path)
    assert (record["arm"], record["part"], record["member"]) == (arm, part.name, None)
    assert record["position_error_m"] > 0.05 and record["time"] > 1.5
    assert f"{arm} released {part.name} at no place" in caplog.text


def test_an_empty_close_is_not_blocked(make_twin):
    twin = make_twin()
    servo = twin.devices.chains["ee_y"].servo(1)
    _grasp_mode(servo, 2048 + round(1.2 * 4096 / (2 * np.pi)))
    twin.run_for(1.5)
    assert twin.scene.position(names.grasp_joint("ars_y", "a")) == pytest.approx(1.2, abs=0.02)
    assert abs(servo.get("present_current")) < 100


def test_lifter_firmware_velocities_move_the_carriages_and_encoders_read_them_back(make_twin):
    twin = make_twin(sync_period_s=0.01)  # ticks of 10 ms, as the commands below count
    fw = twin.devices.firmware
    start = twin.scene.position("lifter_joint_2")
    twin.run_for(0.6)  # past the firmware's initialisation
    assert fw.request_mode(Mode.CRS_CONTROL).name == "ACCEPTED"
    for _ in range(50):  # 0.5 s at 0.02 m/s, one command per 10 ms like a punctual driver
        fw.receive(VelocityCommand((0, 0, 4000, 0)).encode(1))
        twin.tick()
    moved = twin.scene.position("lifter_joint_2") - start
    assert moved == pytest.approx(0.01, abs=0.002)
    assert fw.encoder_counts()[2] == pytest.approx(twin.scene.position("lifter_joint_2") * 200000, abs=2)
    assert twin.scene.position("lifter_joint_0") == pytest.approx(start, abs=5e-4)  # it only sags
    # Without commands the watchdog stops the motor, in sim time.
    twin.run_for(0.2)
    assert fw.watchdog_tripped and fw.velocities[2] == 0
    assert fw.state == FirmwareState.CRS_CONTROL


def test_lower_limit_switch_follows_the_model_carriage(make_twin):
    twin = make_twin()
    fw = twin.devices.firmware
    twin.scene.set_joint_state("lifter_joint_1", 0.0)
    twin.tick()
    assert fw.limit_switches()[4 + 1] and not fw.limit_switches()[4 + 0]


def test_ee_limit_switch_input_and_rivet_gun_output_through_gpio(make_twin):
    twin = make_twin()
    gpio = load_gpio_config(CONFIG_DIR / "gpio_x.yaml")
    chip = EmulatedGpioChip(twin.run_dir / "gpio_x.state")
    lines = SharedMemoryLines(chip, gpio.lines)
    index = {spec.name: i for i, spec in enumerate(gpio.lines)}
    width = names.width_joint("ars_x")
    assert lines.get(index["limit_switch"]) is False  # the carriage starts 5 mm off the switch
    twin.scene.set_joint_state(width, 0.0)
    twin.tick()
    assert lines.get(index["limit_switch"]) is True
    # A pulse shorter than a sync period still fires the gun once.
    lines.set(index["rivet_gun_right"], True)
    lines.set(index["rivet_gun_right"], False)
    twin.tick()
    shots = twin.devices.gpio["ee_x"].shots
    assert [(side, outcome) for _, side, outcome in shots] == [("b", "dry shot")]
    chip.close()


def test_each_rivet_joint_goes_on_the_runs_record_with_its_true_outcome(make_twin, caplog):
    """The twin's truth of each joint (here the rivets of members that start built, one with an
    injected fault) is logged and appended to ``rivets.jsonl``, for judging a run."""
    from tlt_sim.model.config import REPO_ROOT
    from tlt_sim.model.scenario import parse_scenario

    from tlt_common.mission.schema import load_mission

    caplog.set_level(logging.INFO, logger="tlt.twin")
    mission = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")
    member = "bay1/vertical/x0_y0"
    raw = {
        "name": "proud",
        "built": ["bay1/cross_frame", member],
        "faults": {"rivet_faults": [{"member": member, "joint": "bay1/x0_y0", "kind": "proud_head"}]},
    }
    twin = make_twin(scenario=parse_scenario(raw, mission))
    twin.tick()
    records = json_lines.read(twin.rivets_path)
    assert [(r["member"], r["joint"], r["kind"], r["cause"]) for r in records] == [
        (member, "bay0/x0_y0", "good", "staged"),
        (member, "bay1/x0_y0", "proud_head", "injected"),
    ]
    assert f"rivet {member} at bay1/x0_y0: proud_head (injected: staged)" in caplog.text
    twin.tick()
    assert len(json_lines.read(twin.rivets_path)) == 2  # each outcome once


def test_a_rivet_gun_pushed_into_a_feeder_takes_one_rivet(make_twin):
    twin = make_twin()
    scene, binding = twin.scene, twin.devices.gpio["ee_x"]
    feeder = "rivet_dispenser_x"
    count = scene.dispenser_count(feeder)
    twin.tick()
    assert binding.loads == [] and not scene.rivet_loaded("ars_x", "a")
    pickup = scene.site_position(f"dispenser/{feeder}/pickup")
    tool = frame_from_axes([-1, 0, 0], [0, 0, -1])  # a heading with a clear way (tlt_sim.model.ik)
    # 8 cm short of the pickup (the gun on its way in) is not in; at the pickup it is.
    for depth, loaded in ((0.08, False), (0.0, True)):
        target = pickup - depth * tool[:, 2]
        q = ik.plan(scene.model, scene.data.qpos, "ars_x", target, tool, scene.ee_point("ars_x", "gun_a"))
        for i, value in enumerate(q[-1]):
            scene.set_joint_state(names.arm_joint("ars_x", i), float(value))
        twin.tick()
        twin.tick()  # a gun staying at the feeder takes no second rivet
        assert scene.rivet_loaded("ars_x", "a") is loaded
    assert [side for _, side in binding.loads] == ["a"]
    assert scene.dispenser_count(feeder) == count - 1


def test_the_width_carriage_stops_on_its_end_stop_and_the_servo_sees_it(make_twin):
    twin = make_twin()
    servo = twin.devices.chains["ee_x"].servo(3)
    _write(servo, TORQUE, 0, 1)
    _write(servo, OPERATING_MODE, 4, 1)  # extended position
    _write(servo, TORQUE, 1, 1)
    start = servo.get("present_position")
    _write(servo, GOAL_POSITION, start - 4096, 4)  # 20 mm towards the switch: 15 mm past it
    twin.run_for(1.0)
    width = twin.scene.position(names.width_joint("ars_x"))
    assert width == pytest.approx(0.0, abs=0.0005)
    assert servo.get("present_position") == pytest.approx(start - 0.005 / 0.02 * 4096, abs=15)


class Carriage:
    """A model joint as the scene moves it, in one dimension: towards its setpoint at its rated
    speed, unless something holds it (``held``)."""

    def __init__(self, max_velocity: float) -> None:
        self.q = self.v = self.target = 0.0
        self.vmax = max_velocity
        self.held = False

    def command_position(self, joint: str, position: float) -> None:
        self.target = position

    def position(self, joint: str) -> float:
        return self.q

    def velocity(self, joint: str) -> float:
        return self.v

    def max_velocity(self, joint: str) -> float:
        return self.vmax

    def advance(self, dt: float) -> None:
        step = 0.0 if self.held else float(np.clip(self.target - self.q, -self.vmax * dt, self.vmax * dt))
        self.q, self.v = self.q + step, step / dt


def test_a_carriage_held_for_a_moment_goes_on_at_the_servos_speed_without_an_overload():
    """The width carriage stopped for a moment while its servo drives it (a whole-system run saw it
    when its arm moved): once free it follows the shaft again. It used to be sent on to the goal
    at the model's rated speed, six times the servo's, while the servo, held, pressed at its
    current limit and tripped its overload within a second."""
    ticks_per_m = 4096 / 0.02  # the width lead screw: 20 mm a turn
    servo = DynamixelServo(3, position_ticks=0.0)
    _write(servo, TORQUE, 0, 1)
    _write(servo, OPERATING_MODE, 4, 1)  # extended position, as config/hardware/ee_x.yaml
    _write(servo, TORQUE, 1, 1)
    _write(servo, GOAL_POSITION, round(0.25 * ticks_per_m), 4)
    carriage = Carriage(max_velocity=0.1)  # config/twin/edu.yaml width_max_velocity
    binding = ServoJointBinding(
        "width",
        servo,
        lambda m: m * ticks_per_m,
        lambda t: t / ticks_per_m,
        lambda: float(servo.get("goal_position")),
        tolerance=0.002,
    )
    dt = 0.002

    def run(seconds: float) -> list[float]:
        positions = []
        for _ in range(round(seconds / dt)):
            servo.step(dt)
            binding.drive(carriage, dt)
            carriage.advance(dt)
            binding.sense(carriage, dt)
            positions.append(carriage.q)
        return positions

    free = run(1.0)
    servo_speed = (free[-1] - free[len(free) // 2]) / 0.5
    assert 0.005 < servo_speed < 0.05
    carriage.held = True
    run(0.3)
    assert binding.blocked == "upper", "the stall reads as an obstacle"
    carriage.held = False
    after = run(1.5)
    assert binding.blocked is None
    assert not servo.get("hardware_error_status") & HW_OVERLOAD
    speed = (after[-1] - after[len(after) // 3]) / 1.0
    assert speed == pytest.approx(servo_speed, rel=0.05), "the shaft drives the carriage again"
    assert abs(servo.get("present_current")) < 0.1 * servo.get("current_limit")


def test_ur_controller_motion_moves_the_model_arm(make_twin):
    twin = make_twin()
    twin.start()
    host = twin.devices.ur["ur_y"]
    q0 = host.positions()
    goal = [*q0[:5], q0[5] + 0.3]
    host.call("move_joints", goal, 1.0, 2.0)
    twin.run_for(1.5)
    # The controller's process steps its arm to the twin's sim time on its own schedule.
    deadline = time.monotonic() + 10.0
    while host.call("sim_time") < twin.scene.time - 1e-6 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert host.call("sim_time") == pytest.approx(twin.scene.time, abs=1e-6), "never runs ahead"
    assert host.positions()[5] == pytest.approx(goal[5], abs=1e-6)
    twin.run_for(0.5)
    assert twin.scene.position(names.arm_joint("ars_y", 5)) == pytest.approx(goal[5], abs=0.005)
    assert twin.scene.position(names.arm_joint("ars_y", 0)) == pytest.approx(q0[0], abs=0.005)


# ARS X's joints at a near vertical's placement in a build before the planner knew of the D405
# housings: housing a stands in the lifter post beside the strut.
HOUSING_IN_POST = [2.054, -0.644, 2.531, 1.254, -5.981, 1.571]
FREE = [0.965, -0.747, 1.142, 3.317, -1.922, -3.567]


@pytest.mark.parametrize(("q", "pushed"), [(HOUSING_IN_POST, True), (FREE, False)])
def test_an_arm_held_off_its_commanded_joints_is_logged_with_what_it_touches(tmp_path, caplog, q, pushed):
    arm = "ars_x"
    joints = names.arm_joints(arm)
    with Scene(out_dir=tmp_path / "model") as scene:
        for joint, value in zip(joints, q, strict=True):
            scene.set_joint_state(joint, value)
        binding = URArmBinding(lambda: list(q), joints)
        with caplog.at_level(logging.WARNING, logger="tlt.twin"):
            for _ in range(50):  # 1 s at the twin's 20 ms sync period
                binding.drive(scene, 0.02)
                scene.advance(0.02)
                binding.sense(scene, 0.02)
    said = [r.getMessage() for r in caplog.records if "held off its commanded joints" in r.getMessage()]
    if pushed:
        assert len(said) == 1, said  # once per commanded pose
        assert "ars_x/d405_a/housing on lifter/post_0" in said[0], said
    else:
        assert said == []


def test_top_gripper_pins_start_engaged_and_follow_their_actuators(make_twin):
    twin = make_twin()
    act = twin.devices.chains["top_grippers"].actuator(3)
    assert act.position == pytest.approx(4095, abs=1)  # the payload hangs on the pins at start
    act.store(0x80, b"\x01")  # Force on
    act.store(0x86, (2000).to_bytes(2, "little"))
    twin.run_for(2.0)
    assert twin.scene.position("top_gripper_3") == pytest.approx(2000 / 4095 * 0.027, abs=3e-4)


def test_a_servo_reboot_changes_its_count_not_the_joint(make_twin):
    twin = make_twin()
    servo = twin.devices.chains["ee_x"].servo(3)  # the width lead screw, several turns from zero
    width = names.width_joint("ars_x")
    before_joint, before_count = twin.scene.position(width), servo.get("present_position")
    twin.tick()
    servo.reboot()  # what the driver's reboot after a hardware error does
    twin.run_for(0.3)
    assert servo.get("present_position") == before_count % 4096 != before_count
    assert twin.scene.position(width) == pytest.approx(before_joint, abs=1e-4)
    # The shaft still drives the carriage from its new count.
    _write(servo, TORQUE, 0, 1)
    _write(servo, OPERATING_MODE, 4, 1)
    _write(servo, TORQUE, 1, 1)
    _write(servo, GOAL_POSITION, before_count % 4096 + 1024, 4)  # a quarter turn: +5 mm
    twin.run_for(1.0)
    assert twin.scene.position(width) == pytest.approx(before_joint + 0.005, abs=3e-4)
