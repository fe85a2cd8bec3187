"""The virtual G2 controller's protocol v3 program (controller.program_v3.ControllerProgramV3):
Cartesian targets, one per record, into a ring; the controller's own IK; MOVEP joint moves on a
SimStreamArm whose look-ahead is the interpreter look-ahead. Stepped with a fake clock in one thread,
as test_controller_v2.py: CommandV3 records go into the robot DpSlave in Data_Exchange telegrams,
FeedbackV3 comes back in the replies. Nothing sleeps."""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np
import pytest

from pyprofibus_vendor.dp_slave import SlaveState

from vr_driver.controller.arm import Outcome
from vr_driver.controller.cli import main
from vr_driver.controller.options import SimOptions
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import robot_slave, VirtualController
from vr_driver.controller.program_v2 import ControllerProgramV2
from vr_driver.controller.program_v3 import (DEFAULT_INTERPRETER_LOOKAHEAD, DEFAULT_RING_SIZE,
                                             ControllerProgramV3)
from vr_driver.controller.stream_arm import SimStreamArm
from vr_driver.errors import MotionError, ProtocolError
from vr_driver.kinematics.solver import Kinematics
from vr_driver.poses import ControllerPose
from vr_driver.protocol.v1 import StatusBits
from vr_driver.protocol.v3 import (CHK_CFG_V3, CartesianKind, CartesianSlot, CommandV3, Control,
                                   FeedbackV3, RejectCode, StreamState, pose_from_wire, pose_to_wire)

from _slave_rig import StreamRig

PERIOD = 0.005
START_JOINTS = (0.0, 0.4, -0.3, 0.0, 0.6, 0.0)
BRAKE = 0.2


class RigV3(StreamRig):
    """Fake clock + v3 robot DpSlave + SimStreamArm (look-ahead = the interpreter's) +
    ControllerProgramV3, and a minimal DP master sending ``self.record`` every bus cycle. With
    ``stream`` set, the master offers the first target the controller has not taken (by the
    accepted_seq of the feedback it last received), START on the stream's first."""

    def __init__(self, kin, *, lookahead: int = 1, ring: int = 4, order: str = "little",
                 controller_kin: Optional[Kinematics] = None, confirm: bool = False,
                 period: float = PERIOD, watchdog_units: int = 10, brake_time: float = BRAKE,
                 start_joints: Sequence[float] = START_JOINTS) -> None:
        super().__init__(period, watchdog_units)
        self.order = order
        self.slave = robot_slave(4, self.clock, "v3")
        self.arm = SimStreamArm(kin, clock=self.clock, brake_time=brake_time, initial_joints=start_joints,
                                look_ahead=lookahead)
        self.prog = ControllerProgramV3(self.slave, self.arm, kinematics=controller_kin or kin, ring_size=ring,
                                        byte_order=order, confirm_records=confirm)
        self.record = CommandV3()
        self.occupancy_seen: List[int] = []      # targets in the ring, each loop
        self.read_ahead_seen: List[int] = []     # targets the arm holds (running + read ahead), each loop

    def encode(self, record: CommandV3) -> bytes:
        return record.encode(self.order)

    def decode(self, data: bytes) -> FeedbackV3:
        return FeedbackV3.decode(data, self.order)

    def streamed_record(self) -> CommandV3:
        i = self.accepted_index()
        if i >= len(self.stream):
            return CommandV3()
        return CommandV3(Control.START if i == 0 else Control(0), self.stream[i])

    def observe(self) -> None:
        self.occupancy_seen.append(self.prog.occupancy)
        self.read_ahead_seen.append(len(self.arm.queued))


def zigzag(n: int = 9) -> List[Tuple[float, ...]]:
    """n joint points after START_JOINTS (J1 advances, J2 zig-zags: a corner at every point)."""
    q0 = START_JOINTS
    return [(q0[0] + 0.12 * i, q0[1] + (0.08 if i % 2 else 0.0), q0[2] - 0.03 * i, 0.02 * i, q0[4], 0.05 * i)
            for i in range(1, n + 1)]


