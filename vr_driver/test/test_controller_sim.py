"""The virtual G2 controller with an injected clock: the simulated arm (timing and path of PTP / LIN /
CIRC from the reported poses, rejections, faults), the program loop on a real DpSlave driven by
telegrams and protocol.v1.MasterHandshake, the watchdog, the log, the options and the CLI's exit codes.
Nothing here sleeps; the pty tests are in test_controller_sim_pty.py."""
from __future__ import annotations

import json
import math
import threading
from typing import Callable, List, Tuple

import numpy as np
import pytest

from pyprofibus_vendor.dp import PrmStationStatus, Sap, SetPrm
from pyprofibus_vendor.dp_slave import SlaveState

from vr_driver.controller.cli import main
from vr_driver.controller.options import SimOptions
from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import robot_slave, VirtualController
from vr_driver.errors import JointLimitError, MotionError, UnreachableError
from vr_driver.poses import HOME_POSE
from vr_driver.protocol.v1 import (Accepted, Command, ControllerState, Done, Feedback, MasterHandshake, Rejected,
                                StatusBits, WireMoveType)
from vr_driver.controller.arm import ExecutionLog, LogEntry, Outcome, SimArm, round_pose

from _slave_rig import SlaveRig

PERIOD = 0.01
SPEED = 4.0
UNREACHABLE = (2000, 0, 500, 0, 90, 0)          # 2 m out: beyond the reach
OUT_OF_LIMITS = (-600, 0, 400, 0, 90, 180)      # behind the robot: only with joint_1 = pi


class Rig(SlaveRig):
    """Fake clock + robot DpSlave + SimArm + ControllerProgram, and a minimal DP master (telegrams
    straight into DpSlave.handle) running protocol.v1.MasterHandshake: one bus cycle per program loop."""

    def __init__(self, kin, speed: float = SPEED, period: float = PERIOD, watchdog_units: int = 10,
                 **arm_kw) -> None:
        super().__init__(period, watchdog_units)
        clock = self.clock
        self.slave = robot_slave(4, clock)
        self.arm = SimArm(kin, speed_factor=speed, clock=clock, **arm_kw)
        self.prog = ControllerProgram(self.slave, self.arm)
        self.master = MasterHandshake(accept_timeout=0.5, release_timeout=0.5, settle_time=0.0, clock=clock)
        self.trace: List[Tuple[float, Feedback]] = []

    def loop(self, n: int = 1):
        """n rounds of: advance the clock, one Data_Exchange (if exchanging), one program loop."""
        events = []
        for _ in range(n):
            self.t += self.period
            if self.exchanging and self.slave.state is SlaveState.DATA_EXCH:
                reply = self.call(None, self.master.outputs().encode())
                fb = Feedback.decode(reply.data)
                ev = self.master.update(fb, self.t)
                if ev is not None:
                    events.append(ev)
            fb = self.prog.step(self.t)
            self.trace.append((self.t, fb))
        return events

    def until(self, pred: Callable[[], bool], max_time: float = 30.0) -> None:
        end = self.t + max_time
        while not pred():
            assert self.t < end, "condition not reached within %.1f s of fake time" % max_time
            self.loop()

    def run(self, command: Command, max_time: float = 30.0):
        """Submit one command, run to its final event and back to IDLE; returns (events, trace)."""
        self.until(lambda: self.master.ready, 5.0)
        start = len(self.trace)
        self.master.submit(command, motion_timeout=max_time, now=self.t)
        events = []
        end = self.t + max_time
        while not (events and events[-1].final and self.master.ready):
            assert self.t < end, "no answer to %s" % command.describe()
            events += self.loop()
        return events, self.trace[start:]


def cmd(pose, kind) -> Command:
    return Command.from_pose(pose, WireMoveType.parse(kind))


def busy_poses(trace) -> List[Tuple[float, ...]]:
    return [fb.values for _, fb in trace if fb.state is ControllerState.BUSY]


@pytest.fixture
def rig(kin):
    r = Rig(kin)
    r.connect()
    return r


# ------------------------------------------------------------------------------------------ SimArm

def test_arm_starts_at_home_and_reports_whole_units(kin):
    arm = SimArm(kin, clock=lambda: 0.0)
    assert arm.reported_pose() == (1120, 0, 725, 0, 45, 0)
    dp, da = arm.pose.distance_to(HOME_POSE)
    assert dp < 1e-3 and da < 1e-3
    assert not arm.moving and arm.drives_powered and not arm.estop and arm.error is None
    assert round_pose((0.5, -0.5, 2.5, 179.6, -180.0, -0.4)) == (1, -1, 3, 180, 180, 0)


