"""Protocol v3 records (vr_driver.protocol.v3): golden bytes in both byte orders, round trips, every
field's range, the check word catching every single-byte corruption and the seq copy every torn
command, wrong versions and lengths, the seam object (ProtocolV3) and its stream_command, and the
measured target_error."""
from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vr_driver.errors import PoseError, ProtocolError
from vr_driver.poses import ControllerPose
from vr_driver.protocol import registry
from vr_driver.protocol.base import Protocol, WireTarget
from vr_driver.protocol.v1 import ByteOrder, StatusBits
from vr_driver.protocol import v2
from vr_driver.protocol.v3 import (ARMED_BIT, CHK_CFG_V3, COMMAND_SIZE_V3, EMPTY, FEEDBACK_SIZE_V3,
                                   GSD_MODULES_V3, SEQ_MAX, V3, CartesianKind, CartesianSlot, CommandV3,
                                   Control, FeedbackV3, ProtocolV3, RejectCode, StreamState, check_word,
                                   pose_from_wire, pose_to_wire)

ORDERS = ("little", "big")
INT16 = st.integers(-0x8000, 0x7FFF)


def words(raw: bytes, order: str):
    n = len(raw) // 2
    return struct.unpack(("<" if order == "little" else ">") + "%dH" % n, raw)


def weighted(raw: bytes, order: str = "little") -> int:
    """The check word by its definition: sum of (2k + 1) * word k, modulo 65536."""
    return sum((2 * k + 1) * w for k, w in enumerate(words(raw, order))) % 65536


def plain_sum(raw: bytes, order: str = "little") -> int:
    return sum(words(raw, order)) % 65536


# ------------------------------------------------------------------------------------ golden bytes

def test_golden_command_little_endian():
    slot = CartesianSlot(7, CartesianKind.MOVEP, 3, 500, (11200, -1, 7250, -18000, 4500, 17999))
    raw = CommandV3(Control.START, slot).encode()
    assert len(raw) == COMMAND_SIZE_V3 == 24
    assert raw[:2] == bytes([3, 2])                                    # version, START
    assert raw[2:8] == bytes([7, 0, 1, 3]) + struct.pack("<H", 500)   # seq, kind, smooth, speed
    assert raw[8:20] == struct.pack("<6h", 11200, -1, 7250, -18000, 4500, 17999)
    assert raw[20:22] == bytes([7, 0])                                # the seq again
    assert raw[22:] == struct.pack("<H", weighted(raw[:22]))
    assert CommandV3.decode(raw) == CommandV3(Control.START, slot)


def test_golden_command_big_endian_swaps_only_the_words():
    slot = CartesianSlot(0x0102, CartesianKind.MOVEL, 10, 1000, (1, 2, 3, -4, 5, -6))
    little = CommandV3(Control(0), slot).encode("little")
    big = CommandV3(Control(0), slot).encode(ByteOrder.BIG)
    assert big[:2] == little[:2] == bytes([3, 0])                     # single bytes stay put
    assert big[4:6] == little[4:6] == bytes([2, 10])
    assert big[2:4] == bytes([1, 2]) and little[2:4] == bytes([2, 1])
    assert big[8:20] == struct.pack(">6h", 1, 2, 3, -4, 5, -6)
    assert big[22:] == struct.pack(">H", weighted(big[:22], "big"))
    assert CommandV3.decode(big, "big") == CommandV3(Control(0), slot)
    with pytest.raises(ProtocolError):
        CommandV3.decode(big, "little")           # the check word is read (and summed) the wrong way


