"""vr_driver.protocol.v1: the 14-byte records of doc/controller_program.md and both sides of the request handshake."""
from __future__ import annotations

import math
import random
from collections import deque

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vr_driver.errors import (HandshakeError, HandshakeTimeout, PoseError, ProtocolError, TargetRejected,
                              VrDriverError)
from vr_driver.kinematics.preview import MoveType
from vr_driver.poses import HOME_POSE, ControllerPose, Workspace
from vr_driver.protocol.v1 import (RECORD_SIZE, Aborted, Accepted, ByteOrder, Command, ControllerHandshake,
                                ControllerState, Done, Feedback, MasterHandshake, MasterPhase, Rejected,
                                StatusBits, TimedOut, WireMoveType, commands_for, parse_byte_order,
                                round_half_away, to_wire_int)

READY, BUSY, DONE, REJECTED = (ControllerState.READY, ControllerState.BUSY, ControllerState.DONE,
                               ControllerState.REJECTED)
FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def fb(state, status=0, pose=(1120, 0, 725, 0, 45, 0)):
    return Feedback(*pose, state=state, status=status)


def target(n=0, kind=WireMoveType.PTP):
    return Command(1000 + n, -n, 700, 0, 45, 0, True, kind)


class FakeClock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


# ============================================================================================ records

# 1120 = 0x0460, 725 = 0x02D5, 45 = 0x002D
HOME_LIN_LITTLE = "6004" "0000" "d502" "0000" "2d00" "0000" "01" "02"
HOME_LIN_BIG = "0460" "0000" "02d5" "0000" "002d" "0000" "01" "02"
# -1 = 0xFFFF, -900 = 0xFC7C, 32767 = 0x7FFF, -32768 = 0x8000, -180 = 0xFF4C, 180 = 0x00B4
EDGE_LITTLE = "ffff" "7cfc" "ff7f" "0080" "4cff" "b400" "00" "04"
EDGE_BIG = "ffff" "fc7c" "7fff" "8000" "ff4c" "00b4" "00" "04"
# -300 = 0xFED4, -90 = 0xFFA6, 179 = 0x00B3; status 0x19 = drives powered | in motion | program running
FEEDBACK_LITTLE = "6004" "d4fe" "d502" "a6ff" "2d00" "b300" "01" "19"
FEEDBACK_BIG = "0460" "fed4" "02d5" "ffa6" "002d" "00b3" "01" "19"

HOME_LIN = Command(1120, 0, 725, 0, 45, 0, True, WireMoveType.LIN)
EDGE = Command(-1, -900, 32767, -32768, -180, 180, False, WireMoveType.CIRC_VIA)
FEEDBACK = Feedback(1120, -300, 725, -90, 45, 179, BUSY,
                    StatusBits.DRIVES_POWERED | StatusBits.IN_MOTION | StatusBits.PROGRAM_RUNNING)


@pytest.mark.parametrize("record, order, hexstr", [
    (HOME_LIN, "little", HOME_LIN_LITTLE), (HOME_LIN, "big", HOME_LIN_BIG),
    (EDGE, "little", EDGE_LITTLE), (EDGE, "big", EDGE_BIG),
    (FEEDBACK, "little", FEEDBACK_LITTLE), (FEEDBACK, "big", FEEDBACK_BIG),
])
def test_golden_bytes(record, order, hexstr):
    data = bytes.fromhex(hexstr)
    assert len(data) == RECORD_SIZE
    assert record.encode(order) == data
    assert type(record).decode(data, order) == record
    assert type(record).decode(bytearray(data), ByteOrder(order)) == record
    assert type(record).decode(memoryview(data), order) == record


def test_default_byte_order_is_little():
    assert HOME_LIN.encode() == bytes.fromhex(HOME_LIN_LITTLE)
    assert Feedback.decode(bytes.fromhex(FEEDBACK_LITTLE)) == FEEDBACK


def test_feedback_words_are_signed():
    """The thesis' decoder read big-endian unsigned words: -300 must come back as -300."""
    got = Feedback.decode(bytes.fromhex(FEEDBACK_LITTLE), "little")
    assert (got.y, got.rx) == (-300, -90)
    assert Feedback.decode(bytes.fromhex(FEEDBACK_LITTLE), "big").x == 0x6004  # wrong order: garbage


def test_idle_command_is_all_zero():
    idle = Command.idle()
    assert idle.encode() == bytes(14) and idle.encode("big") == bytes(14)
    assert Command.decode(bytes(14)) == idle
    assert not idle.request and idle.move_type is WireMoveType.NONE


def test_record_views():
    assert HOME_LIN.values == (1120, 0, 725, 0, 45, 0)
    assert HOME_LIN.pose == ControllerPose(1120, 0, 725, 0, 45, 0)
    assert FEEDBACK.pose == ControllerPose(1120, -300, 725, -90, 45, 179)
    assert HOME_LIN.with_request(False).request is False
    assert "LIN" in HOME_LIN.describe() and "flag 1" in HOME_LIN.describe()
    assert "BUSY" in FEEDBACK.describe() and "in motion" in FEEDBACK.describe()


# ----------------------------------------------------------------------------------- byte order

@pytest.mark.parametrize("value, expected", [
    ("little", ByteOrder.LITTLE), ("big", ByteOrder.BIG), (" Big ", ByteOrder.BIG),
    (ByteOrder.LITTLE, ByteOrder.LITTLE),
])
def test_byte_order_parse(value, expected):
    assert parse_byte_order(value) is expected


@pytest.mark.parametrize("value", ["middle", "", None, 1, b"little"])
def test_byte_order_bad_value_names_the_parameter(value):
    with pytest.raises(ProtocolError, match="byte_order"):
        parse_byte_order(value)
    with pytest.raises(ProtocolError, match="~feedback_order"):
        parse_byte_order(value, "~feedback_order")
    with pytest.raises(ProtocolError, match="byte_order"):
        HOME_LIN.encode(value)
    with pytest.raises(ProtocolError, match="byte_order"):
        Feedback.decode(bytes(14), value)


# ----------------------------------------------------------------------------------- round trips

int16 = st.integers(-32768, 32767)
orders = st.sampled_from(["little", "big"])