def test_arm_read_outs_are_read_only_and_taken_under_the_lock(kin):
    """joints, pose, estop, error, last_step_time (controller.arm.LockedRead): the value as of the
    last step, read under the arm's lock, and not assignable."""
    arm = SimArm(kin, clock=lambda: 0.0)
    arm.set_estop(True)
    assert arm.estop and arm.joints == arm._joints and SimArm.joints.__doc__.startswith("The exact joints")
    for name in ("joints", "pose", "estop", "error", "last_step_time"):
        with pytest.raises(AttributeError, match="%s is read-only" % name):
            setattr(arm, name, None)
    taken = threading.Event()
    release = threading.Event()

    def hold_the_lock() -> None:
        with arm._lock:
            taken.set()
            release.wait(5.0)
    holder = threading.Thread(target=hold_the_lock)
    holder.start()
    assert taken.wait(5.0)
    reader = threading.Thread(target=lambda: arm.joints)
    reader.start()
    reader.join(0.2)
    assert reader.is_alive()                   # waits for the lock
    release.set()
    reader.join(5.0)
    holder.join(5.0)
    assert not reader.is_alive()


def test_arm_initial_pose_and_joints(kin):
    arm = SimArm(kin, initial_pose=(900, 300, 500, 0, 90, 30), clock=lambda: 0.0)
    assert arm.reported_pose() == (900, 300, 500, 0, 90, 30)
    arm2 = SimArm(kin, initial_joints=arm.joints, clock=lambda: 0.0)
    assert arm2.reported_pose() == (900, 300, 500, 0, 90, 30)
    with pytest.raises(UnreachableError):
        SimArm(kin, initial_pose=UNREACHABLE)
    with pytest.raises(MotionError):
        SimArm(kin, speed_factor=0.0)


@pytest.mark.parametrize("speed", [1.0, 25.0])
def test_arm_ptp_timing_is_planner_duration_over_speed(kin, planner, speed):
    arm = SimArm(kin, speed_factor=speed, clock=lambda: 0.0)
    target = (900, 300, 500, 0, 90, 30)
    expected = planner.plan("ptp", arm.joints, target).duration / speed
    ok, why = arm.begin("ptp", target, now=0.0)
    assert ok, why
    dt = 0.002
    t, result, joints = 0.0, None, [arm.joints]
    while result is None:
        t += dt
        result = arm.step(t)
        joints.append(arm.joints)
    assert result.ok and not result.aborted
    assert expected <= t < expected + dt + 1e-9
    assert arm.reported_pose() == target
    # joint interpolation: every sample on the straight joint-space segment start -> goal
    q = np.array(joints)
    d = q[-1] - q[0]
    for row in q:
        s = float((row - q[0]) @ d / (d @ d))
        assert np.allclose(row, q[0] + s * d, atol=1e-9)


def test_arm_refuses_and_stays_put(kin):
    arm = SimArm(kin, clock=lambda: 0.0)
    before = arm.joints
    ok, why = arm.begin("ptp", UNREACHABLE, now=0.0)
    assert not ok and "UnreachableError" in why
    with pytest.raises(JointLimitError):
        kin.ik_pose(OUT_OF_LIMITS)
    ok, why = arm.begin("lin", OUT_OF_LIMITS, now=0.0)
    assert not ok and "JointLimitError" in why
    ok, why = arm.begin("circ", (1000, 100, 700, 0, 45, 0), now=0.0)
    assert not ok and "via" in why
    assert arm.joints == before and not arm.moving and arm.step(1.0) is None


def test_arm_busy_while_moving(kin):
    arm = SimArm(kin, clock=lambda: 0.0)
    assert arm.begin("ptp", (900, 300, 500, 0, 90, 30), now=0.0)[0]
    ok, why = arm.begin("ptp", (900, 0, 500, 0, 90, 30), now=0.01)
    assert not ok and "already" in why
    assert arm.motion_remaining(0.01) > 0


def test_arm_target_equal_to_the_current_pose_completes_at_once(kin):
    arm = SimArm(kin, clock=lambda: 0.0)
    assert arm.begin("lin", HOME_POSE, now=0.0) == (True, "")
    assert arm.motion_remaining(0.0) < 1e-3
    result = arm.step(0.001)
    assert result is not None and result.ok


