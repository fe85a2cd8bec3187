"""The virtual G2 controller over a REAL pty pair, driven by our DpMaster and protocol.v1.MasterHandshake:
200 random reachable targets of all three move types plus unreachable ones (exactly once, in order,
converging), the DP watchdog stopping a motion, and the command line (pty link, log file, signals).

Waiting is always on events with deadlines (threading.Condition, the controller's wait_until, the
execution log's wait_for); the master thread paces its bus cycles, nothing sleeps to synchronise."""
from __future__ import annotations

import collections
import json
import os
import random
import select
import signal
import subprocess
import sys
import time
from typing import Deque, List, Optional, Tuple

import pytest

from pyprofibus_vendor.config import default_robot_config
from pyprofibus_vendor.dp_master import DpMaster
from pyprofibus_vendor.dp_slave import SlaveState
from pyprofibus_vendor.phy_serial import open_pty_pair

from vr_driver.controller.program import SimDeviceError, SimError, VirtualController, auto_pty_link
from vr_driver.errors import VrDriverError
from vr_driver.kinematics.preview import MotionPlanner, MoveType
from vr_driver.poses import ControllerPose, Workspace
from vr_driver.protocol.v1 import (Accepted, Command, ControllerState, Done, Feedback, HandshakeEvent,
                                MasterHandshake, Rejected, commands_for)
from vr_driver.controller.arm import Outcome

from _pty_master import ThreadedMaster

BAUD = 187500
SPEED = 60.0                     # motions 60x faster than the real arm
LOOP = 0.005                     # program loop of the virtual controller [s]
CYCLE = 0.002                    # master bus cycle period [s]
N_TARGETS = 200
ROBOT_CFG = default_robot_config("virtual", phy_type="memory").slave(4).cfg
UNREACHABLE = [(1400, 0, 1400, 0, 0, 0), (1400, 800, 200, 0, 90, 0), (-600, 0, 400, 0, 90, 180),
               (150, -900, 1400, 90, 0, 0)]

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
REPO = os.path.dirname(os.path.dirname(SRC))
PYTHONPATH = os.pathsep.join([SRC, os.path.join(REPO, "pyprofibus_vendor", "src"),
                              os.path.join(REPO, "panasonic_vr006l_support", "src")])


class MasterDriver(ThreadedMaster):
    """Our DP master on the pty, running MasterHandshake in its bus thread: commands queued with
    :meth:`send` go out one at a time; events and every decoded feedback are recorded."""

    def __init__(self, path, watchdog: float = 0.3, motion_timeout: float = 20.0) -> None:
        super().__init__(path, BAUD, ROBOT_CFG, watchdog=watchdog, cycle=CYCLE)
        self.hs = MasterHandshake(accept_timeout=2.0, release_timeout=2.0)
        self.motion_timeout = motion_timeout
        self.queue: Deque[Command] = collections.deque()
        self.sent: List[Command] = []
        self.events: List[HandshakeEvent] = []
        self.feedback: List[Tuple[float, Feedback]] = []
        self.last_cycle: Optional[float] = None
        self.cycles = 0
        self._inputs_time: Optional[float] = None
        self.start("test-master")

    def _on_cycle(self, master: DpMaster) -> None:
        now = time.monotonic()
        h = self.handle
        fb = None
        if h.connected and h.inputs is not None and h.inputs_time != self._inputs_time:
            self._inputs_time = h.inputs_time
            fb = Feedback.decode(h.inputs)
        with self.cond:
            event = self.hs.update(fb, now)
            if fb is not None:
                self.feedback.append((now, fb))
            if event is not None:
                self.events.append(event)
            if self.hs.ready and self.queue:
                command = self.queue.popleft()
                self.hs.submit(command, self.motion_timeout, now)
                self.sent.append(command)
            self.cycles += 1
            self.last_cycle = time.monotonic()
            self.cond.notify_all()
        h.outputs = self.hs.outputs().encode()

    def send(self, commands) -> None:
        with self.cond:
            self.queue.extend(commands)

    def finals(self) -> List[HandshakeEvent]:
        return [e for e in self.events if e.final]


def _rounded(pose: ControllerPose) -> Tuple[int, ...]:
    return Command.from_pose(pose, "ptp").values