def test_golden_feedback_bytes():
    fb = FeedbackV3(StreamState.WAITING, StatusBits.DRIVES_POWERED | StatusBits.PROGRAM_RUNNING,
                    RejectCode.UNREACHABLE, 12, 10, 0, 13, (11200, 0, 7250, 0, 4500, -17999), 65535,
                    armed=True)
    raw = fb.encode()
    assert len(raw) == FEEDBACK_SIZE_V3 == 28
    assert raw[:4] == bytes([3, 3 | ARMED_BIT, 0x11, 4])                 # version, WAITING + armed, status, code
    assert raw[4:12] == struct.pack("<4H", 12, 10, 0, 13)
    assert raw[12:24] == struct.pack("<6h", 11200, 0, 7250, 0, 4500, -17999)
    assert raw[24:26] == b"\xff\xff"
    assert raw[26:] == struct.pack("<H", weighted(raw[:26]))
    assert FeedbackV3.decode(raw) == fb
    big = fb.encode("big")
    assert big[:4] == raw[:4] and big[12:24] == struct.pack(">6h", 11200, 0, 7250, 0, 4500, -17999)
    assert FeedbackV3.decode(big, "big") == fb


def test_idle_record_and_check_word_helper():
    raw = V3.idle_record()
    assert raw == bytes([3, 0]) + bytes(20) + bytes([3, 0])           # the check word of "version 3"
    assert V3.idle_record("big") == bytes([3, 0]) + bytes(20) + bytes([3, 0])
    assert check_word(bytes([3, 0]), "big") == 0x0300 and check_word(bytes([3, 0])) == 3
    assert V3.decode_command(raw) == CommandV3() == V3.idle_command()


# -------------------------------------------------------------------------------------- round trips

slots = st.one_of(st.just(EMPTY), st.builds(
    CartesianSlot, seq=st.integers(1, SEQ_MAX), kind=st.sampled_from([CartesianKind.MOVEP, CartesianKind.MOVEL]),
    smooth=st.integers(0, 10), speed=st.integers(1, 1000), values=st.tuples(*[INT16] * 6)))


@st.composite
def commands(draw):
    slot = draw(slots)
    if slot.empty:
        control = draw(st.sampled_from([Control(0), Control.STOP]))
    else:
        control = draw(st.sampled_from([Control(0), Control.START]))
    return CommandV3(control, slot)


feedbacks = st.builds(
    FeedbackV3, state=st.sampled_from(list(StreamState)), status=st.integers(0, 0x3F),
    reject_code=st.sampled_from(list(RejectCode)), accepted_seq=st.integers(0, SEQ_MAX),
    done_seq=st.integers(0, SEQ_MAX), active_seq=st.integers(0, SEQ_MAX), rejected_seq=st.integers(0, SEQ_MAX),
    tcp=st.tuples(*[INT16] * 6), heartbeat=st.integers(0, 0xFFFF), armed=st.booleans())


@settings(max_examples=150, deadline=None)
@given(command=commands(), order=st.sampled_from(ORDERS))
def test_command_round_trip(command, order):
    raw = V3.encode(command, order)
    assert len(raw) == V3.output_length
    assert V3.decode_command(raw, order) == command
    assert weighted(raw[:-2], order) == words(raw, order)[-1]


@settings(max_examples=150, deadline=None)
@given(fb=feedbacks, order=st.sampled_from(ORDERS))
def test_feedback_round_trip(fb, order):
    raw = V3.encode_feedback(fb, order)
    assert len(raw) == V3.input_length
    back = V3.decode_feedback(raw, order)
    assert back == fb and back.values == fb.tcp
    assert back.pose == pose_from_wire(fb.tcp)


@settings(max_examples=150, deadline=None)
@given(x=st.floats(-3276.7, 3276.7), y=st.floats(-3276.7, 3276.7), z=st.floats(-3276.7, 3276.7),
       rx=st.floats(-720, 720), ry=st.floats(-720, 720), rz=st.floats(-720, 720))
def test_pose_rounding_is_within_half_a_unit(x, y, z, rx, ry, rz):
    wire = pose_to_wire((x, y, z, rx, ry, rz))
    back = pose_from_wire(wire).as_tuple()
    for a, b in zip(back[:3], (x, y, z)):
        assert abs(a - b) <= 0.05 + 1e-9
    for a, b in zip(back[3:], (rx, ry, rz)):
        assert -180.0 < a <= 180.0
        assert abs((a - b + 180.0) % 360.0 - 180.0) <= 0.005 + 1e-9


