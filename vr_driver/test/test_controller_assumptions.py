"""Every assumption about the real G2 is a parameter of the virtual G2 (issue 33 item 1,
doc/controller_program.md §10.9), each shown both ways by what differs on the bus (the feedback the
master reads) or in the arm's recorded motion: MOVEP's speed unit, a program loop that blocks during
a MOVE, the blend across an input read, the configuration rule, an irregular loop, a refused
send-ahead, an unreachable pose that halts the program, the ramp's shape and per-axis
accelerations. Stepped with a fake clock in one thread (the records go through the robot DpSlave in
Data_Exchange telegrams, as test_controller_v3.py); nothing sleeps."""
from __future__ import annotations

import math
import os
import re
import statistics
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import pytest

from pyprofibus_vendor.dp_slave import SlaveState

from vr_driver.controller.arm import Outcome, SimArm
from vr_driver.controller.cli import main
from vr_driver.controller.options import ASSUMPTIONS, PARAM_NAMES, LoopTiming, SimOptions
from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import robot_slave, VirtualController
from vr_driver.controller.program_v3 import ControllerProgramV3, SendAhead
from vr_driver.controller.session import Unreachable
from vr_driver.controller.stream_arm import RampShape, SimStreamArm, StreamTarget
from vr_driver.errors import MotionError
from vr_driver.protocol.v1 import (Command, ControllerState, Done, Feedback, MasterHandshake, Rejected, StatusBits,
                                   TimedOut, WireMoveType)
from vr_driver.protocol.v3 import CartesianKind, CartesianSlot, CommandV3, Control, FeedbackV3, RejectCode, StreamState

from _slave_rig import SlaveRig, StreamRig

PERIOD = 0.005
START_JOINTS = (0.0, 0.4, -0.3, 0.0, 0.6, 0.0)
HERE = os.path.dirname(os.path.abspath(__file__))
DOC = os.path.join(HERE, "..", "doc", "controller_program.md")
LAUNCH = os.path.join(HERE, "..", "launch", "driver.launch")


class Rig(StreamRig):
    """Fake clock + v3 robot DpSlave + SimStreamArm + ControllerProgramV3 and a minimal master that
    sends ``self.record`` (or the stream) every bus cycle; ``arm_kw`` / ``prog_kw`` set the
    assumptions. ``ahead``: the master sends the next target before the acknowledgement of the one
    before it came (protocol.send_ahead): when its last record offered the first target not taken,
    this one offers the one after it. A point of the stream refused ends it with STOP."""

    def __init__(self, kin, *, lookahead: int = 1, ring: int = 4, period: float = PERIOD, ahead: bool = False,
                 arm_kw: Optional[Dict[str, Any]] = None, prog_kw: Optional[Dict[str, Any]] = None) -> None:
        super().__init__(period, 10)
        self.slave = robot_slave(4, self.clock, "v3")
        self.arm = SimStreamArm(kin, clock=self.clock, brake_time=0.2, initial_joints=START_JOINTS,
                                look_ahead=lookahead, **(arm_kw or {}))
        self.prog = ControllerProgramV3(self.slave, self.arm, kinematics=kin, ring_size=ring, **(prog_kw or {}))
        self.record = CommandV3()
        self.ahead = ahead
        self._offered: Optional[int] = None
        self.connect()

    def encode(self, record: CommandV3) -> bytes:
        return record.encode()

    def decode(self, data: bytes) -> FeedbackV3:
        return FeedbackV3.decode(data)

    def streamed_record(self) -> CommandV3:
        if self.master_fb is not None and self.master_fb.rejected_seq in [s.seq for s in self.stream]:
            return CommandV3(Control.STOP)        # a refused point ends the stream (as the driver's)
        i = self.accepted_index()
        j = i + 1 if self.ahead and self._offered == i and i + 1 < len(self.stream) else i
        self._offered = j
        if j >= len(self.stream):
            return CommandV3()
        return CommandV3(Control.START if j == 0 else Control(0), self.stream[j])

    def speeds(self, since: float = -math.inf) -> List[Tuple[float, float]]:
        """(time, joint-space speed [rad/s]) between the loops recorded after ``since``."""
        return [(t1, float(np.linalg.norm(np.subtract(q1, q0))) / (t1 - t0))
                for (t0, _, q0), (t1, _, q1) in zip(self.trace, self.trace[1:]) if t0 >= since]