@st.composite
def commands(draw):
    kind = draw(st.sampled_from(list(WireMoveType)))
    request = False if kind is WireMoveType.NONE else draw(st.booleans())
    return Command(*[draw(int16) for _ in range(6)], request=request, move_type=kind)


@st.composite
def feedbacks(draw):
    return Feedback(*[draw(int16) for _ in range(6)], state=draw(st.sampled_from(list(ControllerState))),
                    status=StatusBits(draw(st.integers(0, 0x3F))))


@FAST
@given(commands(), orders)
def test_command_round_trip(cmd, order):
    data = cmd.encode(order)
    assert len(data) == 14
    assert Command.decode(data, order) == cmd


@FAST
@given(feedbacks(), orders)
def test_feedback_round_trip(rec, order):
    assert Feedback.decode(rec.encode(order), order) == rec


@FAST
@given(st.binary(min_size=14, max_size=14), orders)
def test_any_14_bytes_decode_exactly_or_fail_cleanly(data, order):
    """Decoding is the inverse of encoding on every record it accepts; the rest is ProtocolError."""
    for cls in (Command, Feedback):
        try:
            rec = cls.decode(data, order)
        except ProtocolError:
            continue
        assert rec.encode(order) == data


def test_byte_orders_differ_only_by_word_swap():
    little, big = EDGE.encode("little"), EDGE.encode("big")
    for i in range(0, 12, 2):
        assert little[i:i + 2] == big[i:i + 2][::-1]
    assert little[12:] == big[12:]


# ----------------------------------------------------------------------------------- decode errors

def _cmd_bytes(flag=1, kind=1):
    return bytes(12) + bytes([flag, kind])


@pytest.mark.parametrize("length", [0, 1, 13, 15, 28])
def test_decode_wrong_length(length):
    with pytest.raises(ProtocolError, match="14 bytes, got %d" % length):
        Command.decode(bytes(length))
    with pytest.raises(ProtocolError, match="14 bytes, got %d" % length):
        Feedback.decode(bytes(length))


@pytest.mark.parametrize("data", [3.5, "abcdefghijklmn", None, [300] * 14])
def test_decode_not_bytes(data):
    with pytest.raises(ProtocolError):
        Command.decode(data)
    with pytest.raises(ProtocolError):
        Feedback.decode(data)


def test_decode_list_of_ints_is_accepted():
    assert Command.decode(list(bytes.fromhex(HOME_LIN_LITTLE))) == HOME_LIN


@pytest.mark.parametrize("flag", [3, 0x80, 0xFF])
def test_command_decode_bad_flag(flag):
    with pytest.raises(ProtocolError, match="byte 13 .*0, 1 or 2 \\(stop\\), got 0x%02X" % flag):
        Command.decode(_cmd_bytes(flag=flag))


def test_stop_flag_golden_bytes_and_round_trip():
    stop = Command(1120, 0, 725, 0, 45, 0, False, WireMoveType.LIN).with_stop()
    assert stop.encode().hex(" ") == "60 04 00 00 d5 02 00 00 2d 00 00 00 02 02"
    assert Command.decode(stop.encode()) == stop
    assert (stop.request, stop.stop) == (False, True)
    assert stop.with_request(True).stop is False
    assert Command.decode(_cmd_bytes(flag=2, kind=0)).stop      # a stop needs no move type
    with pytest.raises(ProtocolError, match="a motion and a stop"):
        Command(0, 0, 0, 0, 0, 0, True, WireMoveType.PTP, stop=True)


@pytest.mark.parametrize("kind", [5, 9, 0xFF])
def test_command_decode_unknown_move_type(kind):
    with pytest.raises(ProtocolError, match="byte 14 .*= %d is unknown" % kind):
        Command.decode(_cmd_bytes(kind=kind))


def test_command_decode_none_type_only_without_request():
    assert Command.decode(_cmd_bytes(flag=0, kind=0)) == Command.idle()
    with pytest.raises(ProtocolError, match="none"):
        Command.decode(_cmd_bytes(flag=1, kind=0))


def test_command_decode_type_with_flag_zero_is_valid():
    """The master keeps the target bytes with the flag at 0 after the answer."""
    for kind in (1, 2, 3, 4):
        cmd = Command.decode(_cmd_bytes(flag=0, kind=kind))
        assert not cmd.request and cmd.move_type == kind


@pytest.mark.parametrize("state", [4, 5, 0xFF])
def test_feedback_decode_unknown_state(state):
    with pytest.raises(ProtocolError, match="byte 13 .*state.* = %d is unknown" % state):
        Feedback.decode(bytes(12) + bytes([state, 0]))


@pytest.mark.parametrize("status", [0x40, 0x80, 0xC0, 0x7F])
def test_feedback_decode_reserved_status_bits(status):
    with pytest.raises(ProtocolError, match="reserved bit"):
        Feedback.decode(bytes(12) + bytes([0, status]))


def test_feedback_decode_all_defined_status_bits():
    rec = Feedback.decode(bytes(12) + bytes([3, 0x3F]))
    assert rec.state is REJECTED and rec.status == StatusBits(0x3F)


# ----------------------------------------------------------------------------- record construction

@pytest.mark.parametrize("bad", [1.0, 1.5, True, "3", None, 40000, -32769])
def test_command_fields_must_be_int16(bad):
    with pytest.raises(ProtocolError, match="command Y"):
        Command(0, bad, 0, 0, 0, 0, False, WireMoveType.PTP)
    with pytest.raises(ProtocolError, match="feedback Rz"):
        Feedback(0, 0, 0, 0, 0, bad, READY)


@pytest.mark.parametrize("flag", [2, -1, "yes", None, 0.5])
def test_command_request_flag_must_be_boolean(flag):
    with pytest.raises(ProtocolError, match="request flag"):
        Command(0, 0, 0, 0, 0, 0, flag, WireMoveType.PTP)


def test_command_request_accepts_0_and_1():
    assert Command(0, 0, 0, 0, 0, 0, 1, 1).request is True
    assert Command(0, 0, 0, 0, 0, 0, 0, 1).request is False
    assert Command(0, 0, 0, 0, 0, 0, 1, 1).move_type is WireMoveType.PTP