@pytest.mark.parametrize("fault", ["estop", "drives", "error"])
def test_arm_fault_during_motion_stops_at_that_instant(kin, fault):
    arm = SimArm(kin, speed_factor=1.0, clock=lambda: 0.0)
    traj = arm.plan("ptp", (900, 300, 500, 0, 90, 30))
    assert arm.begin("ptp", (900, 300, 500, 0, 90, 30), now=0.0)[0]
    arm.step(0.05)
    t_stop = 0.5 * traj.duration
    inject = {"estop": lambda: arm.set_estop(True, now=t_stop),
              "drives": lambda: arm.set_drives_powered(False, now=t_stop),
              "error": lambda: arm.set_error("overload", now=t_stop)}
    inject[fault]()
    result = arm.step(t_stop + 0.5)
    assert result is not None and not result.ok and result.aborted and result.end_time == t_stop
    assert np.allclose(arm.joints, SimArm._sample(traj, t_stop), atol=1e-12)
    frozen = arm.joints
    assert arm.step(t_stop + 5.0) is None and arm.joints == frozen
    assert arm.blocked_reason() is not None
    ok, why = arm.begin("ptp", HOME_POSE, now=t_stop + 6)
    assert not ok and why == arm.blocked_reason()
    arm.set_estop(False)
    arm.set_drives_powered(True)
    arm.set_error(None)
    assert arm.blocked_reason() is None
    assert arm.begin("ptp", HOME_POSE, now=t_stop + 7)[0]


def test_estop_cuts_the_drive_power_and_they_stay_off_until_switched_on(kin):
    """issue 15: the virtual controller powered the drives back on when the e-stop was released;
    a real G2 needs the drives switched on again."""
    arm = SimArm(kin, clock=lambda: 0.0)
    arm.set_estop(True)
    assert not arm.drives_powered and arm.blocked_reason() == "e-stop pressed"
    assert arm.set_drives_powered(True) is False and not arm.drives_powered   # not under e-stop
    arm.set_estop(False)
    assert not arm.drives_powered and arm.blocked_reason() == "drives not powered"
    assert arm.set_drives_powered(True) is True
    assert arm.drives_powered and arm.blocked_reason() is None


# ------------------------------------------------------------------------- program loop + handshake

def test_ptp_over_the_handshake_timing_and_log(rig, planner):
    target = (900, 300, 500, 0, 90, 30)
    expected = planner.plan("ptp", rig.arm.joints, target).duration / SPEED
    events, trace = rig.run(cmd(target, "ptp"))
    assert [type(e) for e in events] == [Accepted, Done]
    states = [fb.state for _, fb in trace]
    assert ControllerState.BUSY in states and states[-1] is ControllerState.READY
    assert trace[-1][1].values == target
    [entry] = rig.prog.log.entries()
    assert (entry.seq, entry.move_type, entry.target, entry.outcome) == (1, "PTP", target, Outcome.EXECUTED)
    assert entry.final_pose == target and entry.reason == "" and not entry.aborted
    assert expected <= entry.duration < expected + PERIOD + 1e-9
    # moving: IN_MOTION set and the pose reported every loop
    moving = [fb for _, fb in trace if fb.state is ControllerState.BUSY]
    assert all(fb.status & StatusBits.IN_MOTION for fb in moving)
    assert len(moving) >= int(expected / PERIOD) - 1
    assert all(fb.status & StatusBits.PROGRAM_RUNNING and fb.status & StatusBits.DRIVES_POWERED
               for _, fb in trace)


def _dist_to_segment(p, a, b) -> float:
    d = b - a
    s = min(1.0, max(0.0, float((p - a) @ d / (d @ d))))
    return float(np.linalg.norm(p - (a + s * d)))


def test_lin_stays_within_1mm_of_the_line(rig, planner):
    start = np.array(rig.arm.pose.as_tuple()[:3])
    target = (900, -350, 450, 0, 90, -20)
    expected = planner.plan("lin", rig.arm.joints, target).duration / SPEED
    events, trace = rig.run(cmd(target, "lin"))
    assert isinstance(events[-1], Done)
    pts = [np.array(p[:3], dtype=float) for p in busy_poses(trace)]
    assert len(pts) > 20
    end = np.array(target[:3], dtype=float)
    worst = max(_dist_to_segment(p, start, end) for p in pts)
    assert worst <= 1.0
    # progress along the line never goes back (beyond the 1 mm rounding of two samples)
    unit = (end - start) / np.linalg.norm(end - start)
    along = [float((p - start) @ unit) for p in pts]
    assert all(b >= a - 2.0 for a, b in zip(along, along[1:]))
    assert along[-1] - along[0] > 0.9 * float(np.linalg.norm(end - start))
    entry = rig.prog.log[-1]
    assert entry.outcome is Outcome.EXECUTED and entry.final_pose == target
    assert expected <= entry.duration < expected + PERIOD + 1e-9