def zigzag(n: int) -> List[Tuple[float, ...]]:
    """n joint points after START_JOINTS: a corner at every point."""
    q0 = START_JOINTS
    return [(q0[0] + 0.12 * i, q0[1] + (0.08 if i % 2 else 0.0), q0[2] - 0.03 * i, 0.02 * i, q0[4], 0.05 * i)
            for i in range(1, n + 1)]


def slot(kin, seq: int, joints, speed: int = 500, smooth: int = 0) -> CartesianSlot:
    return CartesianSlot.from_pose(seq, kin.fk_pose(joints), speed, smooth, CartesianKind.MOVEP)


def stream_of(kin, pts, speed: int = 500, smooth: int = 5) -> List[CartesianSlot]:
    return [slot(kin, 1 + i, q, speed, smooth if i < len(pts) - 1 else 0) for i, q in enumerate(pts)]


def stops(rig: Rig) -> int:
    """How often the arm came (nearly) to rest between its first and its last motion."""
    speeds = [v for _, v in rig.speeds()]
    slow = [v < 0.05 * max(speeds) for v in speeds]
    first, last = slow.index(False), len(slow) - 1 - slow[::-1].index(False)
    inner = slow[first:last + 1]
    return sum(1 for a, b in zip(inner, inner[1:]) if b and not a)


# ------------------------------------------------------------------------- MOVEP's speed unit

@pytest.mark.parametrize("scale", [1.0, 0.6])
def test_speed_scale_sets_the_real_speed_of_a_commanded_one(kin, scale):
    """speed 500 (50 %) at speed_scale 0.6 runs at 30 % of the joint limits: the cruise speed and
    the move time scale by 0.6 (the ramp too: it is the real speed's); at 1.0 exactly as commanded."""
    rig = Rig(kin, arm_kw={"speed_scale": scale})
    goal = (START_JOINTS[0] + 1.0,) + START_JOINTS[1:]
    rig.run_stream([slot(kin, 1, goal, 500, 0)])
    entry = rig.prog.log.entries()[-1]
    assert entry.outcome is Outcome.EXECUTED
    j1_speed = max(abs(q1[0] - q0[0]) / (t1 - t0)
                   for (t0, _, q0), (t1, _, q1) in zip(rig.trace, rig.trace[1:]))
    vmax = kin.limits.velocity[0]
    assert j1_speed == pytest.approx(0.5 * scale * vmax, rel=0.01)
    move = abs(rig.arm.joints[0] - START_JOINTS[0]) / (0.5 * scale * vmax)
    assert entry.duration == pytest.approx(move + 0.1 * 0.5 * scale, abs=2 * PERIOD)   # T0 + ramp


def test_speed_scale_is_capped_at_the_joint_limits(kin):
    arm = SimStreamArm(kin, initial_joints=START_JOINTS, clock=lambda: 0.0, speed_scale=3.0)
    target = StreamTarget(1, (0, 0, 0, 0, 0, 0), 800, 0, 0.0)
    assert arm._fraction(target) == 1.0
    assert SimStreamArm(kin, initial_joints=START_JOINTS, speed_scale=0.5)._fraction(target) == 0.4


# ---------------------------------------------------------------- the loop blocking during a MOVE

@pytest.mark.parametrize("blocks", [False, True])
def test_a_blocking_loop_freezes_the_feedback_and_stops_at_every_point(kin, blocks):
    """Seen from the bus: with the loop running during a MOVE the heartbeat grows every loop and the
    stream blends (no stop); with a MOVE blocking it the master reads the same record (heartbeat,
    pose) for the whole of each motion, the targets are taken only between motions, and the arm stops
    at every point although smooth 5 and the look-ahead ask for a blend."""
    rig = Rig(kin, prog_kw={"loop_blocks_during_move": blocks})
    stream = stream_of(kin, zigzag(4), 500, 5)
    rig.run_stream(stream)
    moving = [fb for _, fb, _ in rig.trace if fb.state is StreamState.MOVING]
    beats = [fb.heartbeat for fb in moving]
    # the records read while the arm moves: a new heartbeat in every loop, or the same for a whole move
    changes = sum(1 for a, b in zip(beats, beats[1:]) if a != b)
    outcomes = [e.outcome for e in rig.prog.log.entries()]
    if blocks:
        assert changes <= len(stream) and rig.prog.blocked_loops > 0.8 * len(moving)
        assert stops(rig) == len(stream) - 1
        assert outcomes == [Outcome.EXECUTED] * len(stream)
    else:
        assert changes == len(moving) - 1 and rig.prog.blocked_loops == 0
        assert stops(rig) == 0
        assert outcomes == [Outcome.BLENDED] * (len(stream) - 1) + [Outcome.EXECUTED]