def make_program(kin, start_joints, n: int, seed: int = 20240601):
    """``n`` reachable moves (PTP, LIN, CIRC in random order), each checked with the planner from the
    joints the previous one ends at (what the controller will do, deterministically), with the
    targets made from the FK of random joints and rounded to whole mm / deg. Every 20th move is
    followed by an unreachable target. Returns [(move type, target, via, reachable)]."""
    rng = random.Random(seed)
    planner = MotionPlanner(kin)
    box = Workspace()
    lo, hi = kin.limits.lower, kin.limits.upper
    q = tuple(start_joints)
    moves = []

    def near(q0, scale):
        return kin.clamp([v + rng.uniform(-scale, scale) for v in q0])

    while len([m for m in moves if m[3]]) < n:
        kind = rng.choice([MoveType.PTP, MoveType.LIN, MoveType.CIRC])
        via = None
        if kind is MoveType.PTP:
            goal = tuple(rng.uniform(max(a, -2.0), min(b, 2.0)) for a, b in zip(lo, hi))
        else:
            goal = near(q, 0.35)
        target = _rounded(kin.fk_pose(goal))
        if kind is MoveType.CIRC:
            mid = [0.5 * (a + b) + rng.uniform(-0.08, 0.08) for a, b in zip(q, goal)]
            via = _rounded(kin.fk_pose(kin.clamp(mid)))
        if not box.contains(ControllerPose(*target)) or (via and not box.contains(ControllerPose(*via))):
            continue
        try:
            traj = planner.plan(kind, q, target, via=via)
        except VrDriverError:
            continue
        if traj.duration > 4.0:
            continue
        moves.append((kind, target, via, True))
        q = traj.goal
        if len(moves) % 20 == 0:
            bad = UNREACHABLE[(len(moves) // 20) % len(UNREACHABLE)]
            moves.append((rng.choice([MoveType.PTP, MoveType.LIN]), bad, None, False))
    return moves


def test_200_random_targets_exactly_once_in_order(kin):
    vc = VirtualController(kinematics=kin, speed_factor=SPEED, loop_period=LOOP)
    moves = make_program(kin, vc.arm.joints, N_TARGETS)
    commands: List[Command] = []
    for kind, target, via, _ in moves:
        commands += commands_for(kind, target, via)
    vc.start()
    driver = MasterDriver(vc.device_path)
    t0 = time.monotonic()
    try:
        assert driver.wait(lambda: driver.handle.connected, 10.0), "the master did not connect"
        driver.send(commands)
        n = len(commands)
        assert driver.wait(lambda: len(driver.finals()) == n and driver.hs.ready, 120.0), \
            "only %d of %d targets answered" % (len(driver.finals()), n)
        elapsed = time.monotonic() - t0
        assert vc.log.wait_for(n, 5.0)
    finally:
        driver.stop()
        vc.stop()
    assert vc.error is None and vc.server_error is None

    # every command was sent once, in order, and the controller handled each exactly once
    assert driver.sent == commands
    entries = vc.log.entries()
    assert [(e.move_type, e.target) for e in entries] == [(c.move_type.name, c.values) for c in commands]
    assert [e.seq for e in entries] == list(range(1, n + 1))

    finals = driver.finals()
    assert [e.seq for e in finals] == list(range(1, n + 1))
    assert all(not isinstance(e, Rejected) or e.target.values in UNREACHABLE for e in finals)
    executed = rejected = vias = 0
    i = 0
    for kind, target, via, reachable in moves:
        if via is not None:
            assert isinstance(finals[i], Done) and entries[i].outcome is Outcome.VIA_STORED
            vias += 1
            i += 1
        event, entry = finals[i], entries[i]
        if reachable:
            assert isinstance(event, Done), (event, entry)
            assert entry.outcome is Outcome.EXECUTED
            dp, da = event.feedback.pose.distance_to(ControllerPose(*target))
            assert dp <= 1.0 and da <= 1.0, (target, event.feedback)
            executed += 1
        else:
            assert isinstance(event, Rejected) and entry.outcome is Outcome.REJECTED
            assert "Unreachable" in entry.reason or "JointLimit" in entry.reason
            # nothing moved: the pose after equals the pose before, and no BUSY for it
            assert entry.final_pose == entries[i - 1].final_pose
            assert not any(isinstance(e, Accepted) and e.seq == event.seq for e in driver.events)
            rejected += 1
        i += 1
    assert executed == N_TARGETS and rejected == N_TARGETS // 20 and i == n
    kinds = collections.Counter(m[0] for m in moves if m[3])
    assert all(kinds[k] >= 30 for k in MoveType)
    motion = sum(e.duration for e in entries if e.outcome is Outcome.EXECUTED)
    print("\n%d reachable targets (%s) + %d unreachable = %d wire commands (%d via) in %.1f s over the pty "
          "(%.1f s of it simulated motion at x%g), %d bus cycles, %d program loops, %d loop overruns"
          % (N_TARGETS, dict((k.name, v) for k, v in kinds.items()), rejected, n, vias, elapsed, motion, SPEED,
             driver.cycles, vc.program.loops, vc.overruns))


def test_watchdog_stops_the_arm_when_the_master_goes_silent(kin):
    watchdog = 0.2
    vc = VirtualController(kinematics=kin, speed_factor=1.0, loop_period=LOOP)
    vc.start()
    driver = MasterDriver(vc.device_path, watchdog=watchdog)
    try:
        assert driver.wait(lambda: driver.handle.connected, 10.0)
        target = (900, 300, 500, 0, 90, 30)                      # ~0.3 s of motion at x1
        driver.send(commands_for("ptp", target))
        assert driver.wait(lambda: any(isinstance(e, Accepted) for e in driver.events), 5.0)
        assert vc.wait_until(lambda fb: fb.x < 1100, 5.0)        # well under way
        driver.stop()                                            # the master goes silent mid-motion
        silent_since = driver.last_cycle
        assert vc.wait_until(lambda fb: vc.slave_state is SlaveState.WAIT_PRM and not vc.arm.moving, 2.0)
        stopped = vc.pose
        loops = vc.program.loops
        assert vc.wait_until(lambda fb: vc.program.loops >= loops + 10, 2.0)
        assert vc.pose == stopped                                 # and it stays there
        assert vc.state is ControllerState.READY
    finally:
        driver.stop()
        vc.stop()
    entry = vc.log[-1]
    assert entry.outcome is Outcome.REJECTED and entry.aborted and "watchdog" in entry.reason
    assert entry.final_pose == stopped and stopped != target
    # it moved no longer than the watchdog time after the master's last telegram
    assert entry.end_time - silent_since <= watchdog + 1e-3
    assert entry.end_time - silent_since >= watchdog - 0.05
    print("\nwatchdog %.0f ms: the arm stopped %.1f ms after the master's last cycle"
          % (watchdog * 1e3, (entry.end_time - silent_since) * 1e3))


def test_serves_an_existing_device(kin):
    """``VirtualController(device)``: the controller opens a device someone else made (here the
    slave end of a pty) and the master talks on the other end."""
    pair = open_pty_pair()
    vc = VirtualController(pair.slave_path, kinematics=kin, speed_factor=SPEED, loop_period=LOOP)
    vc.start()
    driver = MasterDriver(pair.master_link())
    try:
        assert driver.wait(lambda: driver.handle.connected, 10.0)
        commands = commands_for("lin", (1000, 100, 700, 0, 60, 0)) + commands_for("ptp", (1120, 0, 725, 0, 45, 0))
        driver.send(commands)
        assert driver.wait(lambda: len(driver.finals()) == 2 and driver.hs.ready, 20.0)
        assert [type(e) for e in driver.finals()] == [Done, Done]
        assert vc.device_path == pair.slave_path
    finally:
        driver.stop()
        vc.stop()
        pair.close()
    assert [(e.move_type, e.outcome) for e in vc.log.entries()] == [("LIN", Outcome.EXECUTED),
                                                                     ("PTP", Outcome.EXECUTED)]


def _readline(stream, timeout: float) -> str:
    end = time.monotonic() + timeout
    data = b""
    fd = stream.fileno()
    while not data.endswith(b"\n"):
        left = end - time.monotonic()
        assert left > 0, "no line from the controller within %.0f s (got %r)" % (timeout, data)
        ready, _, _ = select.select([fd], [], [], left)
        if ready:
            chunk = os.read(fd, 1)
            assert chunk, "the controller closed stdout (got %r)" % data
            data += chunk
    return data.decode().strip()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_cli_serves_a_pty_link_and_exits_cleanly(tmp_path, sig):
    link = str(tmp_path / "vr006l")
    log_file = str(tmp_path / "executed.jsonl")
    env = dict(os.environ, PYTHONPATH=PYTHONPATH)
    proc = subprocess.Popen(
        [sys.executable, "-m", "vr_driver.controller.program", "--pty-link", link, "--speed-factor", "50",
         "--loop-period", "0.005", "--log-file", log_file, "--initial-pose", "1000", "0", "700", "0", "60", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    driver = None
    try:
        device = _readline(proc.stdout, 30.0)
        assert device.startswith("/dev/pts/") and os.path.realpath(link) == device
        driver = MasterDriver(link)
        assert driver.wait(lambda: driver.handle.connected, 10.0)
        commands = (commands_for("ptp", (1120, 0, 725, 0, 45, 0)) + commands_for("lin", (1000, 100, 700, 0, 60, 0))
                    + commands_for("ptp", UNREACHABLE[0])
                    + commands_for("circ", (1120, 0, 725, 0, 45, 0), via=(1080, 80, 720, 0, 50, 0)))
        driver.send(commands)
        assert driver.wait(lambda: len(driver.finals()) == len(commands) and driver.hs.ready, 30.0)
        assert [type(e) for e in driver.finals()] == [Done, Done, Rejected, Done, Done]
    finally:
        if driver is not None:
            driver.stop()
        proc.send_signal(sig)
        try:
            rc = proc.wait(10.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5.0)
            raise
        err = proc.stderr.read().decode()
        proc.stdout.close()
        proc.stderr.close()
    assert rc == 0, err
    assert not os.path.lexists(link)
    with open(log_file) as f:
        lines = [json.loads(line) for line in f]
    assert [(d["seq"], d["move_type"], d["outcome"]) for d in lines] == [
        (1, "PTP", "executed"), (2, "LIN", "executed"), (3, "PTP", "rejected"), (4, "CIRC_VIA", "via_stored"),
        (5, "CIRC_END", "executed")]
    assert lines[1]["final_pose"] == [1000, 100, 700, 0, 60, 0]
    assert lines[4]["via"] == [1080, 80, 720, 0, 50, 0]


# ------------------------------------------------------------------ the pty link: per launch, locked

def test_auto_pty_link_is_per_master_port_under_the_ros_log_dir():
    assert (auto_pty_link({"ROS_MASTER_URI": "http://localhost:11400/", "ROS_LOG_DIR": "/x/log"})
            == "/x/log/vr006l_virtual_g2_11400")
    assert (auto_pty_link({"ROS_MASTER_URI": "http://host:11401", "ROS_HOME": "/h"})
            == "/h/log/vr006l_virtual_g2_11401")
    assert auto_pty_link({"ROS_HOME": "/h"}) == "/h/log/vr006l_virtual_g2_11311"      # ROS' default master
    with pytest.raises(SimError, match="ROS_MASTER_URI"):
        auto_pty_link({"ROS_MASTER_URI": "http://host/"})


def _lock_of(link):
    with open(link + ".lock") as f:
        return int(f.read())


def test_a_link_held_by_a_live_controller_is_refused_and_released_on_stop(tmp_path):
    link = str(tmp_path / "g2")
    first = VirtualController(pty_link=link)
    try:
        assert os.readlink(link) == first.device_path
        assert _lock_of(link) == os.getpid()
        with pytest.raises(SimDeviceError, match="in use by the live process %d" % os.getpid()):
            VirtualController(pty_link=link)
        assert os.readlink(link) == first.device_path           # the first one's link is untouched
    finally:
        first.stop()
    assert not os.path.lexists(link) and not os.path.exists(link + ".lock")
    again = VirtualController(pty_link=link)
    again.stop()


def test_a_link_locked_by_another_live_process_is_refused_until_that_process_ends(tmp_path):
    link = str(tmp_path / "g2")
    holder = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        os.symlink("/dev/null", link)
        with open(link + ".lock", "w") as f:
            f.write("%d\n" % holder.pid)
        with pytest.raises(SimDeviceError) as err:
            VirtualController(pty_link=link)
        assert "in use by the live process %d" % holder.pid in str(err.value)
        assert "sim_port" in str(err.value)                      # says what to do
        assert os.readlink(link) == "/dev/null"
    finally:
        holder.stdin.close()
        holder.wait(10)
    taken = VirtualController(pty_link=link)                    # its process is gone: a stale lock
    try:
        assert os.readlink(link) == taken.device_path
        assert _lock_of(link) == os.getpid()
    finally:
        taken.stop()
