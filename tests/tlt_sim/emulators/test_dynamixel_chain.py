"""The emulated chain answers Protocol 2.0 packets as MX-106(2.0) servos do (bytes in, bytes out)."""

from __future__ import annotations

import struct

from tlt_sim.emulators import dynamixel_protocol as proto
from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.emulators.dynamixel_servo import HW_OVERLOAD, MODE_CURRENT_BASED_POSITION


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def statuses(data: bytes) -> list[proto.Packet]:
    return proto.PacketParser().feed(data)


def write(chain, dxl_id, address, fmt, value):
    return statuses(
        chain.handle(proto.build_packet(dxl_id, proto.WRITE, struct.pack("<H" + fmt, address, value)))
    )


def read(chain, dxl_id, address, length):
    (status,) = statuses(
        chain.handle(proto.build_packet(dxl_id, proto.READ, struct.pack("<HH", address, length)))
    )
    return status


def test_ping_answers_model_321_and_unknown_id_is_silent():
    chain = DynamixelChain([1, 2], clock=None)
    (status,) = statuses(chain.handle(proto.build_packet(2, proto.PING)))
    assert status.instruction == proto.STATUS and status.params == bytes([0]) + struct.pack("<HB", 321, 45)
    assert chain.handle(proto.build_packet(9, proto.PING)) == b""


def test_broadcast_ping_answers_in_id_order():
    chain = DynamixelChain([3, 1, 2], clock=None)
    assert [s.dxl_id for s in statuses(chain.handle(proto.build_packet(proto.BROADCAST_ID, proto.PING)))] == [
        1,
        2,
        3,
    ]


def test_eeprom_write_refused_while_torque_on():
    chain = DynamixelChain([1], clock=None)
    assert write(chain, 1, 11, "B", 4)[0].params[0] == 0
    assert write(chain, 1, 64, "B", 1)[0].params[0] == 0
    (status,) = write(chain, 1, 11, "B", 3)
    assert status.params[0] == proto.ERR_ACCESS
    assert chain.servo(1).get("operating_mode") == 4


def test_goal_moves_servo_with_clock_and_sync_read_reports_it():
    clock = FakeClock()
    chain = DynamixelChain([1, 2], clock=clock)
    write(chain, 1, 64, "B", 1)
    write(chain, 1, 116, "i", 3000)
    clock.t = 2.0
    packet = proto.build_packet(
        proto.BROADCAST_ID, proto.SYNC_READ, struct.pack("<HH", 132, 4) + bytes([1, 2])
    )
    replies = statuses(chain.handle(packet))
    assert [r.dxl_id for r in replies] == [1, 2]
    assert struct.unpack("<i", replies[0].params[1:])[0] == 3000
    assert struct.unpack("<i", replies[1].params[1:])[0] == 2048


def test_sync_write_sets_goals_without_status():
    chain = DynamixelChain([1, 2], clock=None)
    body = (
        struct.pack("<HH", 116, 4) + bytes([1]) + struct.pack("<i", 100) + bytes([2]) + struct.pack("<i", 200)
    )
    assert chain.handle(proto.build_packet(proto.BROADCAST_ID, proto.SYNC_WRITE, body)) == b""
    assert chain.servo(1).get("goal_position") == 100 and chain.servo(2).get("goal_position") == 200


def test_bad_crc_answered_with_crc_error():
    chain = DynamixelChain([1], clock=None)
    packet = bytearray(proto.build_packet(1, proto.PING))
    packet[-2] ^= 1
    (status,) = statuses(chain.handle(bytes(packet)))
    assert status.params[0] == proto.ERR_CRC


def test_hardware_error_sets_alert_bit_removes_torque_and_reboot_clears():
    chain = DynamixelChain([1], clock=None)
    write(chain, 1, 64, "B", 1)
    chain.servo(1).inject_hardware_error(HW_OVERLOAD)
    status = read(chain, 1, 70, 1)
    assert status.params[0] & proto.ERR_ALERT and status.params[1] == HW_OVERLOAD
    assert read(chain, 1, 64, 1).params[1] == 0
    assert write(chain, 1, 64, "B", 1)[0].params[0] & 0x7F == proto.ERR_RESULT_FAIL
    chain.handle(proto.build_packet(1, proto.REBOOT))
    chain.advance(0.1)
    assert read(chain, 1, 70, 1).params == bytes([0, 0])