@pytest.mark.parametrize("blocks", [False, True])
def test_a_stop_reaches_a_blocked_loop_only_after_the_move(kin, blocks):
    rig = Rig(kin, prog_kw={"loop_blocks_during_move": blocks})
    goal = (START_JOINTS[0] + 1.0,) + START_JOINTS[1:]
    rig.record = CommandV3(Control.START, slot(kin, 1, goal, 300, 0))
    rig.until(lambda fb: fb.accepted_seq == 1)
    rig.loop(20)
    rig.record = CommandV3(Control.STOP)
    rig.until(lambda fb: not rig.arm.moving and fb.state is StreamState.IDLE)
    entry = rig.prog.log.entries()[-1]
    if blocks:       # the program never saw the STOP while the arm moved: it ran to its target
        assert entry.outcome is Outcome.EXECUTED and rig.arm.joints[0] == pytest.approx(goal[0], abs=1e-4)
    else:
        assert entry.outcome is Outcome.STOPPED and rig.arm.joints[0] < goal[0] - 0.3


class RigV1(SlaveRig):
    """The v1 program under protocol.v1.MasterHandshake, one bus cycle per loop."""

    def __init__(self, kin, **prog_kw) -> None:
        super().__init__(0.01)
        self.slave = robot_slave(4, self.clock)
        self.arm = SimArm(kin, speed_factor=4.0, clock=self.clock)
        self.prog = ControllerProgram(self.slave, self.arm, **prog_kw)
        self.master = MasterHandshake(accept_timeout=0.5, release_timeout=0.5, settle_time=0.0, clock=self.clock)
        self.trace: List[Feedback] = []
        self.events: List[Any] = []
        self.connect()

    def loop(self, n: int = 1) -> None:
        for _ in range(n):
            self.t += self.period
            if self.exchanging and self.slave.state is SlaveState.DATA_EXCH:
                reply = self.call(None, self.master.outputs().encode())
                fb = Feedback.decode(reply.data)
                self.trace.append(fb)
                ev = self.master.update(fb, self.t)
                if ev is not None:
                    self.events.append(ev)
            self.prog.step(self.t)

    def run(self, pose, max_time: float = 20.0) -> None:
        while not self.master.ready:
            self.loop()
        self.master.submit(Command.from_pose(pose, WireMoveType.PTP), motion_timeout=max_time, now=self.t)
        end = self.t + max_time
        while not (self.events and self.events[-1].final and self.master.ready):
            assert self.t < end
            self.loop()


@pytest.mark.parametrize("blocks", [False, True])
def test_v1_works_with_a_blocking_loop_its_pose_frozen_during_the_move(kin, blocks):
    """v1 relies on the state byte alone: a blocking loop still ends the target DONE, exactly once;
    the pose it reports stands still while BUSY (it follows the arm with a running loop)."""
    rig = RigV1(kin, loop_blocks_during_move=blocks)
    rig.run((1000, 200, 800, 0, 60, 10))
    assert [e.outcome for e in rig.prog.log.entries()] == [Outcome.EXECUTED]
    assert isinstance(rig.events[-1], Done)
    busy = {fb.values for fb in rig.trace if fb.state is ControllerState.BUSY}
    assert (len(busy) == 1) == blocks
    assert rig.prog.last_feedback.values == (1000, 200, 800, 0, 60, 10)


# ------------------------------------------------------------------ the blend across an input read