def target(kin, seq: int, joints, speed: int = 500, smooth: int = 0, kind=CartesianKind.MOVEP) -> CartesianSlot:
    """A MOVEP to the pose of these joints (FK), rounded as the wire carries it."""
    return CartesianSlot.from_pose(seq, kin.fk_pose(joints), speed, smooth, kind)


def stream_of(kin, pts, speed: int = 500, smooth: int = 3, first: int = 1) -> List[CartesianSlot]:
    return [target(kin, first + i, q, speed, smooth if i < len(pts) - 1 else 0) for i, q in enumerate(pts)]


def pose_error(kin, joints, slot: CartesianSlot) -> Tuple[float, float]:
    """(mm, deg): how far the TCP at ``joints`` is from the slot's pose."""
    at = kin.fk_pose(joints).as_tuple()
    want = slot.controller_pose.as_tuple()
    return (max(abs(a - b) for a, b in zip(at[:3], want[:3])),
            max(abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(at[3:], want[3:])))


def stops(trace, since: float = -math.inf) -> int:
    """How often the arm came (nearly) to rest between its first and its last motion: runs of loops
    whose joint-space speed is below 5 % of the path's top speed (a stop and a restart within one
    loop leave no loop at exactly 0)."""
    speeds = [float(np.linalg.norm(np.subtract(q1, q0))) / (t1 - t0)
              for (t0, _, q0), (t1, _, q1) in zip(trace, trace[1:]) if t1 > since]
    slow = [v < 0.05 * max(speeds) for v in speeds]
    if False not in slow:
        return 0
    first, last = slow.index(False), len(slow) - 1 - slow[::-1].index(False)
    inner = slow[first:last + 1]
    return sum(1 for a, b in zip(inner, inner[1:]) if b and not a)


@pytest.fixture
def rig(kin):
    r = RigV3(kin)
    r.connect()
    return r


# --------------------------------------------------------------------------------- exactly once

def test_each_target_taken_once_and_logged_with_its_cartesian_target(rig, kin):
    pts = zigzag(5)
    stream = stream_of(kin, pts, 800)
    fb = rig.run_stream(stream)
    rig.loop(40)                                        # the master keeps repeating its last record
    entries = rig.prog.log.entries()
    assert [e.seq for e in entries] == [1, 2, 3, 4, 5]
    assert [e.outcome for e in entries] == [Outcome.BLENDED] * 4 + [Outcome.EXECUTED]
    assert [e.target for e in entries] == [s.pose for s in stream]        # as on the wire
    assert all(e.move_type == "MOVEP" and e.to_dict()["target"] == list(s.pose) for e, s in zip(entries, stream))
    assert fb.accepted_seq == 5 and fb.done_seq == 5 and fb.rejected_seq == 0 and fb.armed
    # the controller's IK solved the rounded pose near the planned joints: the arm ends within
    # ProtocolV3.target_error of the plan, and its TCP on the pose as sent
    assert max(abs(a - b) for a, b in zip(rig.arm.joints, pts[-1])) < math.radians(0.07)
    mm, deg = pose_error(kin, rig.arm.joints, stream[-1])
    assert mm < 1e-6 and deg < 1e-6
    assert fb.values == pose_to_wire(kin.fk_pose(rig.arm.joints)) and fb.pose == pose_from_wire(fb.values)
    # a stale record (the first target again, with START) is ignored: nothing moves
    rig.stream = []
    rig.record = CommandV3(Control.START, stream[0])
    before = rig.arm.joints
    rig.loop(20)
    assert rig.arm.joints == before and len(rig.prog.log) == 5 and rig.prog.rejected_seq == 0