def test_command_needs_a_type_with_request():
    with pytest.raises(ProtocolError, match="needs a move type"):
        Command(0, 0, 0, 0, 0, 0, True, WireMoveType.NONE)
    with pytest.raises(ProtocolError, match="unknown move type"):
        Command(0, 0, 0, 0, 0, 0, True, 9)


@pytest.mark.parametrize("state", [4, -1, "READY", True, 1.0])
def test_feedback_bad_state(state):
    with pytest.raises(ProtocolError, match="state"):
        Feedback(0, 0, 0, 0, 0, 0, state)


@pytest.mark.parametrize("status", [0x40, 0x80, 256, -1, True, "x"])
def test_feedback_bad_status(status):
    with pytest.raises(ProtocolError, match="status"):
        Feedback(0, 0, 0, 0, 0, 0, READY, status)


def test_records_are_frozen():
    with pytest.raises(Exception):
        HOME_LIN.x = 3  # type: ignore[misc]
    with pytest.raises(Exception):
        FEEDBACK.state = READY  # type: ignore[misc]


# ------------------------------------------------------------------------------------- from_pose

@pytest.mark.parametrize("value, expected", [
    (0.0, 0), (0.4, 0), (0.5, 1), (-0.5, -1), (1.5, 2), (2.5, 3), (-2.5, -3), (-0.4, 0),
    (0.49999999999999994, 0), (1120.4999, 1120), (-1120.5, -1121), (724.6, 725), (1e15 + 0.5, 10 ** 15 + 1),
])
def test_round_half_away_from_zero(value, expected):
    assert round_half_away(value) == expected


def test_from_pose_rounds_each_field():
    cmd = Command.from_pose((1120.4, -0.5, 724.5, 0.49, 44.5, -179.6), MoveType.LIN)
    assert cmd.values == (1120, -1, 725, 0, 45, -180)
    assert cmd.request and cmd.move_type is WireMoveType.LIN


def test_from_pose_takes_a_controller_pose_and_workspace():
    cmd = Command.from_pose(HOME_POSE, "ptp", Workspace())
    assert cmd == Command(1120, 0, 725, 0, 45, 0, True, WireMoveType.PTP)
    assert Command.from_pose(HOME_POSE, WireMoveType.CIRC_VIA, request=False).request is False


@pytest.mark.parametrize("field, value, limit", [
    (0, 1400.5, r"\[100, 1400\]"), (0, 99.4, r"\[100, 1400\]"), (1, -900.5, r"\[-900, 900\]"),
    (2, -0.6, r"\[0, 1400\]"), (3, 180.5, r"\[-180, 180\]"), (5, -181, r"\[-180, 180\]"),
])
def test_from_pose_workspace_error_names_field_and_limit(field, value, limit):
    values = [1120.0, 0.0, 725.0, 0.0, 45.0, 0.0]
    values[field] = value
    name = ("X", "Y", "Z", "Rx", "Ry", "Rz")[field]
    with pytest.raises(PoseError, match=r"%s = .* outside the workspace %s" % (name, limit)):
        Command.from_pose(values, "lin", Workspace())
    Command.from_pose(values, "lin")  # no workspace: only int16 applies


def test_from_pose_workspace_bound_checked_after_rounding():
    assert Command.from_pose((1400.4, 0, 725, 0, 45, 0), "lin", Workspace()).x == 1400
    assert Command.from_pose((1120, 0, 725, 0, 45, -180.4), "lin", Workspace()).rz == -180


@pytest.mark.parametrize("value", [32767.5, -32768.5, 1e9, -1e20])
def test_from_pose_int16_range(value):
    with pytest.raises(PoseError, match=r"Z \[mm\] = .* int16 range \[-32768, 32767\]"):
        Command.from_pose((0, 0, value, 0, 0, 0), "ptp")


def test_from_pose_int16_extremes_pass():
    assert Command.from_pose((32767.4, -32768.4, 0, 0, 0, 0), "ptp").values[:2] == (32767, -32768)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, None, "abc"])
def test_from_pose_rejects_non_finite(value):
    with pytest.raises(PoseError, match=r"Ry \[deg\]"):
        Command.from_pose((1120, 0, 725, 0, value, 0), "ptp")


@pytest.mark.parametrize("pose", [(1, 2, 3), (1, 2, 3, 4, 5, 6, 7), 5])
def test_from_pose_wrong_shape(pose):
    with pytest.raises(PoseError, match="6"):
        Command.from_pose(pose, "ptp")


def test_from_pose_needs_a_motion_type():
    with pytest.raises(ProtocolError, match="NONE"):
        Command.from_pose(HOME_POSE, WireMoveType.NONE)
    with pytest.raises(ProtocolError, match="CIRC"):
        Command.from_pose(HOME_POSE, MoveType.CIRC)


def test_to_wire_int_and_feedback_from_pose():
    assert to_wire_int(-2.5, "X") == -3
    rec = Feedback.from_pose(ControllerPose(1120.5, 0.2, 724.5, -0.5, 45.2, 0), DONE, StatusBits.DRIVES_POWERED)
    assert rec.values == (1121, 0, 725, -1, 45, 0) and rec.state is DONE
    with pytest.raises(PoseError):
        Feedback.from_pose((0, 0, 0, 0, 0), READY)
    with pytest.raises(PoseError, match="X"):
        Feedback.from_pose((40000, 0, 0, 0, 0, 0), READY)


# ------------------------------------------------------------------------------------- move types

def test_wire_move_type_values_match_design():
    assert [int(t) for t in (WireMoveType.NONE, WireMoveType.PTP, WireMoveType.LIN, WireMoveType.CIRC_END,
                             WireMoveType.CIRC_VIA)] == [0, 1, 2, 3, 4]
    assert [int(s) for s in ControllerState] == [0, 1, 2, 3]
    assert [int(b) for b in StatusBits] == [1, 2, 4, 8, 16, 32]