@pytest.mark.parametrize("keeps", [True, False])
def test_an_input_read_between_two_movep_keeps_or_ends_the_blend(kin, keeps):
    rig = Rig(kin, period=0.002, arm_kw={"blend_across_input_read": keeps})
    stream = stream_of(kin, zigzag(6), 500, 5)
    rig.run_stream(stream)
    outcomes = [e.outcome for e in rig.prog.log.entries()]
    if keeps:
        assert stops(rig) == 0 and outcomes == [Outcome.BLENDED] * 5 + [Outcome.EXECUTED]
    else:     # an exact stop at every inner point, with look-ahead 1 and smooth 5
        assert stops(rig) == 5 and outcomes == [Outcome.EXECUTED] * 6


# -------------------------------------------------------------------------- the configuration rule

@pytest.mark.parametrize("rule", ["previous_target", "current_joints"])
def test_the_configuration_rule_decides_the_solution_of_a_target_taken_ahead(kin, rule):
    """J6 turns +-360 deg: target 2 (J6 3.5) is taken while the arm still runs to target 1 (J6 2.0)
    from J6 0: nearest the previous target it is J6 3.5, nearest the arm's joints 3.5 - 2 pi."""
    base = START_JOINTS[:5]
    rig = Rig(kin, arm_kw={"configuration": rule})
    rig.run_stream([slot(kin, 1, base + (2.0,), 200, 3), slot(kin, 2, base + (3.5,), 200, 0)])
    expected = 3.5 if rule == "previous_target" else 3.5 - 2.0 * math.pi
    assert rig.arm.joints[5] == pytest.approx(expected, abs=1e-3)


# ------------------------------------------------------------------------------ an irregular loop

def _heartbeat_intervals(kin, jitter: float, seed: int = 1, loops: int = 400) -> List[float]:
    """The loop periods a master sees from the bus: it reads every 1 ms and notes when the heartbeat
    changes; the program loops at the times of LoopTiming(10 ms, jitter, seed)."""
    rig = Rig(kin)
    timing = LoopTiming(0.010, jitter, seed)
    next_loop = rig.t + timing.next_period()
    changes: List[float] = []
    last = None
    end = rig.t + loops * 0.010
    while rig.t < end:
        rig.t = round(rig.t + 0.001, 9)
        if rig.t >= next_loop:
            rig.prog.step(rig.t)
            next_loop += timing.next_period()
        fb = FeedbackV3.decode(rig.call(None, CommandV3().encode()).data)
        if fb.heartbeat != last:
            changes.append(rig.t)
            last = fb.heartbeat
    return [b - a for a, b in zip(changes[1:], changes[2:])]


@pytest.mark.parametrize("jitter", [0.0, 0.004])
def test_loop_jitter_spreads_the_periods_the_heartbeat_shows(kin, jitter):
    periods = _heartbeat_intervals(kin, jitter)
    assert statistics.mean(periods) == pytest.approx(0.010, abs=0.001)     # the loop period within 1 ms
    spread = statistics.pstdev(periods)
    if jitter == 0.0:
        assert spread < 0.0006 and max(periods) - min(periods) <= 0.0011    # the 1 ms reading grid only
    else:
        assert spread > 0.0015 and max(periods) - min(periods) > 0.006


def test_loop_timing_is_seeded_and_reaches_the_controller(kin):
    a, b, c = LoopTiming(0.01, 0.003, 7), LoopTiming(0.01, 0.003, 7), LoopTiming(0.01, 0.003, 8)
    pa = [a.next_period() for _ in range(50)]
    assert pa == [b.next_period() for _ in range(50)] != [c.next_period() for _ in range(50)]
    assert all(0.007 <= p <= 0.013 for p in pa)
    assert [LoopTiming(0.01).next_period() for _ in range(3)] == [0.01] * 3
    vc = VirtualController(kinematics=kin, protocol="v3", loop_jitter=0.002, loop_jitter_seed=5)
    try:
        assert (vc.loop_timing.period, vc.loop_timing.jitter, vc.loop_timing.seed) == (0.01, 0.002, 5)
    finally:
        vc.stop()


# -------------------------------------------------------------------------------- sending ahead