def _circle(p0, p1, p2):
    a, b = p1 - p0, p2 - p0
    n = np.cross(a, b)
    centre = p0 + (float(a @ a) * np.cross(b, n) + float(b @ b) * np.cross(n, a)) / (2.0 * float(n @ n))
    return centre, n / np.linalg.norm(n), float(np.linalg.norm(p0 - centre))


def test_circ_through_the_stored_via_point(rig, planner):
    start_pose = rig.arm.pose
    via, end = (1000, 250, 650, 0, 60, 10), (850, 350, 500, 0, 80, 20)
    expected = planner.plan("circ", rig.arm.joints, end, via=via).duration / SPEED
    events, trace = rig.run(cmd(via, "circ_via"))
    assert [type(e) for e in events] == [Done]
    assert all(fb.state is not ControllerState.BUSY for _, fb in trace)   # no motion for the via
    assert trace[-1][1].status & StatusBits.VIA_STORED
    assert rig.arm.reported_pose() == round_pose(start_pose)
    events, trace = rig.run(cmd(end, "circ_end"))
    assert [type(e) for e in events] == [Accepted, Done]
    assert not trace[-1][1].status & StatusBits.VIA_STORED                # consumed
    centre, normal, radius = _circle(np.array(start_pose.as_tuple()[:3]), np.array(via[:3], float),
                                     np.array(end[:3], float))
    pts = [np.array(p[:3], dtype=float) for p in busy_poses(trace)]
    assert len(pts) > 20
    for p in pts:
        rel = p - centre
        off = float(rel @ normal)
        assert math.hypot(off, np.linalg.norm(rel - off * normal) - radius) <= 1.0
    spacing = max(float(np.linalg.norm(b - a)) for a, b in zip(pts, pts[1:]))
    assert min(float(np.linalg.norm(p - np.array(via[:3]))) for p in pts) <= spacing / 2 + 1.0
    via_entry, end_entry = rig.prog.log.entries()
    assert (via_entry.move_type, via_entry.outcome) == ("CIRC_VIA", Outcome.VIA_STORED)
    assert (end_entry.move_type, end_entry.outcome, end_entry.via) == ("CIRC_END", Outcome.EXECUTED, via)
    assert end_entry.final_pose == end
    assert expected <= end_entry.duration < expected + PERIOD + 1e-9


@pytest.mark.parametrize("target,kind,words", [
    (UNREACHABLE, "ptp", "UnreachableError"),
    (UNREACHABLE, "lin", "UnreachableError"),
    (OUT_OF_LIMITS, "ptp", "JointLimitError"),
    ((1000, 100, 700, 0, 45, 0), "circ_end", "without a stored via"),
])
def test_rejected_targets_move_nothing(rig, target, kind, words):
    before = rig.arm.joints
    events, trace = rig.run(cmd(target, kind))
    assert [type(e) for e in events] == [Rejected]
    assert all(fb.state is not ControllerState.BUSY for _, fb in trace)
    assert all(fb.values == (1120, 0, 725, 0, 45, 0) for _, fb in trace)
    assert rig.arm.joints == before
    [entry] = rig.prog.log.entries()
    assert entry.outcome is Outcome.REJECTED and words in entry.reason and not entry.aborted
    assert entry.final_pose == (1120, 0, 725, 0, 45, 0)
    # the next (reachable) target runs normally
    events, _ = rig.run(cmd((1000, 0, 700, 0, 60, 0), "ptp"))
    assert isinstance(events[-1], Done)


def test_via_serves_only_the_next_request(rig):
    rig.run(cmd((1000, 250, 650, 0, 60, 10), "circ_via"))
    events, _ = rig.run(cmd((1000, 0, 700, 0, 60, 0), "ptp"))
    assert isinstance(events[-1], Done)
    events, _ = rig.run(cmd((850, 350, 500, 0, 80, 20), "circ_end"))
    assert isinstance(events[-1], Rejected)
    assert [e.outcome for e in rig.prog.log.entries()] == [Outcome.VIA_STORED, Outcome.EXECUTED,
                                                           Outcome.REJECTED]