def test_pose_rounding_halves_away_from_zero_and_wraps():
    assert pose_to_wire((0.05, -0.05, 0.15, 0.005, -0.005, 180.0)) == (1, -1, 2, 1, -1, 18000)
    assert pose_to_wire((0.25, -0.25, 0.04999, 0.125, -0.125, -179.995)) == (3, -3, 0, 13, -13, 18000)
    assert pose_to_wire((0, 0, 0, -180.0, 190.004, -359.996)) == (0, 0, 0, 18000, -17000, 0)
    assert pose_to_wire(ControllerPose(1120, 0, 725, 0, 45, 0)) == (11200, 0, 7250, 0, 4500, 0)


# -------------------------------------------------------------------------------------- field ranges

@pytest.mark.parametrize("index, name", [(0, "X"), (1, "Y"), (2, "Z")])
def test_pose_out_of_int16_names_the_field(index, name):
    pose = [0.0] * 6
    pose[index] = 3276.75                         # rounds to 32768
    with pytest.raises(PoseError, match=r"\A%s \[mm\] = 3276.75 does not fit" % name):
        pose_to_wire(pose)
    pose[index] = -3276.8                         # -32768 fits
    assert pose_to_wire(pose)[index] == -32768
    pose[index] = float("nan")
    with pytest.raises(PoseError, match=name):
        pose_to_wire(pose)


@pytest.mark.parametrize("index, name", [(3, "Rx"), (4, "Ry"), (5, "Rz")])
def test_angles_never_overflow_but_must_be_finite(index, name):
    pose = [0.0] * 6
    pose[index] = 1e6                             # wrapped first: always fits
    assert -18000 < pose_to_wire(pose)[index] <= 18000
    pose[index] = float("inf")
    with pytest.raises(PoseError, match=name):
        pose_to_wire(pose)


def test_pose_length():
    with pytest.raises(PoseError):
        pose_to_wire((1, 2, 3))


@pytest.mark.parametrize("field, value", [
    ("seq", -1), ("seq", 65536), ("seq", True), ("kind", 3), ("kind", 0), ("smooth", -1), ("smooth", 11),
    ("speed", 0), ("speed", 1001), ("speed", 1.5), ("values", (0, 0, 0, 0, 0, 32768)),
    ("values", (-32769, 0, 0, 0, 0, 0)), ("values", (0, 0, 0, 0, 0)), ("values", (0.5, 0, 0, 0, 0, 0)),
])
def test_slot_field_ranges(field, value):
    good = dict(seq=5, kind=CartesianKind.MOVEP, smooth=2, speed=100, values=(1, 2, 3, 4, 5, 6))
    CartesianSlot(**good)
    good[field] = value
    with pytest.raises(ProtocolError):
        CartesianSlot(**good)


def test_error_messages_name_the_field():
    with pytest.raises(ProtocolError, match="Rz"):
        CartesianSlot(5, 1, 0, 10, (0, 0, 0, 0, 0, 40000))
    with pytest.raises(ProtocolError, match="speed"):
        CartesianSlot(5, 1, 0, 0, (0,) * 6)
    with pytest.raises(ProtocolError, match="smooth"):
        CartesianSlot(5, 1, 11, 10, (0,) * 6)
    with pytest.raises(ProtocolError, match="empty slot"):
        CartesianSlot(0, 0, 0, 0, (1, 0, 0, 0, 0, 0))
    with pytest.raises(ProtocolError, match="no kind"):
        CartesianSlot(5, 0, 0, 10, (0,) * 6)


def test_command_rules():
    target = CartesianSlot(5, CartesianKind.MOVEP, 0, 10, (0,) * 6)
    for bad in (lambda: CommandV3(Control.START), lambda: CommandV3(Control.STOP, target),
                lambda: CommandV3(4), lambda: CommandV3(-1), lambda: CommandV3(Control.STOP | Control.START),
                lambda: CommandV3(0, "slot")):
        with pytest.raises(ProtocolError):
            bad()
    assert CommandV3(3 - 1, target).control is Control.START