def test_a_full_ring_makes_the_slot_wait(kin):
    rig = RigV3(kin, lookahead=0, ring=2)
    rig.connect()
    pts = zigzag(5)
    stream = stream_of(kin, pts, 300)
    rig.record = CommandV3(Control.START, stream[0])
    fb = rig.until(lambda fb: fb.accepted_seq == 1)
    rig.record = CommandV3(Control(0), stream[1])
    fb = rig.until(lambda fb: fb.accepted_seq == 2)
    rig.record = CommandV3(Control(0), stream[2])
    fb = rig.loop(10)
    assert fb.accepted_seq == 2 and fb.rejected_seq == 0 and fb.done_seq == 0       # waits, not refused
    assert rig.prog.occupancy == 2 and len(rig.prog.ring) == 1                      # 1 in the arm, 2 in the ring
    fb = rig.until(lambda fb: fb.accepted_seq == 3)
    assert fb.done_seq == 1                                  # taken as soon as target 1 left the ring
    fb = rig.run_stream(stream)
    assert max(rig.occupancy_seen) == 2 and fb.rejected_seq == 0
    assert [e.seq for e in rig.prog.log.entries()] == [1, 2, 3, 4, 5]


def test_the_ring_fills_to_its_size_while_the_arm_runs(kin):
    rig = RigV3(kin, lookahead=1, ring=4)
    rig.connect()
    fb = rig.run_stream(stream_of(kin, zigzag(8), 200))
    assert max(rig.occupancy_seen) == 4 and fb.done_seq == 8


def test_out_of_order_is_refused_once(rig, kin):
    """One number ahead (the master sends the next target before the acknowledgement of the one
    before it, protocol.send_ahead) waits, neither taken nor refused; further ahead is refused once."""
    pts = zigzag(5)
    rig.record = CommandV3(Control.START, target(kin, 1, pts[0], 800, 5))
    rig.until(lambda fb: fb.accepted_seq == 1)
    rig.record = CommandV3(Control(0), target(kin, 3, pts[2], 800, 5))           # 2 not taken yet
    fb = rig.loop(20)
    assert fb.accepted_seq == 1 and fb.rejected_seq == 0                        # it waits
    rig.record = CommandV3(Control(0), target(kin, 4, pts[3], 800, 5))           # 2 and 3 skipped
    fb = rig.until(lambda fb: fb.rejected_seq == 4)
    assert fb.reject_code is RejectCode.OUT_OF_ORDER and fb.accepted_seq == 1
    fb = rig.until(lambda fb: fb.state is StreamState.WAITING, 10.0)           # no guess past point 1
    assert fb.done_seq == 1
    rejected = [e for e in rig.prog.log.entries() if e.outcome is Outcome.REJECTED]
    assert [(e.seq, e.reject_code, e.move_type) for e in rejected] == [(4, 1, "MOVEP")]    # once
    rig.record = CommandV3(Control(0), target(kin, 2, pts[1], 800, 0))
    rig.until(lambda fb: fb.done_seq == 2 and not rig.arm.moving)
    rig.record = CommandV3(Control(0), target(kin, 3, pts[2], 800, 0))           # now the next one
    rig.until(lambda fb: fb.done_seq == 3 and not rig.arm.moving)
    assert sorted((e.seq, e.outcome.value) for e in rig.prog.log.entries()) == [
        (1, "executed"), (2, "executed"), (3, "executed"), (4, "rejected")]


def test_a_new_stream_begins_with_start(rig, kin):
    fb = rig.loop(3)
    rig.record = CommandV3(Control(0), target(kin, 1, zigzag(1)[0]))
    fb = rig.loop(3)
    assert fb.rejected_seq == 1 and fb.reject_code is RejectCode.OUT_OF_ORDER and not rig.arm.moving
    rig.record = CommandV3(Control.START, target(kin, 1, zigzag(1)[0]))
    fb = rig.loop(2)
    assert fb.accepted_seq == 1 and rig.arm.moving


# ------------------------------------------------------------------------------ STOP, link loss