@pytest.mark.parametrize("fault,bit_set,bit_clear,words", [
    ("estop", StatusBits.ESTOP, StatusBits.DRIVES_POWERED, "e-stop"),
    ("drives_powered", StatusBits(0), StatusBits.DRIVES_POWERED, "drives not powered"),
    ("error", StatusBits.ERROR, StatusBits(0), "controller error"),
])
def test_requests_rejected_while_a_fault_is_active(rig, fault, bit_set, bit_clear, words):
    setter = {"estop": lambda on: rig.arm.set_estop(True) if on else
              (rig.arm.set_estop(False), rig.arm.set_drives_powered(True)),
              "drives_powered": lambda on: rig.arm.set_drives_powered(not on),
              "error": lambda on: rig.arm.set_error(on)}[fault]
    setter(True)
    events, trace = rig.run(cmd((1000, 0, 700, 0, 60, 0), "ptp"))
    assert [type(e) for e in events] == [Rejected]
    fb = events[-1].feedback
    assert fb.status & bit_set == bit_set and not fb.status & bit_clear
    assert rig.prog.log[-1].outcome is Outcome.REJECTED and words in rig.prog.log[-1].reason
    assert rig.arm.reported_pose() == (1120, 0, 725, 0, 45, 0)
    # a via point is refused too (nothing is stored while the arm cannot move)
    events, trace = rig.run(cmd((1000, 250, 650, 0, 60, 10), "circ_via"))
    assert isinstance(events[-1], Rejected) and not trace[-1][1].status & StatusBits.VIA_STORED
    setter(False)
    events, trace = rig.run(cmd((1000, 0, 700, 0, 60, 0), "ptp"))
    assert isinstance(events[-1], Done)
    assert trace[-1][1].status & (StatusBits.ESTOP | StatusBits.ERROR) == 0
    assert trace[-1][1].status & StatusBits.DRIVES_POWERED


@pytest.mark.parametrize("fault", ["estop", "drives_powered", "error"])
def test_fault_mid_motion_stops_the_arm_and_rejects_the_target(rig, fault):
    rig.until(lambda: rig.master.ready)
    rig.master.submit(cmd((900, 300, 500, 0, 90, 30), "ptp"), motion_timeout=30, now=rig.t)
    rig.until(lambda: rig.arm.moving)
    rig.loop(5)
    start = len(rig.trace)
    {"estop": lambda: rig.arm.set_estop(True, now=rig.t),
     "drives_powered": lambda: rig.arm.set_drives_powered(False, now=rig.t),
     "error": lambda: rig.arm.set_error(True, now=rig.t)}[fault]()
    t_stop = rig.t
    stopped_at = rig.arm.reported_pose()
    events = rig.loop(20)
    assert [type(e) for e in events] == [Rejected]
    after = rig.trace[start:]
    assert all(fb.values == stopped_at for _, fb in after)
    assert not any(fb.status & StatusBits.IN_MOTION for _, fb in after)
    entry = rig.prog.log[-1]
    assert entry.outcome is Outcome.REJECTED and entry.aborted and entry.end_time == t_stop
    assert entry.final_pose == stopped_at and stopped_at != entry.target
    assert rig.prog.state is ControllerState.READY      # the master dropped its flag