@pytest.mark.parametrize("rule", ["accepted", "refused"])
def test_a_target_sent_ahead_waits_or_is_refused(kin, rule):
    rig = Rig(kin, prog_kw={"send_ahead": rule})
    pts = zigzag(3)
    rig.record = CommandV3(Control.START, slot(kin, 1, pts[0], 800, 5))
    rig.until(lambda fb: fb.accepted_seq == 1)
    rig.record = CommandV3(Control(0), slot(kin, 3, pts[2], 800, 0))     # before 2: one number ahead
    fb = rig.loop(10)
    if rule == "accepted":
        assert fb.accepted_seq == 1 and fb.rejected_seq == 0 and fb.reject_code is RejectCode.NONE
    else:
        assert fb.accepted_seq == 1 and fb.rejected_seq == 3 and fb.reject_code is RejectCode.OUT_OF_ORDER


@pytest.mark.parametrize("rule", ["accepted", "refused"])
def test_a_master_sending_ahead_finishes_its_stream_only_where_the_program_lets_it_wait(kin, rule):
    """The master sends ahead (as the driver does) and the ring fills (look-ahead 0, ring 2): a
    program that lets the target ahead wait runs the stream to its end; one that refuses it shows
    OUT_OF_ORDER for a target of the stream, and the rest is never taken."""
    rig = Rig(kin, lookahead=0, ring=2, ahead=True, prog_kw={"send_ahead": rule})
    stream = stream_of(kin, zigzag(6), 300, 3)
    rig.stream = stream
    fb = rig.until(lambda fb: (fb.done_seq == 6 or fb.rejected_seq != 0) and not rig.arm.moving, 60.0)
    if rule == "accepted":
        assert fb.done_seq == 6 and fb.rejected_seq == 0
    else:
        assert fb.reject_code is RejectCode.OUT_OF_ORDER and fb.rejected_seq in range(2, 7)
        fb = rig.loop(50)
        assert fb.accepted_seq < 6 and fb.done_seq < 6 and fb.state is StreamState.IDLE


# ---------------------------------------------------------------------------- an unreachable pose

def _unreachable_slot(seq: int) -> CartesianSlot:
    return CartesianSlot(seq, CartesianKind.MOVEP, 0, 500, (20000, 0, 5000, 0, 9000, 0))   # 2 m out


def test_an_unreachable_pose_is_refused_and_the_program_goes_on(kin):
    rig = Rig(kin, prog_kw={"unreachable": "skip"})
    rig.record = CommandV3(Control.START, _unreachable_slot(1))
    fb = rig.until(lambda fb: fb.rejected_seq == 1)
    assert fb.reject_code is RejectCode.UNREACHABLE and not rig.arm.moving
    beat = fb.heartbeat
    fb = rig.loop(5)
    assert fb.heartbeat == beat + 5 and rig.prog.halted is None and rig.arm.error is None


def test_an_unreachable_pose_raises_an_alarm_that_stops_the_arm_and_halts_the_program(kin):
    """alarm_halt: target 2 is unreachable while the arm runs to target 1 -- the arm stops at once,
    the record on the bus is frozen (its heartbeat too: the master's sign of a halted program), no
    target is taken; clearing the error restarts the program disarmed, and a new stream runs."""
    rig = Rig(kin, prog_kw={"unreachable": "alarm_halt"})
    goal = (START_JOINTS[0] + 1.0,) + START_JOINTS[1:]
    rig.record = CommandV3(Control.START, slot(kin, 1, goal, 300, 3))
    rig.until(lambda fb: fb.accepted_seq == 1)
    rig.loop(10)
    rig.record = CommandV3(Control(0), _unreachable_slot(2))
    rig.loop(1)
    frozen = rig.master_fb
    assert rig.prog.halted is not None and "unreachable" in rig.prog.halted
    assert not rig.arm.moving and rig.arm.joints[0] < goal[0] - 0.3 and rig.arm.error.startswith("alarm")
    rig.loop(30)
    assert rig.master_fb == frozen and frozen.state is StreamState.MOVING and frozen.rejected_seq == 0
    entries = rig.prog.log.entries()
    assert [(e.seq, e.outcome) for e in entries] == [(2, Outcome.REJECTED), (1, Outcome.STOPPED)]
    assert entries[0].reason.startswith("alarm, the program halted") and "alarm" in entries[1].reason
    rig.arm.set_error(None)                                # the operator resets the alarm
    rig.record = CommandV3()
    fb = rig.loop(3)
    assert rig.prog.halted is None and fb.armed and fb.accepted_seq == 0 and fb.heartbeat != frozen.heartbeat
    rig.run_stream([slot(kin, 5, goal, 500, 0)])
    assert rig.prog.log.entries()[-1].outcome is Outcome.EXECUTED


