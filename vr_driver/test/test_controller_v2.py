"""The virtual G2 controller's protocol v2 program (controller.program_v2.ControllerProgramV2) and its
streaming arm (controller.stream_arm.SimStreamArm), stepped with a fake clock in one thread: CommandV2 records
go straight into the robot DpSlave (Data_Exchange telegrams, as test_controller_sim.py does for v1),
FeedbackV2 comes back in the replies. Nothing sleeps; times and speeds are the fake clock's, exact."""
from __future__ import annotations

from typing import List, Optional, Tuple

import numpy as np
import pytest

from pyprofibus_vendor.dp_slave import SlaveState

from vr_driver.controller.cli import main
from vr_driver.controller.options import SimOptions
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import robot_slave, VirtualController
from vr_driver.controller.program_v2 import ControllerProgramV2
from vr_driver.protocol.v1 import StatusBits
from vr_driver.protocol.v2 import (CHK_CFG_V2, RECORD_SIZE_V2, CommandV2, Control, FeedbackV2, RejectCode,
                                   StreamState, TargetSlot, joints_from_wire, joints_to_wire)
from vr_driver.controller.arm import Outcome
from vr_driver.controller.stream_arm import (DEFAULT_RAMP_TIME, SimStreamArm, blend_window, segment_time, wire_pose)

from _slave_rig import StreamRig

PERIOD = 0.005
START_JOINTS = (0.0, 0.4, -0.3, 0.0, 0.6, 0.0)
BRAKE = 0.2


class RigV2(StreamRig):
    """Fake clock + v2 robot DpSlave + SimStreamArm + ControllerProgramV2, and a minimal DP master
    sending ``self.record`` every bus cycle (one Data_Exchange per program loop). With ``stream``
    set, the master streams those targets: slot 0 = the first one the controller has not taken
    (by the accepted_seq of the feedback it last received), slot 1 = the one after it (look-ahead),
    START on the stream's first target."""

    def __init__(self, kin, period: float = PERIOD, speed: float = 1.0, watchdog_units: int = 10,
                 brake_time: float = BRAKE, confirm: bool = False) -> None:
        super().__init__(period, watchdog_units)
        self.slave = robot_slave(4, self.clock, "v2")
        self.arm = SimStreamArm(kin, speed_factor=speed, clock=self.clock, brake_time=brake_time,
                                initial_joints=START_JOINTS)
        self.prog = ControllerProgramV2(self.slave, self.arm, confirm_records=confirm)
        self.record = CommandV2()
        self.lookahead = True
        self.withhold: Optional[int] = None       # stream only up to (excluding) this seq

    def encode(self, record: CommandV2) -> bytes:
        return record.encode()

    def decode(self, data: bytes) -> FeedbackV2:
        return FeedbackV2.decode(data)

    def streamed_record(self) -> CommandV2:
        i = self.accepted_index()
        slots = [s for s in self.stream[i:i + (2 if self.lookahead else 1)]
                 if self.withhold is None or s.seq < self.withhold]
        if not slots:
            return CommandV2()
        return CommandV2(Control.START if i == 0 else Control(0), slots[0],
                         slots[1] if len(slots) > 1 else TargetSlot())


def slot(seq: int, joints, speed: float = 0.5, smooth: int = 0) -> TargetSlot:
    return TargetSlot.joint_target(seq, joints, speed, smooth)


def zigzag(n: int = 9) -> List[Tuple[float, ...]]:
    """n points after START_JOINTS: J1 advances, J2 zig-zags (a corner at every point)."""
    q0 = START_JOINTS
    return [(q0[0] + 0.12 * i, q0[1] + (0.08 if i % 2 else 0.0), q0[2] - 0.03 * i, 0.02 * i, q0[4], 0.05 * i)
            for i in range(1, n + 1)]


def wire_exact(joints) -> Tuple[float, ...]:
    return joints_from_wire(joints_to_wire(joints))


def speeds(trace) -> List[Tuple[float, float]]:
    """(time, joint-space speed [rad/s]) by finite differences of the exact joints."""
    return [(t1, float(np.linalg.norm(np.subtract(q1, q0))) / (t1 - t0))
            for (t0, _, q0), (t1, _, q1) in zip(trace, trace[1:])]