@pytest.mark.parametrize("value, expected", [
    (1, WireMoveType.PTP), ("lin", WireMoveType.LIN), ("CIRC_VIA", WireMoveType.CIRC_VIA),
    (" circ_end ", WireMoveType.CIRC_END), (MoveType.PTP, WireMoveType.PTP), (MoveType.LIN, WireMoveType.LIN),
    (WireMoveType.NONE, WireMoveType.NONE), (0, WireMoveType.NONE),
])
def test_wire_move_type_parse(value, expected):
    assert WireMoveType.parse(value) is expected


@pytest.mark.parametrize("value", [5, -1, True, "circ", "movel", None, 1.0, MoveType.CIRC])
def test_wire_move_type_parse_errors(value):
    with pytest.raises(ProtocolError):
        WireMoveType.parse(value)


def test_move_type_mapping_both_ways():
    assert WireMoveType.from_move_type(MoveType.PTP) is WireMoveType.PTP
    assert WireMoveType.from_move_type("lin") is WireMoveType.LIN
    assert WireMoveType.from_move_type(MoveType.CIRC) is WireMoveType.CIRC_END
    assert WireMoveType.from_move_type(MoveType.CIRC, via=True) is WireMoveType.CIRC_VIA
    assert WireMoveType.PTP.to_move_type() is MoveType.PTP
    assert WireMoveType.LIN.to_move_type() is MoveType.LIN
    assert WireMoveType.CIRC_END.to_move_type() is MoveType.CIRC
    assert WireMoveType.CIRC_VIA.to_move_type() is MoveType.CIRC
    with pytest.raises(ProtocolError):
        WireMoveType.NONE.to_move_type()
    assert [t.instruction for t in WireMoveType] == [None, "MOVEP", "MOVEL", "MOVEC", None]


def test_status_describe():
    assert StatusBits(0).describe() == "none"
    assert (StatusBits.IN_MOTION | StatusBits.DRIVES_POWERED).describe() == "drives powered, in motion"
    assert StatusBits(0x3F).describe() == ("drives powered, e-stop, error, in motion, program running, "
                                           "via point stored")


def test_commands_for():
    via = (1000, 100, 700, 0, 45, 0)
    assert commands_for(MoveType.PTP, HOME_POSE) == [Command.from_pose(HOME_POSE, "ptp")]
    assert commands_for("lin", HOME_POSE)[0].move_type is WireMoveType.LIN
    circ = commands_for(MoveType.CIRC, HOME_POSE, via=via)
    assert [c.move_type for c in circ] == [WireMoveType.CIRC_VIA, WireMoveType.CIRC_END]
    assert circ[0].values == via and circ[1].values == (1120, 0, 725, 0, 45, 0)
    assert all(c.request for c in circ)
    assert commands_for(WireMoveType.CIRC_END, HOME_POSE, via=via) == circ
    with pytest.raises(ProtocolError, match="via"):
        commands_for(MoveType.CIRC, HOME_POSE)
    with pytest.raises(ProtocolError, match="only used by CIRC"):
        commands_for(MoveType.LIN, HOME_POSE, via=via)
    with pytest.raises(ProtocolError):
        commands_for("spline", HOME_POSE)
    with pytest.raises(ProtocolError):
        commands_for(WireMoveType.CIRC_VIA, HOME_POSE)
    with pytest.raises(PoseError, match="Y = 950"):
        commands_for(MoveType.CIRC, HOME_POSE, via=(1000, 950, 700, 0, 45, 0), workspace=Workspace())


def test_error_tree():
    assert issubclass(ProtocolError, VrDriverError)
    assert issubclass(HandshakeError, ProtocolError)
    assert issubclass(HandshakeTimeout, HandshakeError) and issubclass(HandshakeTimeout, TimeoutError)
    assert issubclass(TargetRejected, HandshakeError)
    err = TargetRejected("no", HOME_LIN)
    assert err.target is HOME_LIN and err.reason == "no" and str(err) == "no"
    err = HandshakeTimeout("late", HOME_LIN, "accept")
    assert (err.target, err.stage, str(err)) == (HOME_LIN, "accept", "late")


# ========================================================================= controller handshake

def test_controller_idle_without_flag():
    ch = ControllerHandshake()
    assert ch.state is READY
    for cmd in (None, Command.idle(), target().with_request(False)):
        assert ch.step(cmd) is None and ch.state is READY


def test_controller_motion_cycle():
    ch = ControllerHandshake()
    cmd = target(1, WireMoveType.LIN)
    assert ch.step(cmd, arm_idle=True) == cmd
    assert ch.state is BUSY and ch.active == cmd and ch.accepted == 1
    for c in (cmd, cmd.with_request(False), cmd):     # BUSY ignores the flag until finish()
        assert ch.step(c) is None and ch.state is BUSY
    ch.finish(True)
    assert ch.state is DONE and ch.completed == 1
    for _ in range(3):                                 # DONE held while the flag stays 1: no restart
        assert ch.step(cmd) is None and ch.state is DONE
    assert ch.step(cmd.with_request(False)) is None and ch.state is READY
    assert ch.active is None and ch.accepted == 1


def test_controller_motion_failure_is_rejected():
    ch = ControllerHandshake()
    ch.step(target())
    ch.finish(False, "unreachable")
    assert ch.state is REJECTED and ch.reason == "unreachable" and ch.rejected == 1
    assert ch.step(target()) is None and ch.state is REJECTED
    assert ch.step(None) is None and ch.state is READY


def test_controller_finish_needs_motion():
    ch = ControllerHandshake()
    with pytest.raises(ProtocolError, match="finish"):
        ch.finish(True)
    ch.step(target(kind=WireMoveType.CIRC_VIA))
    with pytest.raises(ProtocolError):
        ch.finish(True)


def test_controller_rejects_when_arm_not_ready():
    ch = ControllerHandshake()
    assert ch.step(target(), arm_idle=False) is None
    assert ch.state is REJECTED and "not ready" in ch.reason and ch.accepted == 0