def test_stop_brakes_and_drops_the_ring(kin):
    rig = RigV3(kin, lookahead=1, ring=4)
    rig.connect()
    stream = stream_of(kin, zigzag(6), 150)
    rig.stream = stream
    fb = rig.until(lambda fb: fb.accepted_seq == 4 and fb.active_seq == 1)
    assert rig.prog.occupancy == 4 and len(rig.prog.ring) == 2        # 1 active + 1 read ahead + 2 in the ring
    rig.stream = []
    rig.record = CommandV3(Control.STOP)
    fb = rig.loop()
    assert fb.state is StreamState.STOPPING and fb.status & StatusBits.IN_MOTION
    assert rig.prog.occupancy == 1 and not rig.prog.ring                # only the target braked on
    fb = rig.until(lambda fb: fb.state is StreamState.IDLE, 2.0)
    assert fb.accepted_seq == 4 and fb.done_seq == 0
    entries = rig.prog.log.entries()
    assert [e.seq for e in entries] == [2, 3, 4, 1]                     # the dropped ones, then the braked one
    assert all(e.outcome is Outcome.STOPPED for e in entries)
    assert all(e.start_time is None and "dropped before it started: STOP" in e.reason for e in entries[:3])
    assert [e.target for e in entries[:3]] == [s.pose for s in stream[1:4]]
    # the stream may go on with accepted_seq + 1
    rig.record = CommandV3(Control(0), stream[4])
    fb = rig.until(lambda fb: fb.done_seq == 5 and not rig.arm.moving)
    assert pose_error(kin, rig.arm.joints, stream[4])[0] < 1e-6


