"""The lifter firmware model: every transition of §V.B.1 / Fig. 41 on a stepped clock, the watchdog
at exactly twice the command period, limit switches per motor and direction, and injected faults.

Requests go in as protocol bytes through ``receive`` (the path the real driver uses), so the state
machine and the firmware's side of the codec are tested together.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tlt_sim.emulators.lifter_firmware import Button, FirmwareConfig, LifterFirmware

from tlt_drivers.lifter.protocol import (
    FirmwareState,
    FrameDecoder,
    Mode,
    ModeReply,
    ModeRequest,
    ModeResult,
    StateRequest,
    StateTelemetry,
    VelocityCommand,
    decode_message,
)

S = FirmwareState
PERIOD = 0.02
CONFIG = FirmwareConfig(
    command_period_s=PERIOD,
    init_duration_s=0.1,
    button_max_speed_counts_s=1000,
    max_velocity_counts_s=5000,
    lower_limit_counts=(0, 0, 0, 0),
    upper_limit_counts=(10_000, 10_000, 10_000, 10_000),
    initial_positions_counts=(5000, 5000, 5000, 5000),
)
UPPER = [0, 1, 2, 3]
LOWER = [4, 5, 6, 7]


def send(fw: LifterFirmware, message) -> list:
    decoder = FrameDecoder()
    return [decode_message(f) for f in decoder.feed(fw.receive(message.encode(1)))]


def request(fw: LifterFirmware, mode: int) -> ModeReply:
    (reply,) = send(fw, ModeRequest(mode))
    assert isinstance(reply, ModeReply)
    return reply


def command(fw: LifterFirmware, velocities) -> StateTelemetry:
    (reply,) = send(fw, VelocityCommand(tuple(velocities)))
    return reply


def firmware_in(state: FirmwareState) -> LifterFirmware:
    fw = LifterFirmware(CONFIG)
    if state == S.INITIALIZING:
        return fw
    fw.step(CONFIG.init_duration_s)
    assert fw.state == S.HARDWARE_CONTROL
    if state == S.CRS_CONTROL:
        assert request(fw, Mode.CRS_CONTROL).accepted
    elif state == S.SAFE:
        assert request(fw, Mode.SAFE).accepted
    assert fw.state == state
    return fw


# --- Initializing ------------------------------------------


def test_initializing_enters_hardware_control_when_done() -> None:
    fw = LifterFirmware(CONFIG)
    assert fw.state == S.INITIALIZING
    fw.step(CONFIG.init_duration_s - 1e-6)
    assert fw.state == S.INITIALIZING
    fw.step(2e-6)
    assert fw.state == S.HARDWARE_CONTROL
    assert fw.transitions[-1].reason == "initialization finished"


@pytest.mark.parametrize("mode", [Mode.HARDWARE_CONTROL, Mode.CRS_CONTROL])
def test_control_modes_are_refused_while_initializing(mode) -> None:
    fw = firmware_in(S.INITIALIZING)
    reply = request(fw, mode)
    assert reply.result == ModeResult.REFUSED_INITIALIZING
    assert fw.state == S.INITIALIZING


def test_buttons_do_nothing_while_initializing() -> None:
    fw = firmware_in(S.INITIALIZING)
    fw.press(Button.ALL_CW)
    fw.step(0.05)
    assert fw.velocities == [0, 0, 0, 0]


# --- the transition table ------------------------------------------

# (start, event, resulting state, mode-request result or None)
TRANSITIONS = [
    (S.INITIALIZING, "request safe", S.SAFE, ModeResult.ACCEPTED),
    (S.HARDWARE_CONTROL, "request crs", S.CRS_CONTROL, ModeResult.ACCEPTED),
    (S.HARDWARE_CONTROL, "request crs with button", S.HARDWARE_CONTROL, ModeResult.REFUSED_BUTTON_PRESSED),
    (S.HARDWARE_CONTROL, "request safe", S.SAFE, ModeResult.ACCEPTED),
    (S.HARDWARE_CONTROL, "request hardware", S.HARDWARE_CONTROL, ModeResult.ACCEPTED),
    (S.CRS_CONTROL, "press button", S.HARDWARE_CONTROL, None),
    (S.CRS_CONTROL, "request hardware", S.HARDWARE_CONTROL, ModeResult.ACCEPTED),
    (S.CRS_CONTROL, "request safe", S.SAFE, ModeResult.ACCEPTED),
    (S.CRS_CONTROL, "request crs", S.CRS_CONTROL, ModeResult.ACCEPTED),
    (S.SAFE, "request hardware", S.HARDWARE_CONTROL, ModeResult.ACCEPTED),
    (S.SAFE, "request crs", S.CRS_CONTROL, ModeResult.ACCEPTED),
    (S.SAFE, "request crs with button", S.SAFE, ModeResult.REFUSED_BUTTON_PRESSED),
    (S.SAFE, "request safe", S.SAFE, ModeResult.ACCEPTED),
    (S.SAFE, "press button", S.SAFE, None),
    (S.HARDWARE_CONTROL, "request unknown", S.HARDWARE_CONTROL, ModeResult.REFUSED_UNKNOWN_MODE),
]


@pytest.mark.parametrize(("start", "event", "expected", "result"), TRANSITIONS)
def test_transition_table(start, event, expected, result) -> None:
    fw = firmware_in(start)
    reply = None
    if event == "press button":
        fw.press(Button.MOTOR1_CCW)
        fw.step(0.001)
    elif event == "request crs with button":
        fw.press(Button.MOTOR0_CW)
        reply = request(fw, Mode.CRS_CONTROL)
    else:
        mode = {"request safe": 3, "request crs": 2, "request hardware": 1, "request unknown": 7}[
            event.removesuffix(" with button")
        ]
        reply = request(fw, mode)
    assert fw.state == expected
    if result is not None:
        assert reply.result == result
        assert reply.state == expected
    # the firmware reports the same state in its telemetry
    (tel,) = send(fw, StateRequest())
    assert tel.state == expected


# --- Hardware Control: push buttons ------------------------------------------


def test_button_drives_its_motor_at_potentiometer_speed() -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    fw.set_potentiometer(0.25)
    fw.press(Button.MOTOR2_CW)
    assert fw.velocities == [0, 0, 250, 0]
    fw.step(0.2)
    assert fw.encoder_counts() == (5000, 5000, 5050, 5000)
    fw.set_potentiometer(1.0)
    assert fw.velocities == [0, 0, 1000, 0]
    fw.release(Button.MOTOR2_CW)
    fw.press(Button.MOTOR0_CCW)
    assert fw.velocities == [-1000, 0, 0, 0]


def test_all_buttons_drive_every_motor() -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    fw.set_potentiometer(0.5)
    fw.press(Button.ALL_CCW)
    assert fw.velocities == [-500] * 4
    fw.release_all()
    fw.press(Button.ALL_CW)
    assert fw.velocities == [500] * 4


def test_opposite_buttons_on_one_motor_stand_still() -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    fw.set_potentiometer(1.0)
    fw.press(Button.ALL_CW)
    fw.press(Button.MOTOR3_CCW)
    assert fw.velocities == [1000, 1000, 1000, 0]


@pytest.mark.parametrize("motor", range(4))
def test_button_blocked_only_by_the_switch_in_its_direction(motor) -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    fw.set_potentiometer(1.0)
    fw.force_switch(UPPER[motor], True)
    fw.press(Button.ALL_CW)
    expected = [1000] * 4
    expected[motor] = 0
    assert fw.velocities == expected
    fw.release_all()
    fw.press(Button.for_motor(motor, -1))  # away from the pressed upper switch: allowed
    assert fw.velocities[motor] == -1000
    fw.release_all()
    fw.release_switch(UPPER[motor])
    fw.force_switch(LOWER[motor], True)
    fw.press(Button.for_motor(motor, -1))
    assert fw.velocities[motor] == 0
    fw.release_all()
    fw.press(Button.for_motor(motor, +1))
    assert fw.velocities[motor] == 1000


def test_velocity_commands_are_ignored_in_hardware_control() -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    tel = command(fw, [100, 100, 100, 100])
    assert tel.velocities == (0, 0, 0, 0)
    fw.step(0.1)
    assert fw.encoder_counts() == (5000,) * 4


# --- CRS Control ------------------------------------------


def test_velocity_commands_move_the_encoders() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    tel = command(fw, [1000, -2000, 0, 500])
    assert tel.velocities == (1000, -2000, 0, 500)
    for _ in range(5):
        fw.step(PERIOD)
        command(fw, [1000, -2000, 0, 500])
    assert fw.encoder_counts() == (5100, 4800, 5000, 5050)


def test_commands_are_clamped_to_the_firmware_maximum() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    assert command(fw, [99999, -99999, 0, 0]).velocities == (5000, -5000, 0, 0)


def test_button_press_in_crs_control_zeroes_velocities_and_returns_to_hardware_control() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    fw.set_potentiometer(0.0)  # so the held button itself does not move anything afterwards
    command(fw, [1000, 1000, 1000, 1000])
    fw.press(Button.MOTOR0_CW)
    assert fw.state == S.HARDWARE_CONTROL
    assert fw.commanded == [0, 0, 0, 0]
    assert fw.velocities == [0, 0, 0, 0]
    # later commands are ignored until the CRS asks for CRS Control again
    command(fw, [1000, 1000, 1000, 1000])
    assert fw.velocities == [0, 0, 0, 0]
    fw.release_all()
    assert request(fw, Mode.CRS_CONTROL).accepted


@pytest.mark.parametrize("motor", range(4))
def test_crs_velocity_blocked_only_by_the_switch_in_its_direction(motor) -> None:
    fw = firmware_in(S.CRS_CONTROL)
    fw.force_switch(UPPER[motor], True)
    tel = command(fw, [700] * 4)
    expected = [700] * 4
    expected[motor] = 0
    assert list(tel.velocities) == expected
    assert command(fw, [-700] * 4).velocities == (-700,) * 4
    fw.release_switch(UPPER[motor])
    fw.force_switch(LOWER[motor], True)
    expected = [-700] * 4
    expected[motor] = 0
    assert list(command(fw, [-700] * 4).velocities) == expected
    assert command(fw, [700] * 4).velocities == (700,) * 4


def test_switches_assert_from_positions_and_stop_the_motor() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    for _ in range(200):  # 4 s at 2000 counts/s would pass the 10000 upper limit
        command(fw, [2000, -2000, 0, 0])
        fw.step(PERIOD)
    counts = fw.encoder_counts()
    assert 10_000 <= counts[0] <= 10_000 + 2000 * PERIOD
    assert -2000 * PERIOD <= counts[1] <= 0
    switches = fw.limit_switches()
    assert switches[UPPER[0]] and switches[LOWER[1]]
    assert not switches[UPPER[1]] and not switches[LOWER[0]]
    assert fw.velocities[:2] == [0, 0]


def test_encoders_written_together_decide_the_drive_as_one_by_one() -> None:
    """The twin writes all four carriage positions at once; the firmware ends where four single
    writes would leave it: the switches follow, and a motor on its switch stops."""
    together, apart = firmware_in(S.CRS_CONTROL), firmware_in(S.CRS_CONTROL)
    readings = [10_500.0, 4000.0, -10.0, 0.0]
    for fw in (together, apart):
        command(fw, [700, 700, -700, 700])
    together.set_positions(readings)
    for i, c in enumerate(readings):
        apart.set_position(i, c)
    assert together.positions == apart.positions == readings
    assert together.limit_switches() == apart.limit_switches()
    assert together.velocities == apart.velocities == [0, 700, 0, 700]
    with pytest.raises(ValueError, match="4 encoder readings"):
        together.set_positions([1.0, 2.0])


# --- the watchdog ------------------------------------------


@pytest.mark.parametrize("eps", [1e-6, 1e-4])
def test_watchdog_trips_at_exactly_twice_the_command_period(eps) -> None:
    fw = firmware_in(S.CRS_CONTROL)
    fw.step(0.005)
    command(fw, [1000, 1000, 1000, 1000])
    fw.step(2 * PERIOD - eps)
    assert not fw.watchdog_tripped
    assert fw.velocities == [1000] * 4
    fw.step(2 * eps)
    assert fw.watchdog_tripped
    assert fw.velocities == [0, 0, 0, 0]
    assert fw.state == S.CRS_CONTROL
    (tel,) = send(fw, StateRequest())
    assert tel.watchdog_tripped and tel.velocities == (0, 0, 0, 0)
    # a new command clears the trip and drives again
    tel = command(fw, [300, 300, 300, 300])
    assert not tel.watchdog_tripped and tel.velocities == (300,) * 4


def test_commands_every_period_keep_the_watchdog_quiet() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    for _ in range(100):
        command(fw, [100] * 4)
        fw.step(PERIOD * 1.9)
    assert fw.watchdog_trips == 0


def test_state_requests_do_not_feed_the_watchdog() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    command(fw, [100] * 4)
    for _ in range(5):
        fw.step(PERIOD)
        send(fw, StateRequest())
    assert fw.watchdog_tripped


# --- Safe ------------------------------------------


def test_safe_ignores_buttons_and_commands() -> None:
    fw = firmware_in(S.SAFE)
    fw.set_potentiometer(1.0)
    fw.press(Button.ALL_CW)
    assert command(fw, [1000] * 4).velocities == (0, 0, 0, 0)
    fw.step(0.5)
    assert fw.state == S.SAFE
    assert fw.encoder_counts() == (5000,) * 4


def test_safe_from_crs_control_stops_the_motors() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    command(fw, [1000] * 4)
    assert request(fw, Mode.SAFE).accepted
    assert fw.velocities == [0] * 4
    assert command(fw, [1000] * 4).velocities == (0,) * 4


# --- faults ------------------------------------------


def test_no_answer_fault_processes_but_does_not_reply() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    fw.faults.no_answer = True
    assert fw.receive(VelocityCommand((10, 10, 10, 10)).encode(1)) == b""
    assert fw.velocities == [10] * 4


def test_corrupted_replies_fail_the_crc() -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    fw.faults.corrupt_next = 2
    decoder = FrameDecoder()
    for _ in range(3):
        decoder.feed(fw.receive(StateRequest().encode(1)))
    assert decoder.stats.crc_errors == 2
    assert decoder.stats.frames == 1


def test_dropped_link_loses_bytes_for_its_duration() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    fw.drop_link(0.5)
    assert fw.receive(VelocityCommand((10, 10, 10, 10)).encode(1)) == b""
    assert fw.commanded == [0] * 4  # the command was lost, not queued
    fw.step(0.5)
    assert fw.receive(StateRequest().encode(2)) != b""


def test_garbage_on_the_line_is_survived() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    reply = fw.receive(b"\xa5\x5a\x01\x00\x10" + b"\x00" * 20 + VelocityCommand((1, 2, 3, 4)).encode(1))
    assert fw.commanded == [1, 2, 3, 4]
    assert FrameDecoder().feed(reply)
    assert fw.decoder.stats.crc_errors >= 1


def test_bad_inputs_are_refused() -> None:
    fw = firmware_in(S.HARDWARE_CONTROL)
    with pytest.raises(ValueError, match=r"0\.\.1"):
        fw.set_potentiometer(1.5)
    with pytest.raises(ValueError, match=r"0\.\.7"):
        fw.force_switch(8, True)
    with pytest.raises(ValueError, match="negative"):
        fw.step(-0.1)


# --- the interface the twin drives ---------------------------------------------------------------


def test_externally_owned_positions_drive_the_switches() -> None:
    fw = firmware_in(S.CRS_CONTROL)
    command(fw, [1000, 0, 0, 0])
    fw.step(0.01, integrate=False)
    assert fw.encoder_counts()[0] == 5000  # the twin owns the positions
    assert fw.velocities[0] == 1000
    fw.set_position(0, 10_000)  # the twin moved the carriage onto the upper switch
    assert fw.limit_switches()[UPPER[0]]
    assert fw.velocities[0] == 0
    assert command(fw, [1000, 0, 0, 0]).velocities == (0, 0, 0, 0)
    assert command(fw, [-1000, 0, 0, 0]).velocities == (-1000, 0, 0, 0)


# --- invariants under any sequence of events ---------------------------------------------------------

_EVENTS = st.one_of(
    st.tuples(st.just("press"), st.sampled_from(list(Button))),
    st.tuples(st.just("release"), st.sampled_from(list(Button))),
    st.tuples(st.just("mode"), st.sampled_from([1, 2, 3, 0])),
    st.tuples(st.just("command"), st.lists(st.integers(-6000, 6000), min_size=4, max_size=4)),
    st.tuples(st.just("switch"), st.tuples(st.integers(0, 7), st.sampled_from([True, False, None]))),
    st.tuples(st.just("pot"), st.floats(0.0, 1.0)),
    st.tuples(st.just("step"), st.floats(0.0, 0.1)),
)


@settings(max_examples=100, deadline=None)
@given(st.lists(_EVENTS, max_size=60))
def test_state_machine_invariants_hold_for_any_event_sequence(events) -> None:
    """Whatever happens: no motor drives into a pressed switch, Safe and Initializing stand still,
    CRS Control never coexists with a held button, Hardware Control moves only at the
    potentiometer speed, and CRS velocities are zero once the watchdog bound has passed."""
    fw = LifterFirmware(CONFIG)
    for kind, arg in events:
        if kind == "press":
            fw.press(arg)
        elif kind == "release":
            fw.release(arg)
        elif kind == "mode":
            request(fw, arg)
        elif kind == "command":
            command(fw, arg)
        elif kind == "switch":
            index, pressed = arg
            fw.release_switch(index) if pressed is None else fw.force_switch(index, pressed)
        elif kind == "pot":
            fw.set_potentiometer(arg)
        else:
            fw.step(arg)
        switches = fw.limit_switches()
        for i, v in enumerate(fw.velocities):
            assert not (v > 0 and switches[UPPER[i]]), (i, v)
            assert not (v < 0 and switches[LOWER[i]]), (i, v)
        if fw.state in (S.SAFE, S.INITIALIZING):
            assert fw.velocities == [0, 0, 0, 0]
        if fw.state == S.CRS_CONTROL:
            assert not fw.buttons
            if fw.time - fw.last_command_time > CONFIG.watchdog_timeout_s:
                assert fw.velocities == [0, 0, 0, 0]
        if fw.state == S.HARDWARE_CONTROL:
            speed = round(fw.potentiometer * CONFIG.button_max_speed_counts_s)
            assert all(abs(v) in (0, speed) for v in fw.velocities)
            if not fw.buttons:
                assert fw.velocities == [0, 0, 0, 0]