def test_controller_via_then_end():
    ch = ControllerHandshake()
    via, end = commands_for(MoveType.CIRC, (1100, 0, 700, 0, 45, 0), via=(1000, 100, 700, 0, 45, 0))
    assert ch.step(via) is None                       # no motion for a via point
    assert ch.state is DONE and ch.via_stored and ch.stored_via == via
    assert ch.status_bits() == StatusBits.VIA_STORED
    ch.step(via.with_request(False))
    assert ch.state is READY and ch.via_stored         # kept across the release
    assert ch.step(end) == end
    assert ch.state is BUSY and ch.active_via == via and not ch.via_stored
    ch.finish(True)
    assert ch.state is DONE and ch.active_via is None and ch.status_bits() == StatusBits(0)


def test_controller_end_without_via_is_rejected():
    ch = ControllerHandshake()
    assert ch.step(target(kind=WireMoveType.CIRC_END)) is None
    assert ch.state is REJECTED and "via" in ch.reason


def test_controller_via_serves_the_next_request_only():
    ch = ControllerHandshake()
    ch.step(target(1, WireMoveType.CIRC_VIA)); ch.step(None)
    ch.step(target(2, WireMoveType.CIRC_VIA)); ch.step(None)   # a new via replaces the old
    assert ch.stored_via == target(2, WireMoveType.CIRC_VIA)
    assert ch.step(target(3, WireMoveType.PTP)) == target(3)   # a PTP discards it
    assert not ch.via_stored
    ch.finish(True); ch.step(None)
    assert ch.step(target(4, WireMoveType.CIRC_END)) is None and ch.state is REJECTED


def test_controller_feedback_record():
    ch = ControllerHandshake()
    rec = ch.feedback((1120.4, 0, 725, 0, 45, 0), StatusBits.DRIVES_POWERED | StatusBits.VIA_STORED)
    assert rec == Feedback(1120, 0, 725, 0, 45, 0, READY, StatusBits.DRIVES_POWERED)  # no via: bit cleared
    ch.step(target(kind=WireMoveType.CIRC_VIA))
    rec = ch.feedback(HOME_POSE, StatusBits.DRIVES_POWERED)
    assert rec.state is DONE and rec.status == StatusBits.DRIVES_POWERED | StatusBits.VIA_STORED


def test_controller_reset():
    ch = ControllerHandshake()
    ch.step(target(kind=WireMoveType.CIRC_VIA)); ch.step(None)
    ch.step(target(kind=WireMoveType.CIRC_END))
    ch.reset()
    assert ch.state is READY and not ch.via_stored and ch.active is None and ch.active_via is None


# ============================================================================= master handshake

def ready_master(**kw):
    clock = FakeClock()
    m = MasterHandshake(clock=clock, **kw)
    m.update(fb(READY))
    clock.t += m.settle_time
    m.update(fb(READY))
    assert m.ready
    return m, clock


def test_master_starts_unsynchronised():
    clock = FakeClock()
    m = MasterHandshake(clock=clock)
    assert m.phase is MasterPhase.SYNC and not m.ready and m.seq == 0
    assert m.outputs() == Command.idle() and m.in_flight is None and m.phase_since is None
    with pytest.raises(HandshakeError, match="not ready"):
        m.submit(target(), 5.0)


def test_master_settles_on_ready_after_start():
    clock = FakeClock()
    m = MasterHandshake(accept_timeout=0.5, clock=clock)
    assert m.settle_time == 0.5
    assert m.update(fb(READY)) is None and m.phase is MasterPhase.SYNC
    clock.t += 0.49
    m.update(fb(READY))
    assert m.phase is MasterPhase.SYNC
    clock.t += 0.01
    m.update(None)                      # no record: no transition
    assert m.phase is MasterPhase.SYNC
    m.update(fb(READY))
    assert m.ready and m.phase_since == clock.t


def test_master_settle_zero_and_old_answer_skip_the_wait():
    m = MasterHandshake(settle_time=0, clock=FakeClock())
    m.update(fb(READY))
    assert m.ready
    m = MasterHandshake(clock=FakeClock())
    m.update(fb(DONE))                  # the controller holds an answer from before: it sees flag 0 now
    assert m.phase is MasterPhase.SYNC
    m.update(fb(READY))
    assert m.ready


def test_master_full_cycle():
    m, clock = ready_master()
    cmd = target(7).with_request(False)
    assert m.submit(cmd, 5.0) == 1
    assert m.phase is MasterPhase.WAIT_ACCEPT and m.in_flight == cmd.with_request(True)
    assert m.outputs() == cmd.with_request(True)           # the flag is raised by submit
    with pytest.raises(HandshakeError, match="in flight"):
        m.submit(target(8), 5.0)
    assert m.update(fb(READY)) is None and m.phase is MasterPhase.WAIT_ACCEPT
    clock.t += 0.1
    ev = m.update(fb(BUSY))
    assert isinstance(ev, Accepted) and not ev.final and ev.seq == 1 and ev.time == clock.t
    assert m.phase is MasterPhase.EXECUTING and m.outputs().request
    assert m.update(fb(BUSY)) is None
    ev = m.update(fb(DONE, pose=(1007, -7, 700, 0, 45, 0)))
    assert isinstance(ev, Done) and ev.final and ev.target == target(7) and ev.feedback.x == 1007
    assert m.phase is MasterPhase.WAIT_RELEASE and m.in_flight is None
    assert m.outputs() == target(7).with_request(False)     # same bytes, flag cleared
    assert m.update(fb(DONE)) is None                       # still held: no second event
    with pytest.raises(HandshakeError, match="READY"):
        m.submit(target(8), 5.0)
    assert m.update(fb(READY)) is None and m.ready
    assert m.last_event is ev


def test_master_fast_motion_done_without_busy():
    m, _ = ready_master()
    m.submit(target(), 5.0)
    ev = m.update(fb(DONE))
    assert isinstance(ev, Done) and m.phase is MasterPhase.WAIT_RELEASE


@pytest.mark.parametrize("busy_first", [False, True])
def test_master_rejection(busy_first):
    m, _ = ready_master()
    m.submit(target(), 5.0)
    if busy_first:
        m.update(fb(BUSY))
    ev = m.update(fb(REJECTED, status=StatusBits.ERROR | StatusBits.DRIVES_POWERED))
    assert isinstance(ev, Rejected) and ev.final and "drives powered, error" in ev.reason
    err = ev.error()
    assert isinstance(err, TargetRejected) and err.target == target()
    assert m.phase is MasterPhase.WAIT_RELEASE and not m.outputs().request
    m.update(fb(READY))
    assert m.ready