def move_time(a, b, fraction: float, kin) -> float:
    return max(abs(y - x) / (fraction * v) for x, y, v in zip(a, b, kin.limits.velocity))


@pytest.fixture
def rig(kin):
    r = RigV2(kin)
    r.connect()
    return r


# --------------------------------------------------------------------------------- exactly once

def test_each_target_taken_once_repeats_ignored(rig):
    pts = zigzag(4)
    stream = [slot(i + 1, q, 0.8, smooth=3 if i < 3 else 0) for i, q in enumerate(pts)]
    fb = rig.run_stream(stream)
    rig.loop(40)                                        # the master keeps repeating its last record
    entries = rig.prog.log.entries()
    assert [e.seq for e in entries] == [1, 2, 3, 4]
    assert [e.outcome for e in entries] == [Outcome.BLENDED] * 3 + [Outcome.EXECUTED]
    assert fb.accepted_seq == 4 and fb.done_seq == 4 and fb.rejected_seq == 0
    assert rig.arm.joints == wire_exact(pts[-1])        # reached exactly (the wire's 0.001 deg)
    assert entries[-1].final_joints == joints_to_wire(pts[-1])
    # a stale record (the first two targets again, with START) is ignored: nothing moves
    rig.stream = []
    rig.record = CommandV2(Control.START, stream[0], stream[1])
    before = rig.arm.joints
    rig.loop(20)
    assert rig.arm.joints == before and len(rig.prog.log) == 4 and rig.prog.rejected_seq == 0


def test_out_of_order_is_refused_once_and_the_arm_stops_at_its_last_point(rig):
    pts = zigzag(4)
    rig.record = CommandV2(Control.START, slot(1, pts[0], 0.8, 5), slot(2, pts[1], 0.8, 5))
    rig.until(lambda fb: fb.accepted_seq == 2)
    rig.record = CommandV2(Control(0), slot(4, pts[3], 0.8, 5))       # 3 skipped
    fb = rig.until(lambda fb: fb.rejected_seq == 4)
    assert fb.reject_code is RejectCode.OUT_OF_ORDER and fb.accepted_seq == 2
    fb = rig.until(lambda fb: fb.state is StreamState.WAITING, 10.0)  # no guess past point 2
    assert fb.done_seq == 2 and rig.arm.joints == wire_exact(pts[1])
    rejected = [e for e in rig.prog.log.entries() if e.outcome is Outcome.REJECTED]
    assert [(e.seq, e.reject_code) for e in rejected] == [(4, 1)]     # logged once, repeated often
    rig.record = CommandV2(Control(0), slot(3, pts[2], 0.8, 0))
    fb = rig.until(lambda fb: fb.done_seq == 3 and not rig.arm.moving)
    assert rig.arm.joints == wire_exact(pts[2])
    assert sorted((e.seq, e.outcome.value) for e in rig.prog.log.entries()) == [
        (1, "blended"), (2, "executed"), (3, "executed"), (4, "rejected")]


