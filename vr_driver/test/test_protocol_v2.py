"""Protocol v2 records (vr_driver.protocol.v2): golden bytes, round trips, resolution over the full
joint ranges, the CRC catching every corruption of a record, and the rules a record must obey."""
from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vr_driver.errors import PoseError, ProtocolError
from vr_driver.protocol.v1 import StatusBits
from vr_driver.protocol.v2 import (EMPTY, RECORD_SIZE_V2, SEQ_MAX, CommandV2, Control, FeedbackV2,
                                   RejectCode, StreamState, TargetKind, TargetSlot, crc16,
                                   joints_from_wire, joints_to_wire, next_seq, seq_after)


def test_crc16_check_value():
    assert crc16(b"123456789") == 0x29B1          # CRC-16/CCITT-FALSE's published check value
    assert crc16(b"") == 0xFFFF


def test_golden_command_bytes():
    slot = TargetSlot(7, TargetKind.JOINT, 3, 500, (1000, -2000, 3000, -360000, 0, 359999))
    raw = CommandV2(Control.START, slot).encode()
    assert len(raw) == RECORD_SIZE_V2 == 72
    assert raw[:4] == bytes([2, 2, 0, 0])                                  # version, START, reserved
    assert raw[4:12] == bytes([7, 0, 1, 3]) + struct.pack("<H", 500) + bytes(2)
    assert raw[12:36] == struct.pack("<6i", 1000, -2000, 3000, -360000, 0, 359999)
    assert raw[36:68] == bytes(32) and raw[68:70] == bytes(2)                # empty slot 1, reserved
    assert raw[70:] == struct.pack("<H", crc16(raw[:70]))
    assert CommandV2.decode(raw) == CommandV2(Control.START, slot)


def test_golden_feedback_bytes():
    fb = FeedbackV2(StreamState.MOVING, StatusBits.DRIVES_POWERED | StatusBits.IN_MOTION |
                    StatusBits.PROGRAM_RUNNING, RejectCode.NONE, 12, 10, 11, 0,
                    (1, 2, 3, 4, 5, 6), (112000, 0, 72500, 0, 45000, 0), 65535)
    raw = fb.encode()
    assert raw[:4] == bytes([2, 1, 0x19, 0])
    assert raw[4:12] == struct.pack("<4H", 12, 10, 11, 0)
    assert raw[12:36] == struct.pack("<6i", 1, 2, 3, 4, 5, 6)
    assert raw[36:60] == struct.pack("<6i", 112000, 0, 72500, 0, 45000, 0)
    assert raw[60:62] == b"\xff\xff" and raw[62:70] == bytes(8)
    assert FeedbackV2.decode(raw) == fb


@settings(max_examples=200, deadline=None)
@given(seq=st.integers(1, SEQ_MAX), smooth=st.integers(0, 10), speed=st.integers(1, 1000),
       joints=st.lists(st.integers(-(2 ** 31), 2 ** 31 - 1), min_size=6, max_size=6),
       stop=st.booleans())
def test_command_round_trip(seq, smooth, speed, joints, stop):
    slot0 = TargetSlot(seq, TargetKind.JOINT, smooth, speed, tuple(joints))
    slot1 = TargetSlot(next_seq(seq), TargetKind.JOINT, 0, speed, tuple(reversed(joints)))
    cmd = CommandV2(Control(0), slot0, slot1) if not stop else CommandV2(Control.STOP)
    assert CommandV2.decode(cmd.encode()) == cmd


def test_every_single_byte_corruption_is_refused():
    """The CRC-16 catches every corruption of one byte, anywhere in the record (the 8-bit PROFIBUS
    checksum lets about 1.7e-4 of corrupted telegrams through)."""
    slot = TargetSlot.joint_target(5, (0.1, -0.2, 0.3, 1.0, -1.5, 6.2), 0.5, smooth=2)
    for raw in (CommandV2(Control(0), slot).encode(),
                FeedbackV2(StreamState.IDLE, StatusBits.PROGRAM_RUNNING, accepted_seq=5).encode()):
        decode = CommandV2.decode if raw[4] == 5 else FeedbackV2.decode
        for i in range(1, RECORD_SIZE_V2):          # byte 0 is the version: its own message
            for flip in (0x01, 0x80, 0xFF):
                bad = bytearray(raw)
                bad[i] ^= flip
                with pytest.raises(ProtocolError):
                    decode(bytes(bad))


def test_joint_resolution_over_the_full_ranges():
    """0.001 deg over every joint range (J6 is +-360 deg = +-6.28 rad), rounding error <= 0.0005 deg."""
    for q in (-6.28, -4.712, -math.pi, -0.123456789, 0.0, 1e-7, 2.618, 4.712, 6.28):
        wire = joints_to_wire([q] * 6)
        back = joints_from_wire(wire)
        assert all(abs(math.degrees(b - q)) <= 0.0005 + 1e-12 for b in back)
    assert joints_to_wire([math.radians(360.0)] * 6)[0] == 360000
    assert joints_to_wire([math.radians(-0.0005)] + [0.0] * 5)[0] == -1      # halves away from 0