def test_obstacle_shows_as_load_and_sustained_stall_overloads():
    chain = DynamixelChain([1], clock=None)
    servo = chain.servo(1)
    servo.set_obstacle(upper=2200)
    write(chain, 1, 64, "B", 1)
    write(chain, 1, 116, "i", 3500)
    chain.advance(0.5)
    assert round(servo.position) == 2200
    assert servo.get("present_current") >= 0.95 * servo.get("current_limit")
    chain.advance(1.0)
    assert servo.get("hardware_error_status") & HW_OVERLOAD and servo.get("torque_enable") == 0


def test_current_based_position_grasp_holds_without_overload():
    chain = DynamixelChain([1], clock=None)
    servo = chain.servo(1)
    write(chain, 1, 11, "B", MODE_CURRENT_BASED_POSITION)
    write(chain, 1, 102, "h", 300)
    servo.set_obstacle(upper=2300)
    write(chain, 1, 64, "B", 1)
    write(chain, 1, 116, "i", 3000)
    chain.advance(3.0)
    assert servo.get("present_current") == 300 and servo.get("hardware_error_status") == 0


def test_silenced_servo_and_dropped_link_do_not_answer():
    chain = DynamixelChain([1, 2], clock=None)
    chain.silence(1)
    assert chain.handle(proto.build_packet(1, proto.PING)) == b""
    assert statuses(chain.handle(proto.build_packet(2, proto.PING)))
    chain.drop_link()
    assert chain.handle(proto.build_packet(2, proto.PING)) == b""
    chain.drop_link(False)
    chain.silence(1, False)
    assert statuses(chain.handle(proto.build_packet(1, proto.PING)))


def test_corrupt_next_breaks_crc_of_replies():
    chain = DynamixelChain([1], clock=None)
    chain.corrupt_next(1)
    (bad,) = statuses(chain.handle(proto.build_packet(1, proto.PING)))
    (good,) = statuses(chain.handle(proto.build_packet(1, proto.PING)))
    assert not bad.crc_ok and good.crc_ok


def test_reboot_loses_multi_turn_count():
    chain = DynamixelChain([1], clock=None)
    write(chain, 1, 11, "B", 4)
    write(chain, 1, 64, "B", 1)
    write(chain, 1, 116, "i", 4096 * 3 + 100)
    chain.advance(5.0)
    assert chain.servo(1).get("present_position") == 4096 * 3 + 100
    chain.handle(proto.build_packet(1, proto.REBOOT))
    assert chain.servo(1).get("present_position") == 100


def test_served_on_a_pty():
    import os
    import select

    with DynamixelChain([1], clock=None) as chain:
        fd = os.open(chain.port, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, proto.build_packet(1, proto.PING))
            data = b""
            while len(data) < 14:
                ready, _, _ = select.select([fd], [], [], 2.0)
                assert ready, "no answer on the pty"
                data += os.read(fd, 64)
            assert statuses(data)[0].dxl_id == 1
        finally:
            os.close(fd)


def test_reg_write_applies_on_broadcast_action():
    chain = DynamixelChain([1, 2], clock=None)
    for dxl_id in (1, 2):
        params = struct.pack("<Hi", 116, 1000 * dxl_id)
        (status,) = statuses(chain.handle(proto.build_packet(dxl_id, proto.REG_WRITE, params)))
        assert status.params[0] == 0
    assert chain.servo(1).get("goal_position") == 2048
    assert chain.handle(proto.build_packet(proto.BROADCAST_ID, proto.ACTION)) == b""
    assert [chain.servo(i).get("goal_position") for i in (1, 2)] == [1000, 2000]


def test_bulk_read_and_bulk_write_address_each_servo_differently():
    chain = DynamixelChain([1, 2], clock=None)
    body = struct.pack("<BHHB", 1, 64, 1, 1) + struct.pack("<BHHi", 2, 116, 4, 777)
    assert chain.handle(proto.build_packet(proto.BROADCAST_ID, proto.BULK_WRITE, body)) == b""
    assert chain.servo(1).get("torque_enable") == 1 and chain.servo(2).get("goal_position") == 777
    ask = struct.pack("<BHH", 1, 0, 2) + struct.pack("<BHH", 2, 116, 4)
    replies = statuses(chain.handle(proto.build_packet(proto.BROADCAST_ID, proto.BULK_READ, ask)))
    assert [(r.dxl_id, r.params[1:]) for r in replies] == [
        (1, struct.pack("<H", 321)),
        (2, struct.pack("<i", 777)),
    ]


def test_status_return_level_1_answers_reads_only():
    chain = DynamixelChain([1], clock=None)
    write(chain, 1, 68, "B", 1)
    assert chain.handle(proto.build_packet(1, proto.WRITE, struct.pack("<HB", 65, 1))) == b""
    assert read(chain, 1, 65, 1).params == bytes([0, 1])