@pytest.mark.parametrize("rule", ["skip", "alarm_halt"])
def test_v1_unreachable_rejected_or_frozen_at_busy(kin, rule):
    """v1: REJECTED and on to READY (skip), or BUSY on the bus for good -- the master's motion
    timeout is what it sees (alarm_halt, §5 notes); READY again once the alarm is cleared."""
    rig = RigV1(kin, unreachable=rule)
    while not rig.master.ready:
        rig.loop()
    rig.master.submit(Command.from_pose((2000, 0, 500, 0, 90, 0), WireMoveType.PTP), motion_timeout=1.0, now=rig.t)
    rig.loop(150)
    states = [fb.state for fb in rig.trace[-50:]]
    if rule == "skip":
        assert rig.prog.halted is None and isinstance(rig.events[0], Rejected)
        assert states[-1] is ControllerState.READY
    else:
        assert rig.prog.halted is not None and set(states) == {ControllerState.BUSY}
        assert not StatusBits.ERROR & rig.trace[-1].status        # frozen: written before the alarm
        assert isinstance(rig.events[-1], TimedOut) and rig.events[-1].stage == "motion"
        rig.arm.set_error(None)
        rig.loop(100)
        assert rig.trace[-1].state is ControllerState.READY and rig.prog.halted is None


# ------------------------------------------------------------------ ramp shape, per-axis acceleration

def _j1_move(kin, **arm_kw) -> Tuple[List[Tuple[float, float]], float]:
    """A J1-only move from rest to rest at 100 %: (time, J1 speed) every 1 ms and its duration."""
    t = [0.0]
    arm = SimStreamArm(kin, initial_joints=START_JOINTS, clock=lambda: t[0], **arm_kw)
    goal = [q + d for q, d in zip(START_JOINTS, (1.5, 0, 0, 0, 0, 0))]
    arm.push(StreamTarget(1, tuple(round(math.degrees(q) * 1000) for q in goal), 1000, 0, 0.0), now=0.0)
    out, done, last = [], [], arm.joints[0]
    while not done:
        t[0] += 0.001
        done = arm.step(t[0])
        out.append((t[0], (arm.joints[0] - last) / 0.001))
        last = arm.joints[0]
    return out, done[0].end_time - done[0].start_time


@pytest.mark.parametrize("shape", ["linear", "s_curve"])
def test_the_ramp_shape_from_the_recorded_motion(kin, shape):
    """Same duration either way (T0 + ramp); a quarter into the ramp from rest the linear ramp is at
    a quarter of full speed, the S-shaped one at 5/32 (smoothstep), its acceleration peaking at 1.5
    times the linear one's in the middle."""
    trace, duration = _j1_move(kin, ramp_shape=shape, ramp_time=0.4)
    vmax = kin.limits.velocity[0]
    t0 = math.radians(round(math.degrees(1.5) * 1000) / 1000) / vmax
    assert duration == pytest.approx(t0 + 0.4, abs=2e-3)
    speed_at = dict((round(t, 3), v) for t, v in trace)
    quarter = speed_at[0.1] / vmax
    assert quarter == pytest.approx(0.25 if shape == "linear" else 5.0 / 32.0, abs=0.01)
    acc = [(b[1] - a[1]) / 0.001 for a, b in zip(trace, trace[1:]) if b[0] <= 0.4]
    peak = max(acc) / (vmax / 0.4)
    assert peak == pytest.approx(1.0 if shape == "linear" else 1.5, abs=0.05)