@pytest.mark.parametrize("field, value", [
    ("state", 4), ("reject_code", 6), ("status", 0x40), ("status", -1), ("accepted_seq", 65536),
    ("done_seq", -1), ("active_seq", 1.0), ("rejected_seq", None), ("heartbeat", 65536),
    ("tcp", (0, 0, 0, 0, 0, 32768)), ("tcp", (0,) * 5), ("armed", 1),
])
def test_feedback_field_ranges(field, value):
    FeedbackV3()
    with pytest.raises(ProtocolError):
        FeedbackV3(**{field: value})


def _sealed(body: bytes, order: str = "little") -> bytes:
    return body + struct.pack(("<" if order == "little" else ">") + "H", weighted(body, order))


@pytest.mark.parametrize("byte, value, words_", [
    (1, 0x04, "state"), (1, 0x7C, "state"), (2, 0x40, "status"), (2, 0x80, "status"), (3, 9, "reject"),
])
def test_feedback_reserved_bits_refused_even_with_a_good_check_word(byte, value, words_):
    raw = bytearray(FeedbackV3().encode()[:-2])
    raw[byte] = value
    with pytest.raises(ProtocolError):
        FeedbackV3.decode(_sealed(bytes(raw)))


def test_command_bad_bytes_with_a_good_check_word_are_refused():
    good = CommandV3(Control(0), CartesianSlot(5, 1, 0, 10, (0,) * 6)).encode()[:-2]
    for index, value in ((1, 4), (4, 3), (5, 11), (6, 0)):      # control, kind, smooth, speed low byte
        raw = bytearray(good)
        raw[index] = value
        if index == 6:
            raw[7] = 0
        with pytest.raises(ProtocolError):
            CommandV3.decode(_sealed(bytes(raw)))


# -------------------------------------------------------------------------- versions and lengths

@pytest.mark.parametrize("order", ORDERS)
def test_wrong_version_or_length(order):
    cmd = CommandV3(Control(0), CartesianSlot(5, 1, 0, 10, (1, 2, 3, 4, 5, 6))).encode(order)
    fb = FeedbackV3(heartbeat=3).encode(order)
    for raw, decode in ((cmd, V3.decode_command), (fb, V3.decode_feedback)):
        with pytest.raises(ProtocolError, match="must be %d bytes" % len(raw)):
            decode(raw[:-1], order)
        with pytest.raises(ProtocolError, match="must be %d bytes" % len(raw)):
            decode(raw + b"\0", order)
        for version in (0, 1, 2, 4, 255):
            bad = bytes([version]) + raw[1:]
            with pytest.raises(ProtocolError, match="version byte %d" % version):
                decode(bad, order)
        with pytest.raises(ProtocolError):
            decode("not bytes", order)
        with pytest.raises(ProtocolError):
            decode(raw, "middle")
    with pytest.raises(ProtocolError):          # a v2 record (72 bytes) or v1 record (14) is no v3 record
        V3.decode_command(v2.CommandV2().encode())
    with pytest.raises(ProtocolError):
        V3.decode_feedback(bytes(14))
    with pytest.raises(ProtocolError):           # the card's safe image: all zero
        V3.decode_command(bytes(COMMAND_SIZE_V3))


# ----------------------------------------------------------------------------------- the check word

@pytest.mark.parametrize("order", ORDERS)
def test_check_word_catches_every_single_byte_corruption(order):
    records = [
        (CommandV3(Control.START, CartesianSlot(65535, 2, 10, 1000, (-32768, 32767, 0, -1, 1, 18000))).encode(order),
         V3.decode_command),
        (V3.idle_record(order), V3.decode_command),
        (FeedbackV3(StreamState.MOVING, 0x3F, 5, 65535, 1, 2, 3, (-32768, 32767, 0, -1, 1, 2), 0xFFFF,
                    True).encode(order), V3.decode_feedback),
        (FeedbackV3().encode(order), V3.decode_feedback),
    ]
    for raw, decode in records:
        decode(raw, order)
        for i in range(len(raw)):
            for flip in range(1, 256):
                bad = bytearray(raw)
                bad[i] ^= flip
                with pytest.raises(ProtocolError):
                    decode(bytes(bad), order)