def test_a_link_loss_brakes_drops_the_ring_and_disarms(kin):
    rig = RigV3(kin, watchdog_units=10)                   # 100 ms
    rig.connect()
    pts = zigzag(6)
    stream = stream_of(kin, pts, 100, 5)
    rig.stream = stream
    rig.until(lambda fb: fb.active_seq == 2 and fb.accepted_seq == 5)
    rig.exchanging = False                               # the master goes silent
    fb = rig.until(lambda fb: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
    assert fb.state is StreamState.STOPPING and not rig.prog.ring
    fb = rig.until(lambda fb: fb.state is StreamState.IDLE, 2.0)
    assert rig.prog.link_losses == 1 and rig.prog.need_start and not rig.prog.armed and not fb.armed
    by_seq = {e.seq: e for e in rig.prog.log.entries()}
    assert sorted(by_seq) == [1, 2, 3, 4, 5] and len(rig.prog.log) == 5
    assert by_seq[1].outcome is Outcome.BLENDED
    assert by_seq[2].outcome is Outcome.STOPPED and "watchdog" in by_seq[2].reason
    assert all(by_seq[s].start_time is None and "watchdog" in by_seq[s].reason for s in (3, 4, 5))
    stopped_at = rig.arm.joints
    # reconnected, the old record again: a new seq before an empty record -> NOT_ARMED, nothing moves
    rig.exchanging = True
    rig.stream = []
    rig.record = CommandV3(Control(0), stream[5])
    rig.connect()
    fb = rig.loop(10)
    assert fb.rejected_seq == 6 and fb.reject_code is RejectCode.NOT_ARMED and rig.arm.joints == stopped_at
    rig.record = CommandV3()
    fb = rig.loop(2)
    assert fb.armed
    rig.record = CommandV3(Control(0), stream[5])
    fb = rig.loop(3)
    assert fb.reject_code is RejectCode.OUT_OF_ORDER and rig.arm.joints == stopped_at   # needs START
    rig.record = CommandV3(Control.START, stream[5])
    rig.until(lambda fb: fb.done_seq == 6 and not rig.arm.moving)
    assert pose_error(kin, rig.arm.joints, stream[5])[0] < 1e-6


def test_a_fault_drops_the_ring_and_refuses_with_code_3(kin):
    rig = RigV3(kin, ring=4)
    rig.connect()
    stream = stream_of(kin, zigzag(6), 150)
    rig.stream = stream
    rig.until(lambda fb: fb.accepted_seq == 4)
    rig.arm.set_estop(True)
    fb = rig.loop(3)
    assert not rig.arm.moving and not rig.prog.ring and rig.prog.occupancy == 0
    assert fb.rejected_seq == 5 and fb.reject_code is RejectCode.FAULT and fb.status & StatusBits.ESTOP
    outcomes = sorted((e.seq, e.outcome.value) for e in rig.prog.log.entries())
    assert outcomes == [(1, "stopped"), (2, "stopped"), (3, "stopped"), (4, "stopped"), (5, "rejected")]


# ---------------------------------------------------------------------- the interpreter look-ahead

def run_path(kin, lookahead: int, smooth: int = 5, n: int = 8, speed: int = 500):
    rig = RigV3(kin, lookahead=lookahead, period=0.002)
    rig.connect()
    t0 = rig.t
    fb = rig.run_stream(stream_of(kin, zigzag(n), speed, smooth))
    return rig, fb, t0


def test_lookahead_0_stops_at_every_point_and_ignores_smooth(kin):
    rig, fb, t0 = run_path(kin, lookahead=0)
    entries = rig.prog.log.entries()
    assert [e.outcome for e in entries] == [Outcome.EXECUTED] * 8          # reached, never blended
    assert stops(rig.trace, t0) == 7                                        # at each of the 7 inner points
    assert fb.done_seq == 8 and max(rig.occupancy_seen) == 4 and max(rig.read_ahead_seen) == 1


def test_lookahead_1_blends_without_a_stop_between_the_points(kin):
    rig, fb, t0 = run_path(kin, lookahead=1)
    entries = rig.prog.log.entries()
    assert [e.outcome for e in entries] == [Outcome.BLENDED] * 7 + [Outcome.EXECUTED]
    assert stops(rig.trace, t0) == 0 and max(rig.read_ahead_seen) == 2
    slow, _, _ = run_path(kin, lookahead=0)
    assert rig.t < slow.t                                  # and it is faster than stopping at each


def test_lookahead_2_blends_too(kin):
    rig, fb, t0 = run_path(kin, lookahead=2)
    assert stops(rig.trace, t0) == 0 and fb.done_seq == 8
    assert max(rig.read_ahead_seen) == 3 and max(rig.occupancy_seen) == 4


def test_smooth_0_stops_even_with_lookahead(kin):
    rig, fb, t0 = run_path(kin, lookahead=1, smooth=0)
    assert stops(rig.trace, t0) == 7


# -------------------------------------------------------------------------- refusals of a target

def test_an_unreachable_pose_is_refused_with_code_4(rig):
    far = CartesianSlot.from_pose(1, ControllerPose(3000, 0, 500, 0, 90, 0), 500)
    rig.record = CommandV3(Control.START, far)
    fb = rig.loop(5)
    assert fb.rejected_seq == 1 and fb.reject_code is RejectCode.UNREACHABLE and fb.accepted_seq == 0
    assert not rig.arm.moving
    (entry,) = rig.prog.log.entries()
    assert entry.outcome is Outcome.REJECTED and entry.target == far.pose and "unreachable" in entry.reason


def test_movel_is_refused_with_code_5(rig, kin):
    rig.record = CommandV3(Control.START, target(kin, 1, zigzag(1)[0], kind=CartesianKind.MOVEL))
    fb = rig.loop(3)
    assert fb.rejected_seq == 1 and fb.reject_code is RejectCode.BAD_SLOT and not rig.arm.moving
    assert rig.prog.log.entries()[0].move_type == "MOVEL"


def test_a_corrupted_or_torn_record_is_ignored_and_counted(rig, kin):
    good = CommandV3(Control.START, target(kin, 1, zigzag(1)[0])).encode()
    other = CommandV3(Control.START, target(kin, 2, zigzag(2)[1])).encode()
    bad = []
    for index in (0, 1, 3, 9, 20, 23):                  # version, control, seq, pose, seq copy, check
        raw = bytearray(good)
        raw[index] ^= 0x10
        bad.append(bytes(raw))
    bad.append(other[:10] + good[10:])                 # torn between two records
    for raw in bad:
        fb = rig.send_raw(raw)
        assert fb.accepted_seq == 0 and not rig.arm.moving
    assert rig.prog.bad_records == len(bad) and len(rig.prog.log) == 0
    fb = rig.send_raw(good)
    assert fb.accepted_seq == 1 and rig.arm.moving


def test_the_ik_seed_is_the_previous_target_then_the_arm(kin):
    """J6 turns +-360 deg: a pose is reached with J6 = a and with a -+ 2 pi. The controller picks
    the solution nearest the joints of the previous target still in the ring (not the arm's, which
    still stand near J6 = 0), and the arm's when none is."""
    base = (0.0, 0.4, -0.3, 0.0, 0.6)
    rig = RigV3(kin, lookahead=1)
    rig.connect()
    rig.run_stream([target(kin, 1, base + (2.0,), 200, 3), target(kin, 2, base + (3.5,), 200, 0)])
    assert abs(rig.arm.joints[5] - 3.5) < 1e-3           # seeded by target 1 (J6 2.0); the arm's 0 gives 3.5 - 2 pi
    # a stream stopped early: the ring is empty, so the seed is where the arm stopped (J6 ~ 0.4),
    # not the newest target taken (J6 3.5 would give -1.5 + 2 pi)
    rig = RigV3(kin, lookahead=1)
    rig.connect()
    rig.stream = [target(kin, 1, base + (2.0,), 100, 3), target(kin, 2, base + (3.5,), 100, 0)]
    rig.until(lambda fb: fb.accepted_seq == 2 and 0.3 < rig.arm.joints[5])
    rig.stream = []
    rig.record = CommandV3(Control.STOP)
    rig.until(lambda fb: fb.state is StreamState.IDLE)
    stopped = rig.arm.joints[5]
    assert 0.3 < stopped < 1.0
    rig.record = CommandV3(Control.START, target(kin, 3, base + (-1.5,), 200, 0))
    rig.until(lambda fb: fb.done_seq == 3 and not rig.arm.moving)
    assert abs(rig.arm.joints[5] + 1.5) < 1e-3


def shifted_kinematics(dz: float, tmp_path) -> Kinematics:
    """The model with the upper arm (joint_2 -> joint_3) ``dz`` metres longer: a true-model file
    (panasonic_vr006l_support.true_model) of the model's numbers with that change."""
    import yaml
    from panasonic_vr006l_support.description import default_kinematics_yaml
    with open(default_kinematics_yaml()) as f:
        tree = yaml.safe_load(f)
    tree["geometry"]["upper_arm"]["value"] += dz
    path = tmp_path / "upper_arm.yaml"
    path.write_text(yaml.safe_dump(tree))
    return Kinematics.from_true_model(str(path))


def test_the_controller_solves_with_its_own_kinematics(kin, tmp_path):
    """A G2 whose model differs from the robot's (upper arm 5 mm longer): it solves the pose with
    its own IK, and the arm (the real robot) lands off the pose by about that much."""
    own = shifted_kinematics(0.005, tmp_path)
    stream = stream_of(kin, zigzag(2), 500, 0)
    exact = RigV3(kin)
    exact.connect()
    exact.run_stream(stream)
    assert pose_error(kin, exact.arm.joints, stream[-1])[0] < 1e-6
    off = RigV3(kin, controller_kin=own)
    off.connect()
    off.run_stream(stream)
    mm, _ = pose_error(kin, off.arm.joints, stream[-1])
    assert 1.0 < mm < 10.0
    assert pose_error(own, off.arm.joints, stream[-1])[0] < 1e-6      # exact in the controller's model


# ------------------------------------------------------------------------- byte order, confirmation

def test_big_endian_program(kin):
    rig = RigV3(kin, order="big")
    rig.connect()
    fb = rig.run_stream(stream_of(kin, zigzag(3), 800))
    assert fb.done_seq == 3 and rig.prog.bad_records == 0
    assert FeedbackV3.decode(rig.slave.inputs, "big") == fb
    with pytest.raises(ProtocolError):
        FeedbackV3.decode(rig.slave.inputs, "little")
    # a little-endian master is refused record by record (the check word is summed the other way)
    fb = rig.send_raw(CommandV3(Control(0), target(kin, 4, zigzag(4)[3])).encode("little"))
    assert rig.prog.bad_records == 1 and fb.accepted_seq == 3


@pytest.mark.parametrize("confirm", [False, True])
def test_confirm_records_is_an_option(kin, confirm):
    rig = RigV3(kin, confirm=confirm)
    rig.connect()
    rig.loop(2)
    once = CommandV3(Control.START, target(kin, 1, zigzag(1)[0])).encode()
    if confirm:
        assert rig.send_raw(once).accepted_seq == 0
        assert rig.send_raw(CommandV3().encode()).accepted_seq == 0
        assert rig.send_raw(once).accepted_seq == 0
        assert rig.send_raw(once).accepted_seq == 1          # the second equal telegram
    else:
        assert rig.send_raw(once).accepted_seq == 1          # the check word does the rule's job


def test_feedback_heartbeat_and_pose(rig, kin):
    a = rig.loop()
    b = rig.loop()
    assert b.heartbeat == (a.heartbeat + 1) % 65536
    assert b.values == pose_to_wire(kin.fk_pose(START_JOINTS)) and b.status & StatusBits.PROGRAM_RUNNING
    assert FeedbackV3.decode(rig.slave.inputs) == b


# ----------------------------------------------------------------------- options, slave, CLI

def test_program_options_are_checked(kin):
    slave = robot_slave(4, protocol="v3")
    assert slave.cfg == CHK_CFG_V3 and (slave.input_size, slave.output_size) == (28, 24)
    arm = SimStreamArm(kin, look_ahead=0)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(MotionError):
            ControllerProgramV3(robot_slave(4, protocol="v3"), arm, kinematics=kin, ring_size=bad)
    for bad in (-1, 1.0, True):
        with pytest.raises(MotionError):
            SimStreamArm(kin, look_ahead=bad)
    assert SimStreamArm(kin).look_ahead == 1                  # v2's queue of two, unchanged


def test_virtual_controller_v3(kin):
    assert SimOptions().interpreter_lookahead == DEFAULT_INTERPRETER_LOOKAHEAD == 1
    assert SimOptions().ring_size == DEFAULT_RING_SIZE == 4
    o = SimOptions.from_mapping({"protocol": "v3", "interpreter_lookahead": "0", "ring_size": 8})
    assert (o.protocol, o.interpreter_lookahead, o.ring_size) == ("v3", 0, 8)
    for bad in ({"interpreter_lookahead": -1}, {"interpreter_lookahead": 1.5}, {"ring_size": 0}):
        with pytest.raises(SimError):
            SimOptions.from_mapping(bad)
    assert main(["--protocol", "v3", "--interpreter-lookahead", "-2"]) == 2
    assert main(["--protocol", "v3", "--ring-size", "0"]) == 2
    vc = VirtualController(kinematics=kin, protocol="v3", interpreter_lookahead=0, ring_size=3,
                           controller_kinematics=kin, byte_order="big")
    try:
        assert isinstance(vc.program, ControllerProgramV3) and isinstance(vc.program, ControllerProgramV2)
        assert vc.arm.look_ahead == 0 and vc.program.ring_size == 3 and vc.program.kin is kin
        assert vc.slave.cfg == CHK_CFG_V3 and not vc.program.confirm_records
        fb = vc.step()
        assert isinstance(fb, FeedbackV3) and fb.state is StreamState.IDLE
        assert FeedbackV3.decode(vc.slave.inputs, "big") == fb
    finally:
        vc.stop()
    vc = VirtualController(kinematics=kin, protocol="v2", interpreter_lookahead=0)
    try:
        assert vc.arm.look_ahead == 1 and type(vc.program) is ControllerProgramV2   # v2 unchanged
    finally:
        vc.stop()