def test_per_axis_accelerations_set_each_joint_s_time_to_full_speed(kin):
    vmax = kin.limits.velocity
    default, d_default = _j1_move(kin)
    # the model's accelerations given per axis: the same motion as ramp_time's model
    same, d_same = _j1_move(kin, accelerations=kin.limits.acceleration)
    assert d_same == pytest.approx(d_default, abs=1e-9)
    assert max(abs(a[1] - b[1]) for a, b in zip(default, same)) < 1e-6
    # joint_1 at 5 rad/s^2: 2.09 / 5 = 0.418 s from rest to full speed
    slow, d_slow = _j1_move(kin, accelerations=(5.0,) + kin.limits.acceleration[1:])
    reached = next(t for t, v in slow if v >= 0.999 * vmax[0])
    assert reached == pytest.approx(vmax[0] / 5.0, abs=0.003)
    assert d_slow == pytest.approx(d_default - 0.1 + vmax[0] / 5.0, abs=2e-3)


def test_a_joint_5_move_follows_its_own_acceleration(kin):
    t = [0.0]
    acc = (5.0, 5.0, 5.0, 5.0, 30.0, 52.3)
    arm = SimStreamArm(kin, initial_joints=START_JOINTS, clock=lambda: t[0], accelerations=acc)
    goal = [q + d for q, d in zip(START_JOINTS, (0, 0, 0, 0, -1.5, 0))]
    arm.push(StreamTarget(1, tuple(round(math.degrees(q) * 1000) for q in goal), 1000, 0, 0.0), now=0.0)
    last, speeds = arm.joints[4], []
    while arm.moving or not speeds:
        t[0] += 0.001
        arm.step(t[0])
        speeds.append((t[0], abs(arm.joints[4] - last) / 0.001))
        last = arm.joints[4]
    vmax5 = kin.limits.velocity[4]
    reached = next(t for t, v in speeds if v >= 0.999 * vmax5)
    assert reached == pytest.approx(vmax5 / 30.0, abs=0.003)       # joint_5's own, not joint_1's 5 rad/s^2


# ------------------------------------------------------------------------ the options, everywhere

def test_every_assumption_has_a_ros_parameter_a_cli_option_a_launch_arg_and_a_row_in_the_doc():
    with open(DOC, encoding="utf-8") as f:
        doc = f.read()
    table = doc[doc.index("### 10.9"):]
    with open(LAUNCH, encoding="utf-8") as f:
        launch = f.read()
    help_text = _cli_help()
    for name in ASSUMPTIONS:
        assert name in PARAM_NAMES, name
        assert re.search(r"\| *`%s`[ (]" % name, table), "no row for %s in §10.9" % name
        assert 'name="%s"' % name in launch or 'name="sim_%s"' % name in launch, name
        assert re.search(r"--(no-)?%s\b" % name.replace("_", "-"), help_text), name


def _cli_help() -> str:
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main(["--help"])
    return out.getvalue()


def test_the_defaults_are_today_s_model():
    o = SimOptions()
    assert (o.speed_scale, o.loop_blocks_during_move, o.blend_across_input_read, o.loop_jitter,
            o.loop_jitter_seed, o.send_ahead, o.unreachable, o.ramp_shape, o.accelerations) == \
        (1.0, False, True, 0.0, 0, "accepted", "skip", "linear", None)