def test_watchdog_stops_the_arm_at_the_deadline_and_resets(kin):
    rig = Rig(kin, speed=1.0, watchdog_units=10)       # 100 ms
    rig.connect()
    rig.until(lambda: rig.master.ready)
    rig.master.submit(cmd((900, 300, 500, 0, 90, 30), "ptp"), motion_timeout=30, now=rig.t)
    rig.until(lambda: rig.arm.moving)
    rig.loop(3)
    rig.exchanging = False                               # the master goes silent
    last = rig.last_rx
    deadline = last + 0.1
    rig.until(lambda: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
    assert rig.t - deadline <= PERIOD + 1e-9
    assert not rig.arm.moving and rig.prog.state is ControllerState.READY
    assert not rig.prog.handshake.via_stored
    entry = rig.prog.log[-1]
    assert entry.outcome is Outcome.REJECTED and entry.aborted and "watchdog" in entry.reason
    assert entry.end_time == pytest.approx(deadline)
    assert rig.arm.last_step_time <= rig.t
    frozen = rig.arm.joints
    rig.loop(10)
    assert rig.arm.joints == frozen
    assert rig.slave.outputs == bytes(14)               # safe image
    assert rig.prog.link_losses == 1
    # reconnect: a fresh master syncs on READY and works
    rig.master.reset(now=rig.t)
    rig.exchanging = True
    rig.connect()
    events, _ = rig.run(cmd((1000, 0, 700, 0, 60, 0), "ptp"))
    assert isinstance(events[-1], Done)


def test_a_request_older_than_the_watchdog_never_starts(kin):
    rig = Rig(kin, watchdog_units=5)                   # 50 ms
    rig.connect()
    rig.loop(3)
    # a raised flag reaches the slave, then the master dies before the program loop ran
    rig.t += PERIOD
    rig.call(None, cmd((1000, 0, 700, 0, 60, 0), "ptp").encode())
    rig.t += 0.2
    rig.exchanging = False
    rig.loop(5)
    assert rig.slave.state is SlaveState.WAIT_PRM
    assert not rig.arm.moving and len(rig.prog.log) == 0
    assert rig.arm.reported_pose() == (1120, 0, 725, 0, 45, 0)


def test_malformed_records_are_ignored(rig):
    raw = bytearray(cmd((1000, 0, 700, 0, 60, 0), "ptp").encode())
    raw[13] = 9                                          # unknown move type
    for _ in range(3):
        rig.t += PERIOD
        rig.call(None, bytes(raw))
        rig.prog.step(rig.t)
    assert rig.prog.bad_records == 3 and rig.prog.state is ControllerState.READY
    assert not rig.arm.moving and len(rig.prog.log) == 0


def test_log_entry_json():
    e = LogEntry(3, "LIN", (1, 2, 3, 4, 5, 6), Outcome.REJECTED, "why", 1.0, 1.5, (1, 2, 3, 4, 5, 6),
                 aborted=True)
    d = json.loads(e.to_json())
    assert d == {"seq": 3, "time": 1.5, "start_time": 1.0, "duration": 0.5, "move_type": "LIN",
                 "target": [1, 2, 3, 4, 5, 6], "via": None, "outcome": "rejected", "reason": "why",
                 "aborted": True, "final_pose": [1, 2, 3, 4, 5, 6]}


def test_execution_log_is_thread_safe():
    log = ExecutionLog()
    seen: List[int] = []
    log.add_listener(lambda e: seen.append(e.seq))
    log.add_listener(lambda e: 1 / 0)                   # a broken listener does not stop the others
    ready = threading.Event()

    def writer(base: int) -> None:
        ready.wait(5)
        for i in range(200):
            log.append(LogEntry(base + i, "PTP", (0,) * 6, Outcome.EXECUTED, "", 0.0, 0.0, (0,) * 6))

    threads = [threading.Thread(target=writer, args=(k * 1000,)) for k in range(4)]
    for th in threads:
        th.start()
    ready.set()
    assert log.wait_for(800, timeout=10)
    for th in threads:
        th.join(5)
    assert len(log) == 800 and sorted(e.seq for e in log.entries()) == sorted(seen)
    assert len(log.listener_errors) == 800
    assert not log.wait_for(801, timeout=0.0)


# ------------------------------------------------------------------------------- options and CLI

def test_options_validation():
    o = SimOptions.from_mapping({"pty_link": "/tmp/x", "addr": 5, "baud": 187500, "speed_factor": 3,
                                 "initial_pose": [1000, 0, 700, 0, 60, 0], "loop_period": 0.005})
    assert (o.pty_link, o.address, o.baud, o.speed_factor, o.loop_period) == ("/tmp/x", 5, 187500, 3.0, 0.005)
    assert o.initial_pose == (1000, 0, 700, 0, 60, 0) and o.device is None
    assert SimOptions(device="", pty_link="").device is None
    for bad in ({"addr": 130}, {"addr": 4.5}, {"baud": 12345}, {"speed_factor": 0}, {"speed_factor": "x"},
                {"loop_period": -1}, {"initial_pose": [1, 2, 3]}, {"byte_order": "middle"},
                {"device": "/dev/null", "pty_link": "/tmp/x"}, {"bogus": 1}):
        with pytest.raises(SimError):
            SimOptions.from_mapping(bad)


def test_cli_bad_option_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--speed-factor", "fast"])
    assert exc.value.code == 2
    assert main(["--speed-factor", "0"]) == 2
    assert main(["--baud", "1234"]) == 2
    assert main(["--initial-pose", "3000", "0", "0", "0", "0", "0"]) == 2
    assert "unreachable" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["--device", "/dev/null", "--pty-link", "/tmp/x"])
    assert exc.value.code == 2