def stream_records(order: str, n: int = 40):
    """Consecutive commands of a stream, as the driver changes them (with the speed falling by
    0.1 % while the seq rises by 1: the tear a plain sum misses)."""
    rng = random.Random(3)
    out = [V3.idle_record(order)]
    pose = [11200, 0, 7250, 0, 4500, 0]
    for i in range(n):
        pose = [v + rng.randint(-40, 40) for v in pose]
        slot = CartesianSlot(100 + i, CartesianKind.MOVEP, 3 if i < n - 1 else 0, 600 - i, tuple(pose))
        out.append(CommandV3(Control.START if i == 0 else Control(0), slot).encode(order))
    out.append(CommandV3(Control.STOP).encode(order))
    return out


@pytest.mark.parametrize("order", ORDERS)
def test_torn_commands_are_refused_or_are_one_of_the_two(order):
    """The front of one record and the back of the next (or the reverse), torn at every byte: never
    a target that neither record carries."""
    records = stream_records(order)
    torn_refused = 0
    for a, b in zip(records, records[1:]):
        for old, new in ((a, b), (b, a)):
            for cut in range(1, COMMAND_SIZE_V3):
                raw = new[:cut] + old[cut:]
                try:
                    cmd = V3.decode_command(raw, order)
                except ProtocolError:
                    torn_refused += 1
                    continue
                assert raw in (old, new), "torn record %s decoded as %s" % (raw.hex(" "), cmd.describe())
    assert torn_refused > 1000


