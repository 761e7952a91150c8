"""The emulated MightyZAP chain speaks the IR protocol: checksum, feedback return modes, motion, overload."""

from __future__ import annotations

from tlt_sim.emulators.mightyzap_chain import (
    ERR_CHECKSUM,
    ERR_OVERLOAD,
    ERR_STROKE_LIMIT,
    MightyZapChain,
    checksum,
    frame,
)


def test_checksum_is_inverted_sum_of_id_size_command_and_factors():
    # Goal Position 2048 (0x0800) to id 1: FF FF FF 01 05 F3 86 00 08 -> ~(0x01+0x05+0xF3+0x86+0x00+0x08)
    packet = frame(1, 0xF3, bytes([0x86, 0x00, 0x08]))
    assert packet == bytes([0xFF, 0xFF, 0xFF, 0x01, 0x05, 0xF3, 0x86, 0x00, 0x08, 0x78])
    assert checksum(packet[3:-1]) == (~0x187) & 0xFF  # 0x187 = 391


def test_echo_always_answered_load_per_return_mode_store_only_in_mode_2():
    chain = MightyZapChain([1], clock=None)
    assert chain.handle(frame(1, 0xF1)) == frame(1, 0)
    reply = chain.handle(frame(1, 0xF2, bytes([0x10, 1])))
    assert reply == frame(1, 0, bytes([1]))  # return mode 1 answers reads
    assert chain.handle(frame(1, 0xF3, bytes([0x86, 0x00, 0x04]))) == b""
    chain.handle(frame(1, 0xF3, bytes([0x10, 2])))
    assert chain.handle(frame(1, 0xF3, bytes([0x86, 0x00, 0x04]))) == frame(1, 0)
    chain.handle(frame(1, 0xF3, bytes([0x10, 0])))
    assert chain.handle(frame(1, 0xF2, bytes([0x10, 1]))) == b""
    assert chain.handle(frame(1, 0xF1)) == frame(1, 0)


def test_goal_outside_stroke_limit_reports_error_bit():
    chain = MightyZapChain([1], clock=None)
    chain.handle(frame(1, 0xF3, bytes([0x10, 2])))
    chain.handle(frame(1, 0xF3, bytes([0x08, 0x00, 0x0A])))  # long stroke limit 2560
    assert chain.handle(frame(1, 0xF3, bytes([0x86, 0x00, 0x0B]))) == frame(1, ERR_STROKE_LIMIT)


def test_bad_checksum_answered_in_mode_2_ignored_otherwise():
    chain = MightyZapChain([1], clock=None)
    bad = bytearray(frame(1, 0xF2, bytes([0x8C, 2])))
    bad[-1] ^= 1
    assert chain.handle(bytes(bad)) == b""
    chain.handle(frame(1, 0xF3, bytes([0x10, 2])))
    assert chain.handle(bytes(bad)) == frame(1, ERR_CHECKSUM)


def test_symmetric_store_moves_two_actuators_with_force_on():
    chain = MightyZapChain([1, 2], clock=None)
    for act_id in (1, 2):
        chain.handle(frame(act_id, 0xF3, bytes([0x80, 1])))
    chain.handle(frame(0xFE, 0x73, bytes([0x86, 2, 1, 0x00, 0x08, 2, 0x00, 0x04])))
    chain.advance(2.0)
    assert chain.actuator(1).get(0x8C) == 2048 and chain.actuator(2).get(0x8C) == 1024


def test_blocked_rod_overloads_and_force_drops_until_restart():
    chain = MightyZapChain([1], clock=None)
    act = chain.actuator(1)
    act.set_obstacle(upper=1000)
    chain.handle(frame(1, 0xF3, bytes([0x80, 1])))
    chain.handle(frame(1, 0xF3, bytes([0x86, 0x00, 0x08])))
    chain.advance(1.5)
    assert act.get(0x8C) == 1000 and act.error & ERR_OVERLOAD and act.get(0x80) == 0
    assert chain.handle(frame(1, 0xF1))[5] & ERR_OVERLOAD
    chain.handle(frame(1, 0xF8))
    assert chain.handle(frame(1, 0xF1)) == frame(1, 0)