@pytest.mark.parametrize("joints, words", [
    ([0.0] * 5, "6 angles"),
    ([0.0] * 5 + [float("nan")], "joint_6 must be a finite number"),
    ([float("inf")] + [0.0] * 5, "joint_1 must be a finite number"),
    ([1e30] + [0.0] * 5, r"joint_1 = 1e\+30 rad does not fit"),
    ([True] + [0.0] * 5, "joint_1"),
])
def test_bad_joint_values_are_refused_naming_the_joint(joints, words):
    with pytest.raises(PoseError, match=words):
        joints_to_wire(joints)


def test_speed_is_rounded_up_never_slower_than_planned():
    assert TargetSlot.joint_target(1, [0.0] * 6, 0.5).speed == 500
    assert TargetSlot.joint_target(1, [0.0] * 6, 0.5001).speed == 501
    assert TargetSlot.joint_target(1, [0.0] * 6, 1e-6).speed == 1
    assert TargetSlot.joint_target(1, [0.0] * 6, 1.0).speed == 1000
    for bad in (0.0, -0.1, 1.01, float("nan")):
        with pytest.raises(ProtocolError):
            TargetSlot.joint_target(1, [0.0] * 6, bad)


@pytest.mark.parametrize("make, words", [
    (lambda: CommandV2(Control(0), EMPTY, TargetSlot.joint_target(2, [0.0] * 6, 0.5)), "without slot 0"),
    (lambda: CommandV2(Control(0), TargetSlot.joint_target(2, [0.0] * 6, 0.5),
                       TargetSlot.joint_target(4, [0.0] * 6, 0.5)), "after slot 0"),
    (lambda: CommandV2(Control.START), "START needs a target"),
    (lambda: CommandV2(Control.STOP, TargetSlot.joint_target(1, [0.0] * 6, 0.5)), "STOP carries no"),
    (lambda: CommandV2(8), "only STOP"),
    (lambda: TargetSlot(1, TargetKind.JOINT, 11, 500), "smooth"),
    (lambda: TargetSlot(1, TargetKind.JOINT, 0, 1001), "speed"),
    (lambda: TargetSlot(1, TargetKind.NONE, 0, 100), "no kind"),
    (lambda: TargetSlot(0, TargetKind.JOINT, 0, 100), "empty slot"),
    (lambda: TargetSlot(SEQ_MAX + 1, TargetKind.JOINT, 0, 100), "seq"),
])
def test_malformed_records_are_refused(make, words):
    with pytest.raises(ProtocolError, match=words):
        make()


def test_a_v1_record_or_the_wrong_version_is_refused_with_a_hint():
    with pytest.raises(ProtocolError, match="72 bytes"):
        CommandV2.decode(bytes(14))
    raw = bytearray(CommandV2().encode())
    raw[0] = 1
    with pytest.raises(ProtocolError, match="protocol v1"):
        CommandV2.decode(bytes(raw))


def test_sequence_numbers_wrap_past_zero():
    assert next_seq(0) == 1 and next_seq(41) == 42 and next_seq(SEQ_MAX) == 1
    assert seq_after(1, SEQ_MAX) and seq_after(42, 41) and not seq_after(41, 42)
    assert seq_after(5, 0) and not seq_after(0, 5)
    slot0 = TargetSlot.joint_target(SEQ_MAX, [0.0] * 6, 0.2)
    slot1 = TargetSlot.joint_target(1, [0.0] * 6, 0.2)
    assert CommandV2.decode(CommandV2(Control(0), slot0, slot1).encode()).slot1.seq == 1


def test_feedback_refuses_reserved_status_bits():
    with pytest.raises(ProtocolError, match="reserved status"):
        FeedbackV2(status=0x40)


def test_the_armed_flag_is_byte_67_bit_0():
    raw = FeedbackV2(armed=True).encode()
    assert raw[66] == 0x01 and raw[67:70] == bytes(3)
    assert FeedbackV2.decode(raw).armed is True
    assert FeedbackV2.decode(FeedbackV2().encode()).armed is False
    assert "not armed" in FeedbackV2().describe() and "not armed" not in FeedbackV2(armed=True).describe()
    # another flag bit set (with a valid CRC): refused, as the reserved bytes
    body = bytearray(raw[:70])
    body[66] = 0x03
    with pytest.raises(ProtocolError, match="reserved flag"):
        FeedbackV2.decode(bytes(body) + struct.pack("<H", crc16(bytes(body))))
    with pytest.raises(ProtocolError, match="armed"):
        FeedbackV2(armed=1)


def test_controller_io_words_on_the_wire():
    from vr_driver.protocol.v2 import CommandV2, FeedbackV2
    raw = CommandV2(outputs=0xA501).encode()
    assert raw[68:70] == bytes([0x01, 0xA5])                             # bytes 69-70: outputs 1..16
    assert CommandV2.decode(raw).outputs == 0xA501
    fb = FeedbackV2(inputs=0x0102, outputs=0x8001).encode()
    assert fb[62:64] == bytes([0x02, 0x01]) and fb[64:66] == bytes([0x01, 0x80]) and fb[66:70] == bytes(4)
    back = FeedbackV2.decode(fb)
    assert (back.inputs, back.outputs) == (0x0102, 0x8001)
    for bad in (-1, 0x10000, True, 1.0):
        with pytest.raises(ProtocolError, match="outputs"):
            CommandV2(outputs=bad)
        with pytest.raises(ProtocolError, match="inputs"):
            FeedbackV2(inputs=bad)