def g2_check_word_16bit(raw: bytes, order: str) -> bytes:
    """doc/controller_program.md §10.3's recipe for a G2 with 16-bit signed integers: the low and the
    high byte of the weighted sum apart, every intermediate below 32768."""
    lo_first = order == "little"
    low = high = carry = 0
    for k in range(len(raw) // 2):
        lo, hi = (raw[2 * k], raw[2 * k + 1]) if lo_first else (raw[2 * k + 1], raw[2 * k])
        c = 2 * k + 1
        low = low + c * lo
        carry = carry + low // 256
        low = low % 256
        high = (high + c * hi) % 256
        assert max(low + c * 255, carry, high + c * 255) < 32768
    check_low, check_high = low, (high + carry) % 256
    return bytes([check_low, check_high]) if lo_first else bytes([check_high, check_low])


@settings(max_examples=100, deadline=None)
@given(command=commands(), fb=feedbacks, order=st.sampled_from(ORDERS))
def test_the_16_bit_recipe_gives_the_check_word(command, fb, order):
    for raw in (command.encode(order), fb.encode(order)):
        assert g2_check_word_16bit(raw[:-2], order) == raw[-2:]


def test_a_sum_alone_would_miss_such_a_tear():
    """Why the seq is carried twice: seq + 1 and speed - 1 leave a plain sum unchanged, so the front
    of the next target with the back of this one would pass it; the seq copy refuses it."""
    a = CommandV3(Control(0), CartesianSlot(7, 1, 3, 500, (100, 200, 300, 0, 0, 0))).encode()
    b = CommandV3(Control(0), CartesianSlot(8, 1, 3, 499, (900, 200, 300, 0, 0, 0))).encode()
    torn = b[:8] + a[8:]
    assert plain_sum(a[:-2]) == plain_sum(torn[:-2])
    with pytest.raises(ProtocolError, match="torn|check word"):
        V3.decode_command(torn)


@pytest.mark.parametrize("order", ORDERS)
def test_the_weights_catch_what_the_profibus_checksum_misses(order):
    """+d in one byte and -d in another keep the PROFIBUS FCS (a byte sum) -- and a plain sum of
    words when both bytes are the same half of their words. The odd weights catch all such pairs
    of low bytes (and all but a few of high bytes) in a command."""
    raw = CommandV3(Control(0), CartesianSlot(1234, 1, 3, 517, (11200, -345, 7250, 1234, 4500, -17999))).encode(order)
    low = [i for i in range(22) if (i % 2 == 0) == (order == "little")]      # the low byte of each word
    missed_plain = missed = total = 0
    for i in low:
        for j in low:
            if j <= i:
                continue
            for d in (1, 7, 100, 255):
                bad = bytearray(raw)
                bad[i], bad[j] = (bad[i] + d) % 256, (bad[j] - d) % 256
                assert sum(bad) % 256 == sum(raw) % 256                 # the FCS would pass it
                total += 1
                missed_plain += plain_sum(bytes(bad[:-2]), order) == plain_sum(raw[:-2], order)
                try:
                    V3.decode_command(bytes(bad), order)
                    missed += 1
                except ProtocolError:
                    pass
    assert missed == 0 and missed_plain > total // 2


# --------------------------------------------------------------------------------------- the seam

def test_seam_object():
    assert registry.get("v3") is V3 and isinstance(V3, ProtocolV3) and isinstance(V3, Protocol)
    assert "v3" in registry.names() and registry.names()[:2] == ("v1", "v2")
    assert V3.name == "v3" and V3.version == 3
    assert (V3.output_length, V3.input_length) == (24, 28)
    assert V3.record_length == 0                          # no single length: see input/output_length
    assert V3.streams and not V3.joint_targets and not V3.reports_joints and not V3.controller_io
    assert not V3.confirm_records and V3.byte_order_matters
    assert V3.pose_resolution == (0.1, 0.01) and V3.joint_resolution is None
    assert V3.look_ahead_slots == 1
    assert V3.chk_cfg == CHK_CFG_V3 == bytes.fromhex("17 17 17 13 27 27 27")
    assert V3.gsd_modules == GSD_MODULES_V3
    assert "24 bytes out, 28 bytes in" in V3.describe()
    assert V3.feedback_joints(FeedbackV3()) is None
    assert math.radians(0.05) < V3.default_goal_tolerance < math.radians(0.2)
    # the stream sequencer reads these FeedbackV2 names on any streaming protocol's feedback
    fb = FeedbackV3()
    for name in ("state", "status", "reject_code", "accepted_seq", "done_seq", "active_seq", "rejected_seq",
                 "heartbeat", "armed", "values", "pose"):
        assert hasattr(v2.FeedbackV2(), name) and hasattr(fb, name), name
    assert isinstance(fb.describe(), str)


def test_gsd_modules_match_the_chk_cfg_and_the_lengths():
    from pyprofibus_vendor.config import BusConfig, default_robot_config, find_gsd_file
    from pyprofibus_vendor.dp import cfg_io_lengths
    from pyprofibus_vendor.gsd import load_gsd
    gsd = load_gsd(find_gsd_file("PAN06C6.gsd"))
    assert b"".join(gsd.module(name).cfg for name in GSD_MODULES_V3) == CHK_CFG_V3
    assert cfg_io_lengths(CHK_CFG_V3) == (V3.input_length, V3.output_length)   # inputs = feedback
    assert len(GSD_MODULES_V3) <= gsd.module_limit
    # a bus configuration with these modules passes pyprofibus_vendor's GSD checks (what
    # params.bus() must build for v3: input_len 28, output_len 24)
    data = default_robot_config("/dev/null").to_dict()
    slave = data["slaves"][0]
    slave.pop("cfg", None)
    slave.update(modules=list(GSD_MODULES_V3), input_len=V3.input_length, output_len=V3.output_length)
    bus = BusConfig.from_dict(data)
    assert bus.slaves[0].cfg == CHK_CFG_V3
    assert (bus.slaves[0].input_len, bus.slaves[0].output_len) == (28, 24)


def data_exchange_bits(timing, input_len: int, output_len: int, tsdr: int) -> int:
    """Bits on the line for one Data_Exchange (doc/controller_program.md §10.6): the idle time TSYN
    before the request, the request SD2 telegram (9 characters of header and trailer + the outputs),
    the slave's response time, the response SD2 telegram (9 + the inputs); 11-bit characters."""
    return timing.tsyn_bits + 11 * (9 + output_len) + tsdr + 11 * (9 + input_len)


def test_wire_time_per_bus_cycle_with_the_io_island():
    """§10.6's figures from pyprofibus_vendor's BusTiming and the v3 line's bus config: at 19.2
    kbit/s the arm and the I/O island cycle at >= 15 Hz even at the slaves' largest response time."""
    import os
    from pyprofibus_vendor.config import load_config
    from pyprofibus_vendor.dp_master import BusTiming
    here = os.path.dirname(os.path.abspath(__file__))
    bus = load_config(os.path.join(os.path.dirname(here), "config", "io_line_bus_v3.yaml"))
    arm, island = bus.slaves
    assert (arm.input_len, arm.output_len, arm.cfg) == (V3.input_length, V3.output_length, CHK_CFG_V3)
    assert (island.input_len, island.output_len) == (2, 2)
    expected = {19200: (863, 1198), 93750: (863, 1198), 187500: (863, 1198)}
    for baud, (arm_bits, both_bits) in expected.items():
        t = BusTiming.for_baud(baud)
        assert (t.tsyn_bits, t.min_tsdr_bits, t.max_tsdr_bits) == (33, 11, 60)
        got_arm = data_exchange_bits(t, arm.input_len, arm.output_len, t.max_tsdr_bits)
        got_both = got_arm + data_exchange_bits(t, island.input_len, island.output_len, t.max_tsdr_bits)
        assert (got_arm, got_both) == (arm_bits, both_bits)
    rate = 19200 / 1198
    assert 15.0 <= rate < 16.1                        # 62.4 ms a cycle


def target(seq=5, pose=ControllerPose(1120, 0, 725, 0, 45, 0), speed=300, smooth=2):
    return WireTarget(seq, (0.0,) * 6, pose, speed, smooth)


def test_stream_command():
    cmd = V3.stream_command([target(5), target(6)], start=True)
    assert cmd.control is Control.START
    assert cmd.slot == CartesianSlot(5, CartesianKind.MOVEP, 2, 300, (11200, 0, 7250, 0, 4500, 0))
    assert V3.stream_command([target(9)]).control is Control(0)          # only the first target: one slot
    assert V3.stream_command([]) == CommandV3() == V3.stream_command((), start=True)
    assert V3.stream_command([target(5)], stop=True) == CommandV3(Control.STOP)
    with pytest.raises(ProtocolError, match="outputs"):
        V3.stream_command([target(5)], outputs=1)
    with pytest.raises(ProtocolError, match="no pose"):
        V3.stream_command([WireTarget(5, (0.0,) * 6, None, 10, 0)])
    with pytest.raises(PoseError, match="X"):
        V3.stream_command([target(pose=ControllerPose(4000, 0, 0, 0, 0, 0))])
    with pytest.raises(ProtocolError):
        V3.stream_command([target(speed=0)])
    assert V3.encode(V3.stream_command([target(5)]), "big") == V3.stream_command([target(5)]).encode("big")


def test_wire_pose_is_what_the_controller_gets():
    for pose in (ControllerPose(0.15, -0.25, 1e3, 0.005, -190.004, 180.0),
                 ControllerPose(1120.04, 0.05, 725.0, 359.995, 45.0049, -0.0051)):
        sent = V3.stream_command([target(1, pose)]).slot.controller_pose
        assert V3.wire_pose(pose) == sent
    assert V3.wire_pose(ControllerPose(0.15, 0, 0, 0, -190.004, 0)).as_tuple() == pytest.approx(
        (0.2, 0, 0, 0, 170.0, 0))


def test_target_error_bounds_the_rounding(kin):
    """A smaller sample of ProtocolV3.target_error's measurement: away from singularities (smallest
    singular value of the Jacobian >= 0.05) and >= 1 deg from the joint limits, the rounding of a
    target to 0.1 mm / 0.01 deg moves the controller's IK solution by less than target_error."""
    rng = random.Random(11)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    worst, n = 0.0, 0
    while n < 300:
        q = kin.random_joints(rng)
        if min(np.min(np.array(q) - lo), np.min(hi - np.array(q))) < math.radians(1.0):
            continue
        if np.linalg.svd(kin.jacobian(q), compute_uv=False).min() < 0.05:
            continue
        sent = pose_from_wire(pose_to_wire(kin.fk_pose(q)))
        solved = kin.ik_pose(sent, seed=q)
        worst = max(worst, max(abs(a - b) for a, b in zip(q, solved)))
        n += 1
    assert 0.0 < worst < V3.target_error