def test_a_link_loss_stops_the_stream_and_old_targets_never_run_again(kin):
    rig = RigV2(kin, watchdog_units=10)                  # 100 ms
    rig.connect()
    pts = zigzag(6)
    stream = [slot(i + 1, q, 0.1, smooth=5) for i, q in enumerate(pts)]    # ~0.6 s a segment
    rig.stream = stream
    rig.until(lambda fb: fb.active_seq == 3)
    rig.exchanging = False                               # the master goes silent
    fb = rig.until(lambda fb: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
    assert fb.state is StreamState.STOPPING and fb.status & StatusBits.IN_MOTION   # braking on the path
    fb = rig.until(lambda fb: fb.state is StreamState.IDLE, 2.0)
    assert rig.prog.link_losses == 1 and rig.prog.need_start and not rig.prog.armed
    stopped_at = rig.arm.joints
    taken = rig.prog.accepted_seq
    by_seq = {e.seq: e for e in rig.prog.log.entries()}
    assert sorted(by_seq) == list(range(1, taken + 1)) and len(rig.prog.log) == taken
    assert by_seq[3].outcome is Outcome.STOPPED and "watchdog" in by_seq[3].reason
    assert all(by_seq[s].outcome is Outcome.STOPPED and by_seq[s].start_time is None
               for s in range(4, taken + 1))             # the look-ahead was dropped
    # a naive master reconnects and repeats its old record: repeats, ignored; nothing moves
    rig.exchanging = True
    rig.stream = []
    rig.record = CommandV2(Control(0), stream[taken - 1], stream[taken])
    rig.connect()
    fb = rig.loop(20)
    assert rig.arm.joints == stopped_at and fb.rejected_seq == taken + 1
    assert fb.reject_code is RejectCode.NOT_ARMED        # the new seq in it: not armed yet
    # armed by an empty record; a new target without START is refused, with START it runs
    rig.record = CommandV2()
    rig.loop(3)
    assert rig.prog.armed
    nxt = slot(taken + 2, pts[-1], 0.5, 0)
    rig.record = CommandV2(Control(0), nxt)
    fb = rig.loop(5)
    assert fb.rejected_seq == nxt.seq and fb.reject_code is RejectCode.OUT_OF_ORDER
    assert rig.arm.joints == stopped_at
    rig.record = CommandV2(Control.START, nxt)
    fb = rig.until(lambda fb: fb.done_seq == nxt.seq and not rig.arm.moving)
    seqs = [e.seq for e in rig.prog.log.entries() if e.outcome is not Outcome.REJECTED]
    assert len(seqs) == len(set(seqs)) and seqs[-1] == nxt.seq
    assert rig.arm.joints == wire_exact(pts[-1])


# ------------------------------------------------------------------------------ blending, gaps

def run_path(kin, smooth: int, n: int = 9, speed: float = 0.5, period: float = 0.002):
    rig = RigV2(kin, period=period)
    rig.connect()
    pts = zigzag(n)
    stream = [slot(i + 1, q, speed, smooth if i < n - 1 else 0) for i, q in enumerate(pts)]
    rig.run_stream(stream)
    return rig, pts, stream


def corner_bounds(kin, pts, smooth, speed):
    """For each inner point P1..P8: the blend window and the closest approach it allows at most
    (|v_in| + |v_out|) * w / 8 (each segment's leftover / head start is v w / 8 at mid-window)."""
    full = [wire_exact(START_JOINTS)] + [wire_exact(p) for p in pts]
    out = []
    for i in range(1, len(full) - 1):
        t_in = move_time(full[i - 1], full[i], speed, kin)
        t_out = move_time(full[i], full[i + 1], speed, kin)
        v_in = np.linalg.norm(np.subtract(full[i], full[i - 1])) / t_in
        v_out = np.linalg.norm(np.subtract(full[i + 1], full[i])) / t_out
        w = blend_window(smooth, t_in, t_out)
        out.append((np.array(full[i]), w, (v_in + v_out) * w / 8.0, min(v_in, v_out)))
    return out


def test_lookahead_blends_through_the_inner_points_without_standing_still(kin):
    rig, pts, stream = run_path(kin, smooth=5)
    entries = rig.prog.log.entries()
    assert [e.seq for e in entries] == list(range(1, 10))
    assert [e.outcome for e in entries] == [Outcome.BLENDED] * 8 + [Outcome.EXECUTED]
    assert not any(fb.state is StreamState.WAITING for _, fb, _ in rig.trace)
    bounds = corner_bounds(kin, pts, 5, 0.5)
    # from the first blend to the start of the final deceleration the arm never slows below
    # a third of the slower segment's speed (at a stop it would be 0)
    t_from = entries[0].end_time
    t_to = entries[-1].end_time - DEFAULT_RAMP_TIME * entries[-1].speed / 1000.0
    inner = [v for t, v in speeds(rig.trace) if t_from <= t <= t_to]
    slowest = min(b[3] for b in bounds)
    assert len(inner) > 100 and min(inner) > slowest / 3.0, (min(inner), slowest)
    # ...and never faster than the joint limits at 50 %
    for (t0, _, q0), (t1, _, q1) in zip(rig.trace, rig.trace[1:]):
        assert all(abs(b - a) / (t1 - t0) <= 0.5 * v + 1e-6 for a, b, v in zip(q0, q1, kin.limits.velocity))
    # the corners are rounded: near each inner point, but not through it
    qs = np.array([q for _, _, q in rig.trace])
    step = max(v for _, v in speeds(rig.trace)) * rig.period
    for point, w, bound, _ in bounds:
        closest = float(np.min(np.linalg.norm(qs - point, axis=1)))
        assert 0.2 * bound < closest <= bound + step, (closest, bound)
    # the final point is reached exactly
    assert rig.arm.joints == wire_exact(pts[-1])


def test_smooth_0_stops_exactly_at_every_point(kin):
    rig, pts, stream = run_path(kin, smooth=0)
    entries = rig.prog.log.entries()
    assert [e.outcome for e in entries] == [Outcome.EXECUTED] * 9
    assert [e.final_joints for e in entries] == [s.joints for s in stream]
    # between two segments the next one starts from rest: the speed just after a point is ramping
    for e, nxt in zip(entries, entries[1:]):
        assert nxt.start_time == pytest.approx(e.end_time)


@pytest.mark.parametrize("smooth", [1, 5, 10])
def test_the_corner_grows_with_the_smooth_level(kin, smooth):
    rig, pts, _ = run_path(kin, smooth=smooth)
    qs = np.array([q for _, _, q in rig.trace])
    bounds = corner_bounds(kin, pts, smooth, 0.5)
    step = max(v for _, v in speeds(rig.trace)) * rig.period
    for point, w, bound, _ in bounds:
        closest = float(np.min(np.linalg.norm(qs - point, axis=1)))
        assert 0.2 * bound < closest <= bound + step


def test_a_late_target_makes_the_arm_stop_exactly_at_the_point_and_wait(rig):
    pts = zigzag(3)
    stream = [slot(1, pts[0], 0.5, 5), slot(2, pts[1], 0.5, 5), slot(3, pts[2], 0.5, 0)]
    rig.stream = stream
    rig.withhold = 3
    fb = rig.until(lambda fb: fb.state is StreamState.WAITING, 10.0)
    assert fb.done_seq == 2 and fb.active_seq == 0 and fb.accepted_seq == 2
    assert not fb.status & StatusBits.IN_MOTION
    assert rig.arm.joints == wire_exact(pts[1]) and fb.joints == stream[1].joints
    rig.loop(40)                                        # it stays there: no guess
    assert rig.arm.joints == wire_exact(pts[1]) and rig.prog.state is StreamState.WAITING
    rig.withhold = None
    fb = rig.until(lambda fb: fb.state is StreamState.MOVING, 1.0)
    assert fb.active_seq == 3
    rig.until(lambda fb: fb.done_seq == 3 and not rig.arm.moving)
    assert rig.arm.joints == wire_exact(pts[2]) and rig.prog.state is StreamState.IDLE
    one, two, three = rig.prog.log.entries()
    assert (one.outcome, two.outcome, three.outcome) == (Outcome.BLENDED, Outcome.EXECUTED, Outcome.EXECUTED)
    assert two.final_joints == stream[1].joints
    assert three.start_time > two.end_time + 0.19


# --------------------------------------------------------------------------------------- timing

@pytest.mark.parametrize("speed", [0.1, 0.35, 1.0])
def test_a_segment_takes_its_move_time_plus_the_ramp(rig, kin, speed):
    target = (0.5, 0.1, 0.2, -0.4, 0.9, 1.0)
    s = slot(1, target, speed)
    t0 = move_time(wire_exact(START_JOINTS), s.joints_rad, s.speed / 1000.0, kin)
    ramp = min(DEFAULT_RAMP_TIME * s.speed / 1000.0, t0)     # constant acceleration: f * ramp_time
    expected = t0 + ramp
    assert expected == segment_time(t0, ramp, ramp)
    rig.record = CommandV2(Control.START, s)
    fb = rig.until(lambda fb: fb.done_seq == 1 and not rig.arm.moving)
    [entry] = rig.prog.log.entries()
    # the log's times are the model's event times: exact up to float rounding
    assert entry.end_time - entry.start_time == pytest.approx(expected, abs=1e-9)
    # the master sees the arrival in the first feedback after it: within one loop period
    arrived = next(t for t, f, _ in rig.trace if f.done_seq == 1)
    assert entry.end_time <= arrived < entry.end_time + PERIOD + 1e-9
    # the limiting joint cruises at exactly speed * vmax, none faster
    top = max(max(abs(b - a) / (t1 - t0_) / v for a, b, v in zip(q0, q1, kin.limits.velocity))
              for (t0_, _, q0), (t1, _, q1) in zip(rig.trace, rig.trace[1:]))
    assert top == pytest.approx(s.speed / 1000.0, rel=1e-6)
    assert fb.joints == s.joints and rig.arm.joints == wire_exact(target)


def test_blended_points_are_passed_one_move_time_apart(kin):
    """With blending the middle of each blend window comes exactly T0 after the previous one's:
    a blended stream runs on the planned time."""
    rig, pts, _ = run_path(kin, smooth=4, n=5, period=0.005)
    entries = rig.prog.log.entries()
    full = [wire_exact(START_JOINTS)] + [wire_exact(p) for p in pts]
    t0s = [move_time(a, b, 0.5, kin) for a, b in zip(full, full[1:])]
    windows = [blend_window(4, a, b) for a, b in zip(t0s, t0s[1:])]
    mids = [e.end_time + w / 2 for e, w in zip(entries, windows)]
    for i in range(1, len(mids)):
        assert mids[i] - mids[i - 1] == pytest.approx(t0s[i], abs=1e-9)


# ------------------------------------------------------------------------------- stop, faults

def test_stop_brakes_along_the_path_then_idle_with_the_queue_dropped(rig):
    pts = zigzag(5)
    rig.stream = [slot(i + 1, q, 0.5, 5) for i, q in enumerate(pts)]
    rig.until(lambda fb: fb.active_seq == 2 and fb.accepted_seq == 3)
    rig.loop(3)
    rig.stream = []
    rig.record = CommandV2(Control.STOP)
    fb = rig.loop()
    t_stop = rig.t
    assert fb.state is StreamState.STOPPING
    moving = [fb]
    while fb.state is StreamState.STOPPING:
        fb = rig.loop()
        moving.append(fb)
    t_rest = rig.t
    assert fb.state is StreamState.IDLE and not fb.status & StatusBits.IN_MOTION
    assert all(f.status & StatusBits.IN_MOTION for f in moving[:-1])
    assert BRAKE - PERIOD <= t_rest - t_stop <= BRAKE + PERIOD + 1e-9
    v = speeds(rig.trace[-len(moving) - 3:])
    assert v[0][1] > 0.3 and v[-1][1] == 0.0             # from path speed to rest
    rest = rig.arm.joints
    rig.loop(20)
    assert rig.arm.joints == rest
    entries = {e.seq: e for e in rig.prog.log.entries()}
    assert entries[1].outcome is Outcome.BLENDED
    assert entries[2].outcome is Outcome.STOPPED and entries[2].start_time is not None
    assert entries[3].outcome is Outcome.STOPPED and entries[3].start_time is None
    assert sorted(entries) == [1, 2, 3] and fb.done_seq == 1 and fb.active_seq == 0


@pytest.mark.parametrize("fault", ["estop", "drives_powered", "error"])
def test_a_fault_stops_at_once_and_targets_are_refused_with_code_3(rig, fault):
    pts = zigzag(3)
    rig.stream = [slot(i + 1, q, 0.5, 5) for i, q in enumerate(pts)]
    rig.until(lambda fb: fb.active_seq == 2)
    {"estop": lambda: rig.arm.set_estop(True, now=rig.t),
     "drives_powered": lambda: rig.arm.set_drives_powered(False, now=rig.t),
     "error": lambda: rig.arm.set_error(True, now=rig.t)}[fault]()
    frozen = rig.arm.joints
    fb = rig.loop(10)
    assert rig.arm.joints == frozen and fb.state is StreamState.IDLE
    entries = {e.seq: e for e in rig.prog.log.entries()}
    assert entries[2].outcome is Outcome.STOPPED and entries[2].final_joints == joints_to_wire(frozen)
    rig.stream = []
    rig.record = CommandV2(Control(0), slot(rig.prog.accepted_seq + 1, pts[0], 0.5))
    fb = rig.loop(5)
    assert fb.reject_code is RejectCode.FAULT and fb.rejected_seq == rig.prog.accepted_seq + 1
    assert rig.arm.joints == frozen
    if fault == "error":
        assert fb.status & StatusBits.ERROR and fb.status & StatusBits.DRIVES_POWERED
    else:
        assert not fb.status & StatusBits.DRIVES_POWERED
        assert bool(fb.status & StatusBits.ESTOP) == (fault == "estop")


def test_a_target_outside_the_joint_limits_is_refused_with_code_4(rig):
    bad = slot(1, (3.0, 0.4, -0.3, 0.0, 0.6, 0.0), 0.5)       # joint_1 limit 2.705 rad
    rig.record = CommandV2(Control.START, bad)
    fb = rig.loop(5)
    assert fb.rejected_seq == 1 and fb.reject_code is RejectCode.UNREACHABLE and fb.accepted_seq == 0
    assert rig.arm.joints == START_JOINTS and fb.state is StreamState.IDLE
    [entry] = rig.prog.log.entries()
    assert entry.outcome is Outcome.REJECTED and entry.reject_code == 4 and "joint_1" in entry.reason


# ------------------------------------------------------------------------------ records, wire

def test_a_corrupted_record_is_ignored(rig):
    good = CommandV2(Control.START, slot(1, zigzag(1)[0], 0.5)).encode()
    for index in (0, 1, 9, 40, 70):                      # version, control, joints, CRC
        raw = bytearray(good)
        raw[index] ^= 0x10
        fb = rig.send_raw(bytes(raw))
        assert fb.accepted_seq == 0 and not rig.arm.moving
    assert rig.prog.bad_records == 5 and len(rig.prog.log) == 0
    fb = rig.send_raw(good)
    assert fb.accepted_seq == 1 and rig.arm.moving


def test_a_record_counts_only_when_it_arrived_twice(kin):
    rig = RigV2(kin, confirm=True)
    rig.connect()
    rig.loop(2)
    once = CommandV2(Control.START, slot(1, zigzag(1)[0], 0.5)).encode()
    assert rig.send_raw(once).accepted_seq == 0
    assert rig.send_raw(CommandV2().encode()).accepted_seq == 0
    assert rig.send_raw(once).accepted_seq == 0
    assert rig.send_raw(once).accepted_seq == 1


def test_feedback_joints_pose_and_heartbeat(rig, kin):
    beats = []
    for _ in range(5):
        beats.append(rig.loop().heartbeat)
    assert [b - beats[0] for b in beats] == [0, 1, 2, 3, 4]
    rig.exchanging = False                               # also while the link is down
    rig.until(lambda fb: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
    b = rig.loop().heartbeat
    assert rig.loop().heartbeat == b + 1
    rig.prog.loops = 65534
    assert [rig.loop().heartbeat for _ in range(3)] == [65535, 0, 1]
    fb = rig.trace[-1][1]
    assert fb.joints == joints_to_wire(START_JOINTS)
    assert fb.tcp == wire_pose(kin.fk_pose(START_JOINTS))
    assert len(fb.encode()) == RECORD_SIZE_V2
    x_mm = kin.fk_pose(START_JOINTS).x
    assert abs(fb.tcp[0] * 0.01 - x_mm) <= 0.005 and abs(fb.pose.x - x_mm) <= 0.005


# ------------------------------------------------------------------------- options, slave, CLI

def test_protocol_option_slave_and_cli(kin):
    slave = robot_slave(4, protocol="v2")
    assert slave.cfg == CHK_CFG_V2 and slave.input_size == slave.output_size == RECORD_SIZE_V2
    assert robot_slave(4).input_size == 14
    assert SimOptions.from_mapping({"protocol": "v2"}).protocol == "v2"
    assert SimOptions().protocol == "v1"
    with pytest.raises(SimError):
        SimOptions(protocol="v9")
    with pytest.raises(SimError):
        robot_slave(4, protocol="v9")
    with pytest.raises(SystemExit) as exc:
        main(["--protocol", "v9"])
    assert exc.value.code == 2
    vc = VirtualController(kinematics=kin, protocol="v2")
    try:
        assert isinstance(vc.program, ControllerProgramV2) and isinstance(vc.arm, SimStreamArm)
        assert vc.slave.cfg == CHK_CFG_V2
        fb = vc.step()
        assert isinstance(fb, FeedbackV2) and fb.state is StreamState.IDLE and vc.state is StreamState.IDLE
        assert fb.status & StatusBits.PROGRAM_RUNNING
    finally:
        vc.stop()