def test_master_accept_timeout_and_late_pickup():
    m, clock = ready_master(accept_timeout=1.0)
    m.submit(target(1), 5.0)
    clock.t += 1.0
    assert m.update(fb(READY)) is None                      # exactly at the limit: not yet
    clock.t += 0.01
    ev = m.update(None)
    assert isinstance(ev, TimedOut) and ev.stage == "accept" and ev.final
    assert isinstance(ev.error(), HandshakeTimeout) and ev.error().stage == "accept"
    assert m.phase is MasterPhase.RECOVER and not m.outputs().request
    # READY right after clearing proves nothing: the controller may have read the flag just before
    assert m.update(fb(READY)) is None and not m.ready
    # ... and it did: the late motion's BUSY / DONE produce no events for anyone
    assert m.update(fb(BUSY)) is None and m.update(fb(DONE)) is None
    assert m.update(fb(READY)) is None and m.ready          # after its answer: the next READY is real
    m.submit(target(2), 5.0)
    assert m.update(fb(READY)) is None and m.phase is MasterPhase.WAIT_ACCEPT


def test_master_accept_timeout_settles_without_late_pickup():
    m, clock = ready_master(accept_timeout=1.0)
    m.submit(target(1), 5.0)
    clock.t += 1.5
    assert isinstance(m.update(fb(READY)), TimedOut)
    clock.t += 0.9
    m.update(fb(READY))
    assert not m.ready
    clock.t += 0.1
    m.update(fb(READY))
    assert m.ready


def test_master_motion_timeout_counts_from_accept():
    m, clock = ready_master()
    m.submit(target(), 2.0)
    clock.t += 0.5
    m.update(fb(BUSY))
    clock.t += 2.0
    assert m.update(fb(BUSY)) is None
    clock.t += 0.01
    ev = m.update(fb(BUSY))
    assert isinstance(ev, TimedOut) and ev.stage == "motion" and "2 s" in ev.reason
    assert m.phase is MasterPhase.RECOVER and not m.outputs().request
    assert m.update(fb(DONE)) is None                       # the motion ends late: no event
    m.update(fb(READY))
    assert m.ready                                          # BUSY was seen: no settle needed


def test_master_answer_beats_timeout_in_the_same_update():
    m, clock = ready_master()
    m.submit(target(), 1.0)
    m.update(fb(BUSY))
    clock.t += 10
    assert isinstance(m.update(fb(DONE)), Done)


def test_master_release_timeout():
    m, clock = ready_master(release_timeout=0.5)
    m.submit(target(), 5.0)
    m.update(fb(DONE))
    clock.t += 0.5
    assert m.update(fb(DONE)) is None
    clock.t += 0.01
    ev = m.update(fb(DONE))
    assert isinstance(ev, TimedOut) and ev.stage == "release" and not ev.final
    assert m.phase is MasterPhase.RECOVER
    clock.t += 100
    assert m.update(fb(DONE)) is None                       # reported once
    m.update(fb(READY))
    assert m.ready


def test_master_controller_drops_busy_without_answer():
    m, _ = ready_master()
    m.submit(target(), 5.0)
    m.update(fb(BUSY))
    ev = m.update(fb(READY))
    assert isinstance(ev, Rejected) and "without reporting DONE" in ev.reason
    assert m.phase is MasterPhase.RECOVER and not m.outputs().request


def test_master_abort_before_accept_needs_settle():
    m, clock = ready_master()
    m.submit(target(), 5.0)
    ev = m.abort("user cancel")
    assert isinstance(ev, Aborted) and ev.reason == "user cancel" and ev.final and ev.seq == 1
    assert not m.outputs().request and m.phase is MasterPhase.RECOVER   # cleared at once
    m.update(fb(READY))
    assert not m.ready
    clock.t += m.settle_time
    m.update(fb(READY))
    assert m.ready


def test_master_abort_while_executing():
    m, _ = ready_master()
    m.submit(target(), 5.0)
    m.update(fb(BUSY))
    assert isinstance(m.abort(), Aborted)
    assert not m.outputs().request
    assert m.update(fb(BUSY)) is None and m.update(fb(DONE)) is None   # no Done for an aborted target
    m.update(fb(READY))
    assert m.ready


def test_master_abort_with_stop_sends_flag_2_until_ready():
    m, _ = ready_master()
    m.submit(target(), 5.0)
    m.update(fb(BUSY))
    ev = m.abort("cancel", stop=True)
    assert isinstance(ev, Aborted)
    out = m.outputs()
    assert out.stop and not out.request and out.encode()[12] == 2
    assert out.values == target().values                              # same target bytes
    assert m.update(fb(BUSY)) is None and m.outputs().stop             # still moving: keep asking
    assert m.update(fb(REJECTED)) is None and m.outputs().stop         # stopped; flag 2 releases
    m.update(fb(READY))
    assert m.ready and not m.outputs().stop and not m.outputs().request


def test_controller_halts_on_stop_and_releases():
    ch = ControllerHandshake()
    cmd = target(kind=WireMoveType.LIN)
    assert ch.step(cmd) == cmd and ch.state is BUSY
    assert not ch.stop_requested
    ch.step(cmd)                                   # flag still 1: keep moving
    assert not ch.stop_requested
    ch.step(cmd.with_stop())
    assert ch.stop_requested and ch.state is BUSY  # the program halts the arm now
    ch.finish(False, "stopped by the master")
    assert ch.state is REJECTED and ch.reason == "stopped by the master" and not ch.stop_requested
    ch.step(cmd.with_stop())                       # flag 2 also releases the answer
    assert ch.state is READY
    assert ch.step(cmd.with_stop()) is None and ch.state is READY   # a stop never starts anything


def test_controller_stop_when_ready_is_ignored():
    ch = ControllerHandshake()
    assert ch.step(target().with_stop()) is None
    assert ch.state is READY and not ch.stop_requested and ch.accepted == 0