def test_cli_device_problem_exits_3(tmp_path, capsys):
    assert main(["--device", str(tmp_path / "no-such-tty")]) == 3
    assert "device error" in capsys.readouterr().err
    blocker = tmp_path / "regular-file"
    blocker.write_text("keep me")
    assert main(["--pty-link", str(blocker)]) == 3
    assert blocker.read_text() == "keep me"


def test_cli_help_exits_0(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for opt in ("--pty-link", "--device", "--addr", "--baud", "--speed-factor", "--initial-pose",
                "--loop-period", "--log-file"):
        assert opt in text


def test_set_fault_service_logic(kin, tmp_path):
    vc = VirtualController(kinematics=kin, pty_link=str(tmp_path / "tty"))
    try:
        assert (tmp_path / "tty").is_symlink()
        assert vc.set_fault("estop", True)[0] and vc.arm.estop
        ok, msg = vc.set_fault("drives_powered", True)
        assert not ok and "e-stop" in msg and not vc.arm.drives_powered
        ok, msg = vc.set_fault("estop", False)
        assert ok and "stay off" in msg and not vc.arm.drives_powered
        assert vc.set_fault("drives_powered", True)[0] and vc.arm.drives_powered
        assert vc.set_fault("error", True)[0] and vc.arm.error
        assert vc.set_fault("error", False)[0] and vc.arm.error is None
        assert not vc.set_fault("overheat", True)[0]
        fb = vc.step()
        assert fb.state is ControllerState.READY and fb.values == (1120, 0, 725, 0, 45, 0)
        assert vc.feedback == fb and vc.slave_state is SlaveState.WAIT_PRM
    finally:
        vc.stop()
    assert not (tmp_path / "tty").exists()


def test_core_modules_import_without_ros():
    """controller.virtual_controller and controller.arm are core modules: they import with rospy and every *_msgs blocked."""
    import os
    import subprocess
    import sys
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
    repo = os.path.dirname(os.path.dirname(src))
    paths = [src, os.path.join(repo, "pyprofibus_vendor", "src"), os.path.join(repo, "panasonic_vr006l_support", "src")]
    script = ("import sys\n"
              "for name in ('rospy', 'rospkg', 'roslib', 'std_msgs', 'std_srvs'):\n"
              "    sys.modules[name] = None\n"
              "sys.path[:0] = %r\n"
              "import vr_driver.controller.virtual_controller, vr_driver.controller.arm\n"
              "assert not [m for m in sys.modules if m.endswith('_msgs') and sys.modules[m] is not None]\n"
              "print('ok')\n" % (paths,))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_node_parameter_split():
    pytest.importorskip("rospy")
    pytest.importorskip("std_srvs.srv")
    from vr_driver.ros.virtual_controller import split_params
    params = {"pty_link": "/tmp/x", "addr": 4, "device_path": "/dev/pts/3", "typo_speed": 2}
    known, unknown = split_params(params)
    assert known == {"pty_link": "/tmp/x", "addr": 4} and unknown == ("typo_speed",)
    assert SimOptions.from_mapping(known).pty_link == "/tmp/x"


def test_a_flag_raised_before_the_link_came_up_is_rejected(kin):
    rig = Rig(kin)
    prm = SetPrm(ident=0x06C6, station_status=PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON,
                 wd_fact1=10, wd_fact2=1)
    rig.call(Sap.SET_PRM, prm.encode())
    rig.call(Sap.CHK_CFG, rig.slave.cfg)
    rig.prog.step(rig.t)                                 # in Data_Exchange, no record from the master yet
    assert rig.prog.last_command is None and not rig.prog.armed
    stale = cmd((1000, 0, 700, 0, 60, 0), "ptp")
    for _ in range(5):                                   # the very first record has the flag raised
        rig.t += PERIOD
        rig.call(None, stale.encode())
        fb = rig.prog.step(rig.t)
    assert fb.state is ControllerState.REJECTED and not rig.arm.moving
    [entry] = rig.prog.log.entries()
    assert entry.outcome is Outcome.REJECTED and "already raised" in entry.reason
    assert rig.arm.reported_pose() == (1120, 0, 725, 0, 45, 0)
    rig.t += PERIOD
    rig.call(None, stale.with_request(False).encode())
    assert rig.prog.step(rig.t).state is ControllerState.READY and rig.prog.armed
    rig.t += PERIOD
    rig.call(None, stale.encode())
    assert rig.prog.step(rig.t).state is ControllerState.BUSY


def test_a_master_that_keeps_its_flag_across_a_link_loss_gets_rejected(kin):
    rig = Rig(kin, speed=1.0, watchdog_units=10)
    rig.connect()
    target = cmd((900, 300, 500, 0, 90, 30), "ptp")
    rig.master.submit(target, motion_timeout=30, now=rig.t)
    rig.until(lambda: rig.arm.moving)
    rig.exchanging = False
    rig.until(lambda: rig.slave.state is SlaveState.WAIT_PRM, 1.0)
    stopped = rig.arm.reported_pose()
    # a naive master reconnects and goes on sending the same raised flag
    prm = SetPrm(ident=0x06C6, station_status=PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON,
                 wd_fact1=10, wd_fact2=1)
    rig.call(Sap.SET_PRM, prm.encode())
    rig.call(Sap.CHK_CFG, rig.slave.cfg)
    for _ in range(10):
        rig.t += PERIOD
        rig.call(None, target.encode())
        fb = rig.prog.step(rig.t)
    assert fb.state is ControllerState.REJECTED and not rig.arm.moving
    assert rig.arm.reported_pose() == stopped
    aborted, stale = rig.prog.log.entries()
    assert aborted.aborted and "watchdog" in aborted.reason
    assert stale.outcome is Outcome.REJECTED and "already raised" in stale.reason and not stale.aborted


def test_reparameterised_between_two_loops_counts_as_a_link_loss(kin):
    rig = Rig(kin, speed=1.0)
    rig.connect()
    rig.master.submit(cmd((900, 300, 500, 0, 90, 30), "ptp"), motion_timeout=30, now=rig.t)
    rig.until(lambda: rig.arm.moving)
    rig.loop(3)
    # the master restarts: Set_Prm + Chk_Cfg + Data_Exchange, all before the next program loop
    rig.t += PERIOD
    prm = SetPrm(ident=0x06C6, station_status=PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON,
                 wd_fact1=10, wd_fact2=1)
    rig.call(Sap.SET_PRM, prm.encode())
    rig.call(Sap.CHK_CFG, rig.slave.cfg)
    rig.call(None, Command.idle().encode())
    fb = rig.prog.step(rig.t)
    assert rig.slave.state is SlaveState.DATA_EXCH
    assert rig.prog.link_losses == 1 and not rig.arm.moving and fb.state is ControllerState.READY
    entry = rig.prog.log[-1]
    assert entry.aborted and "link to the master lost" in entry.reason and "parameterised" in entry.reason


def test_flag_2_stops_the_motion_and_rejects_the_target(rig):
    rig.until(lambda: rig.master.ready)
    rig.master.submit(cmd((900, 300, 500, 0, 90, 30), "ptp"), motion_timeout=30, now=rig.t)
    rig.until(lambda: rig.arm.moving)
    rig.loop(5)
    before = rig.arm.reported_pose()
    assert rig.master.abort("cancelled", now=rig.t, stop=True) is not None
    rig.until(lambda: not rig.arm.moving, 0.05)             # the next loop halts it
    stopped = rig.arm.reported_pose()
    rig.until(lambda: rig.master.ready, 2.0)
    assert rig.arm.reported_pose() == stopped != (900, 300, 500, 0, 90, 30) and stopped != before
    entry = rig.prog.log[-1]
    assert entry.outcome is Outcome.REJECTED and entry.aborted and "flag 2" in entry.reason
    assert rig.prog.state is ControllerState.READY
    events, _ = rig.run(cmd((1000, 0, 700, 0, 60, 0), "lin"))   # and it goes on normally
    assert isinstance(events[-1], Done)


def test_flag_2_outside_a_motion_is_no_request(rig):
    stop = cmd((1000, 0, 700, 0, 60, 0), "ptp").with_stop()
    for _ in range(3):
        rig.t += PERIOD
        rig.call(None, stop.encode())
        assert rig.prog.step(rig.t).state is ControllerState.READY
    assert not rig.arm.moving and len(rig.prog.log) == 0 and rig.prog.bad_records == 0