def test_the_options_are_checked_with_a_clear_error(kin):
    o = SimOptions.from_mapping({"protocol": "v3", "speed_scale": "0.6", "loop_blocks_during_move": True,
                                 "blend_across_input_read": False, "loop_jitter": 0.002, "loop_jitter_seed": "3",
                                 "send_ahead": "Refused", "unreachable": "alarm_halt", "ramp_shape": "s_curve",
                                 "accelerations": "[5, 20.9, 20.9, 20.9, 52.3, 52.3]"})
    assert (o.speed_scale, o.loop_jitter_seed, o.send_ahead, o.unreachable, o.ramp_shape) == \
        (0.6, 3, "refused", "alarm_halt", "s_curve")
    assert o.accelerations == (5.0, 20.9, 20.9, 20.9, 52.3, 52.3)
    assert SimOptions(accelerations=[1, 2, 3, 4, 5, 6]).accelerations == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    bad = [({"speed_scale": 0}, "speed_scale must be"), ({"speed_scale": "fast"}, "speed_scale must be"),
           ({"speed_scale": 11}, "speed_scale must be"),
           ({"loop_blocks_during_move": "yes"}, "loop_blocks_during_move must be true or false"),
           ({"blend_across_input_read": 1}, "blend_across_input_read must be true or false"),
           ({"loop_jitter": -0.001}, "loop_jitter must be"), ({"loop_jitter": 0.01}, "below loop_period"),
           ({"loop_jitter_seed": -1}, "loop_jitter_seed"), ({"send_ahead": "maybe"}, "send_ahead must be"),
           ({"unreachable": "ignore"}, "unreachable must be skip or alarm_halt"),
           ({"ramp_shape": "cubic"}, "ramp_shape must be linear or s_curve"),
           ({"accelerations": [1, 2, 3]}, "accelerations must be 6 numbers"),
           ({"accelerations": "1 2 3 4 5 x"}, "joint_6 must be a finite number > 0"),
           ({"accelerations": [1, 2, 3, 4, 0, 6]}, "joint_5 must be a finite number > 0"),
           ({"accelerations": [1] * 6, "ramp_time": 0.5}, "not both")]
    for params, message in bad:
        with pytest.raises(SimError, match=message):
            SimOptions.from_mapping(params)
    for argv in (["--speed-scale", "0"], ["--loop-jitter", "0.02"], ["--loop-jitter-seed", "-1"],
                 ["--accelerations", "1", "2", "3", "4", "5", "-6"],
                 ["--accelerations", "1", "2", "3", "4", "5", "6", "--ramp-time", "0.5"]):
        assert main(["--protocol", "v3"] + argv) == 2, argv
    for argv in (["--send-ahead", "x"], ["--unreachable", "x"], ["--ramp-shape", "x"]):
        with pytest.raises(SystemExit) as exit_:            # argparse's choices
            main(["--protocol", "v3"] + argv)
        assert exit_.value.code == 2
    with pytest.raises(MotionError, match="speed_scale"):
        SimStreamArm(kin, speed_scale=float("nan"))
    with pytest.raises(MotionError, match="not both"):
        SimStreamArm(kin, ramp_time=0.2, accelerations=kin.limits.acceleration)
    with pytest.raises(MotionError, match="send_ahead"):
        SendAhead.parse("later")
    assert RampShape.parse(" S_Curve ") is RampShape.S_CURVE and Unreachable.parse("skip") is Unreachable.SKIP


def test_the_cli_options_are_the_node_parameters():
    """The CLI hands its options to SimOptions.from_mapping by the node's parameter names: each
    parameter is an option's destination, the CLI's defaults are SimOptions' own, and
    controller_kwargs names only VirtualController's keywords."""
    import inspect

    from vr_driver.controller.cli import _parser
    args = _parser().parse_args([])
    assert set(PARAM_NAMES) <= set(vars(args))
    assert SimOptions.from_mapping({name: getattr(args, name) for name in PARAM_NAMES}) == SimOptions()
    kwargs = SimOptions().controller_kwargs()
    assert "device" not in kwargs and set(kwargs) == set(PARAM_NAMES.values()) - {"device"}
    assert set(kwargs) <= set(inspect.signature(VirtualController).parameters)


@pytest.mark.parametrize("protocol", ["v1", "v2", "v3"])
def test_the_virtual_controller_hands_each_setting_to_its_program_and_arm(kin, protocol):
    kw = dict(loop_blocks_during_move=True, unreachable="alarm_halt", speed_scale=0.6,
              blend_across_input_read=False, ramp_shape="s_curve", accelerations=(5.0,) * 6, send_ahead="refused")
    vc = VirtualController(kinematics=kin, protocol=protocol, **kw)
    try:
        assert vc.program.loop_blocks_during_move and vc.program.unreachable is Unreachable.ALARM_HALT
        if protocol == "v1":
            assert isinstance(vc.arm, SimArm)            # v1's arm: the program's constant speeds, no ramps
        else:
            assert (vc.arm.speed_scale, vc.arm.blend_across_input_read, vc.arm.ramp_shape, vc.arm.accelerations) \
                == (0.6, False, RampShape.S_CURVE, (5.0,) * 6)
        if protocol == "v3":
            assert vc.program.send_ahead is SendAhead.REFUSED and vc.program.waits_ahead == 0
        assert SimOptions(protocol=protocol, **kw).controller_kwargs()["speed_scale"] == 0.6
    finally:
        vc.stop()