def test_master_abort_with_nothing_in_flight():
    m, _ = ready_master()
    assert m.abort() is None and m.ready
    m.submit(target(), 5.0)
    m.update(fb(DONE))
    assert m.abort() is None and m.phase is MasterPhase.WAIT_RELEASE


@pytest.mark.parametrize("busy_seen", [False, True])
def test_master_reset_after_link_loss(busy_seen):
    m, clock = ready_master()
    m.submit(target(3), 5.0)
    if busy_seen:
        m.update(fb(BUSY))
    ev = m.reset()
    assert isinstance(ev, Aborted) and ev.reason == "link lost" and ev.target == target(3)
    assert m.phase is MasterPhase.SYNC and m.outputs() == Command.idle() and m.last_feedback is None
    with pytest.raises(HandshakeError):
        m.submit(target(4), 5.0)
    m.update(fb(READY))                   # the first READY after the link came back is not enough
    assert not m.ready
    clock.t += m.settle_time
    m.update(fb(READY))
    assert m.ready and m.seq == 1
    assert m.reset() is None              # nothing in flight


def test_master_reset_then_stale_done():
    m, _ = ready_master()
    m.submit(target(3), 5.0)
    m.update(fb(BUSY))
    m.reset()
    assert m.update(fb(DONE)) is None     # the pre-loss target's answer: no event, not ready
    assert not m.ready
    m.update(fb(READY))
    assert m.ready
    m.submit(target(4), 5.0)
    assert m.update(fb(READY)) is None and m.phase is MasterPhase.WAIT_ACCEPT


def test_master_idle_sees_unrequested_activity():
    m, _ = ready_master()
    m.update(fb(BUSY))
    assert m.phase is MasterPhase.SYNC
    with pytest.raises(HandshakeError, match="last state: BUSY"):
        m.submit(target(), 5.0)
    m.update(fb(DONE)); m.update(fb(READY))
    assert m.ready


def test_master_argument_checks():
    for bad in (0, -1, math.nan, math.inf, True, "x", None):
        with pytest.raises(HandshakeError, match="accept_timeout"):
            MasterHandshake(accept_timeout=bad)
        with pytest.raises(HandshakeError, match="release_timeout"):
            MasterHandshake(release_timeout=bad)
    with pytest.raises(HandshakeError, match="settle_time"):
        MasterHandshake(settle_time=-1)
    assert MasterHandshake(settle_time=0).settle_time == 0.0
    m, _ = ready_master()
    with pytest.raises(HandshakeError, match="motion_timeout"):
        m.submit(target(), 0)
    with pytest.raises(HandshakeError, match="Command"):
        m.submit((1, 2, 3), 1.0)  # type: ignore[arg-type]
    with pytest.raises(HandshakeError, match="NONE"):
        m.submit(Command.idle(), 1.0)
    with pytest.raises(HandshakeError, match="Feedback"):
        m.update(b"\x00" * 14)  # type: ignore[arg-type]
    assert m.ready                        # nothing changed


def test_master_explicit_now_overrides_clock():
    m = MasterHandshake(settle_time=1.0, clock=lambda: 0.0)
    m.update(fb(READY), now=10.0)
    m.update(fb(READY), now=11.0)
    assert m.ready
    m.submit(target(), 1.0, now=11.0)
    assert isinstance(m.update(None, now=12.5), TimedOut)


# ---------------------------------------------------------------------- exactly once, fuzzed

ACTIONS = st.lists(st.one_of(
    st.tuples(st.just("fb"), st.sampled_from(list(ControllerState))),
    st.tuples(st.just("tick"), st.sampled_from([0.0, 0.3, 1.1, 6.0])),
    st.tuples(st.just("submit"), st.just(None)),
    st.tuples(st.just("abort"), st.just(None)),
    st.tuples(st.just("reset"), st.just(None)),
), max_size=60)


@FAST
@given(ACTIONS)
def test_master_never_raises_a_flag_twice_for_one_target(actions):
    """Whatever the controller reports and whatever the caller does: the flag is 1 for a target in
    one unbroken stretch, each target gets at most one final event, and no event of any kind comes
    for a target after its final one (a late release TimedOut is not final)."""
    clock = FakeClock()
    m = MasterHandshake(accept_timeout=1.0, release_timeout=1.0, clock=clock)
    flag_history = {}     # seq -> list of flag values seen while it was the current target
    finals = {}
    n = 0

    def observe(event):
        if event is None:
            return
        assert event.seq == m.seq
        assert event.seq not in finals or (isinstance(event, TimedOut) and event.stage == "release"
                                           and isinstance(finals[event.seq], (Done, Rejected)))
        if event.final:
            finals[event.seq] = event

    for kind, arg in actions:
        if kind == "fb":
            observe(m.update(fb(arg)))
        elif kind == "tick":
            clock.t += arg
            observe(m.update(None))
        elif kind == "submit":
            if m.ready:
                n += 1
                assert m.submit(target(n), 2.0) == n
            else:
                with pytest.raises(HandshakeError):
                    m.submit(target(n + 1), 2.0)
        elif kind == "abort":
            observe(m.abort())
        else:
            observe(m.reset())
        out = m.outputs()
        if m.seq:
            flag_history.setdefault(m.seq, []).append(out.request)
        if out.request:
            assert out == target(m.seq) and m.seq not in finals
    for seq, flags in flag_history.items():
        edges = sum(1 for a, b in zip([False] + flags, flags) if b and not a)
        assert edges <= 1, (seq, flags)


# ------------------------------------------------------------------- back to back, in memory

class FakeArm:
    """Moves for ``loops`` controller loops, then reports the motion finished (or failed)."""

    def __init__(self):
        self.remaining = None
        self.fail = False

    def start(self, loops, fail=False):
        self.remaining, self.fail = loops, fail

    def tick(self):
        """True / False when the motion ended now (reached / failed), None otherwise."""
        if self.remaining is None:
            return None
        if self.remaining <= 0:
            self.remaining = None
            return not self.fail
        self.remaining -= 1
        return None


def run_back_to_back(moves, rng, byte_order="little", fail_rate=0.0, abort_rate=0.0, out_delay=1, in_delay=1,
                     loop_every=(1, 1), accept_timeout=1.0, max_cycles=200000):
    """Master and controller joined by delay lines that carry encoded records; the controller's
    program runs one loop every ``loop_every`` bus cycles. Returns (executed, events, master);
    ``executed`` lists (command, via) per motion started, ``events`` (event, len(executed) then)."""
    clock = FakeClock(0.0)
    master = MasterHandshake(accept_timeout=accept_timeout, release_timeout=5.0, clock=clock)
    ctrl, arm = ControllerHandshake(), FakeArm()
    to_ctrl = deque([Command.idle().encode(byte_order)] * out_delay)
    to_master = deque([Feedback(0, 0, 0, 0, 0, 0, READY).encode(byte_order)] * in_delay)
    pending = deque(moves)              # each move: list of wire commands
    current = deque()
    executed, events = [], []
    controller_input = Command.idle()
    feedback = Feedback(0, 0, 0, 0, 0, 0, READY)
    next_loop = 0
    for cycle in range(max_cycles):
        clock.t = cycle * 0.01
        # bus: the master's outputs travel to the controller, its inputs travel back
        to_ctrl.append(master.outputs().encode(byte_order))
        controller_input = Command.decode(to_ctrl.popleft(), byte_order)
        # controller program loop (slower than the bus, with jitter)
        if cycle >= next_loop:
            next_loop = cycle + rng.randint(*loop_every)
            ended = arm.tick()
            if ended is not None:
                ctrl.finish(ended, "" if ended else "arm fault")
            start = ctrl.step(controller_input, arm_idle=arm.remaining is None)
            if start is not None:
                executed.append((start, ctrl.active_via))
                arm.start(rng.randint(0, 4), fail=rng.random() < fail_rate)
                if arm.remaining == 0 and rng.random() < 0.5:    # very fast: answered in this loop
                    arm.remaining = None
                    ctrl.finish(not arm.fail, "arm fault")
            status = StatusBits.DRIVES_POWERED | StatusBits.PROGRAM_RUNNING
            if arm.remaining is not None:
                status |= StatusBits.IN_MOTION
            feedback = ctrl.feedback((1120, 0, 725, 0, 45, 0), status)
        to_master.append(feedback.encode(byte_order))
        event = master.update(Feedback.decode(to_master.popleft(), byte_order))
        if event is not None:
            events.append((event, len(executed)))
            if event.final and not isinstance(event, Done):
                current.clear()          # give the rest of a failed move up (a CIRC's end point)
        if master.in_flight is not None and abort_rate and rng.random() < abort_rate:
            events.append((master.abort("test abort"), len(executed)))
            current.clear()
        if master.ready:
            if not current:
                if not pending:
                    break
                current.extend(pending.popleft())
            master.submit(current.popleft(), motion_timeout=5.0)
    else:
        raise AssertionError("did not finish: %d moves left" % len(pending))
    return executed, events, master


def random_moves(rng, n):
    moves = []
    for i in range(n):
        pose = (200 + i, (i % 7) * 10, 700, 0, 45, i % 180)
        kind = rng.choice([MoveType.PTP, MoveType.LIN, MoveType.CIRC])
        via = (150 + i, 50, 650, 0, 45, 0) if kind is MoveType.CIRC else None
        moves.append(commands_for(kind, pose, via=via, workspace=Workspace()))
    return moves


@pytest.mark.parametrize("byte_order, delays, loop_every", [
    ("little", (1, 1), (1, 1)), ("big", (0, 0), (1, 1)), ("little", (2, 3), (1, 4)),
])
def test_back_to_back_every_target_exactly_once_in_order(byte_order, delays, loop_every):
    rng = random.Random(42)
    moves = random_moves(rng, 300)
    executed, events, master = run_back_to_back(moves, rng, byte_order, out_delay=delays[0],
                                                in_delay=delays[1], loop_every=loop_every)
    wire = [c for move in moves for c in move]
    motions = [c for c in wire if c.move_type is not WireMoveType.CIRC_VIA]
    assert [cmd for cmd, _ in executed] == motions                  # each motion once, in order
    for cmd, via in executed:                                         # every arc used its own via
        if cmd.move_type is WireMoveType.CIRC_END:
            assert via is not None and via.x == cmd.x - 50
        else:
            assert via is None
    finals = [e for e, _ in events if e.final]
    assert all(isinstance(e, Done) for e in finals)
    assert [e.target for e in finals] == wire                        # one answer per target, in order
    assert [e.seq for e in finals] == list(range(1, len(wire) + 1))
    assert master.seq == len(wire)


def test_back_to_back_with_failures_aborts_and_timeouts():
    """Rejections, aborts and a controller too slow for the accept timeout: still no target runs
    twice, a Done is only reported for a target the controller really finished, and every
    target gets exactly one final answer."""
    rng = random.Random(7)
    moves = random_moves(rng, 200)
    executed, events, master = run_back_to_back(moves, rng, fail_rate=0.15, abort_rate=0.02,
                                                out_delay=1, in_delay=2, loop_every=(1, 30),
                                                accept_timeout=0.2)
    started = [cmd for cmd, _ in executed]
    assert len(started) == len(set(started))                         # targets are all distinct poses
    submitted = {}
    for e, _ in events:
        submitted.setdefault(e.seq, e.target)
    assert len(set(submitted.values())) == len(submitted)
    finals = {}
    for e, n_started in events:
        if e.final:
            assert e.seq not in finals
            finals[e.seq] = e
        if isinstance(e, (Accepted, Done)) and e.target.move_type is not WireMoveType.CIRC_VIA:
            # BUSY / DONE is only ever taken from this target's own motion, never an earlier one's
            assert e.target in started[:n_started], (e, "reported before the controller started it")
    assert sorted(finals) == list(range(1, master.seq + 1))
    kinds = {type(e).__name__ for e in finals.values()}
    assert {"Done", "Rejected", "Aborted", "TimedOut"} <= kinds       # every path was exercised
    order = {cmd: i for i, cmd in enumerate(started)}
    last = -1
    for e in sorted(finals.values(), key=lambda ev: ev.seq):          # execution follows submit order
        if e.target in order:
            assert order[e.target] > last
            last = order[e.target]
