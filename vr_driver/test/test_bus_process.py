"""The bus in a process of its own (vr_driver.bus): its health figures (stepped, plain numbers), and
over a REAL pty with the virtual G2: the driver on a bus process; the bus process killed mid-move
(the node says so, nothing is sent twice, a new bus process drives again); the node killed mid-move
(the bus process stops the arm, then ends); the requests' wake-up (the inbox's) ends the link's wait
for the bus process's next report, without a call into the bus side."""
from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time

import pytest
from vr_driver.bus.health import BusHealth
from vr_driver.controller.arm import Outcome
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.driver import DriverCore, JobPhase, LinkState, MoveRequest
from vr_driver.driver.link.link import LinkSupervisor
from vr_driver.driver.motion.inbox import Wake
from vr_driver.params import DriverParams
from vr_driver.poses import ControllerPose, MoveType

from _rig import BAUD, StatusWaiter, rig_params

HERE = os.path.dirname(os.path.abspath(__file__))
#: far from home (1120, 0, 725, 0, 45, 0): a PTP of several seconds at speed factor 1
FAR = (700.0, 600.0, 900.0, 0.0, 45.0, 30.0)


# ------------------------------------------------------------------------------ health (stepped)
def test_health_gaps_jitter_and_margin_over_the_window():
    h = BusHealth(period=0.02, watchdog=0.3, window=60.0)
    t = 100.0
    assert h.reply(t) is None                       # the first reply has no gap
    for gap in [0.02] * 98 + [0.05, 0.02]:
        t += gap
        h.reply(t)
    s = h.summary(t)
    assert s.replies == 101
    assert s.max_gap == pytest.approx(0.05)
    assert s.jitter_max == pytest.approx(0.03)
    assert s.jitter_p99 == pytest.approx(0.0, abs=1e-9)   # one gap in 100 is late: p99 is the 99th
    assert s.margin == pytest.approx(0.25)
    assert not s.late and s.late_gaps == 0
    assert "watchdog margin 250 ms of 300 ms" in s.describe()


def test_a_gap_past_half_the_watchdog_is_counted_and_logged(caplog):
    caplog.set_level(logging.WARNING)
    h = BusHealth(period=0.02, watchdog=0.3)
    h.reply(0.0)
    h.reply(0.149)
    assert h.late_gaps == 0
    h.reply(0.149 + 0.16)
    s = h.summary(0.31)
    assert s.late and h.late_gaps == 1 and s.worst_gap == pytest.approx(0.16)
    assert "more than half the card's watchdog (300 ms)" in caplog.text


def test_the_window_forgets_old_gaps_but_not_the_worst_and_a_new_session_starts_a_new_series():
    h = BusHealth(period=0.02, watchdog=0.3, window=60.0)
    h.reply(0.0)
    h.reply(0.2)                                    # late
    h.session_ended()
    h.reply(10.0)                                   # 9.8 s out of Data_Exchange: not a gap
    h.reply(10.02)
    assert h.summary(10.02).max_gap == pytest.approx(0.2)
    s = h.summary(70.0)                             # the late gap left the window
    assert s.max_gap == pytest.approx(0.02) and not s.late
    assert s.worst_gap == pytest.approx(0.2) and s.late_gaps == 1


def test_health_without_a_watchdog_has_no_margin():
    h = BusHealth(period=0.05, watchdog=None)
    h.reply(0.0)
    h.reply(1.0)
    s = h.summary(1.0)
    assert s.margin is None and not s.late and "watchdog" not in s.describe()


# ------------------------------------------------------------------------------ over a real pty
class Rig:
    """A virtual controller on a pty at ``path`` and a DriverCore on a bus process driving it."""

    def __init__(self, tmp_path, kin, protocol="v1", speed_factor=1.0):
        self.path = str(tmp_path / "g2")
        self.protocol = protocol
        self.sim = VirtualController(pty_link=self.path, baud=BAUD, speed_factor=speed_factor,
                                     loop_period=0.01, kinematics=kin, protocol=protocol).start()
        params = rig_params(self.path)
        self.params = type(params).from_dict({
            "port": self.path, "baud": BAUD, "cycle_rate": 50.0, "link_timeout": 1.0,
            "reconnect_period": 0.2, "watchdog_ms": 1000, "accept_timeout": 1.0, "protocol": protocol})
        assert self.params.bus_process
        self.core = DriverCore(self.params, kinematics=kin)
        waiter = StatusWaiter(self.core)
        self.wait_status, self.wait_ready = waiter.wait_status, waiter.wait_ready
        self.core.start()

    def close(self):
        self.core.stop()
        self.sim.stop()


@pytest.fixture
def rig(tmp_path, kin):
    r = Rig(tmp_path, kin)
    yield r
    r.close()


@pytest.fixture
def slow_rig(tmp_path, kin):
    r = Rig(tmp_path, kin, speed_factor=0.2)      # FAR takes over 2 s: past the card's 1 s watchdog
    yield r
    r.close()


def test_the_driver_cycles_on_a_bus_process_and_reports_its_health(rig):
    rig.wait_ready(10.0)
    master = rig.core.link._master
    assert master.paced and master.pid != os.getpid()
    status = rig.wait_status(lambda s: s.bus_health is not None and s.bus_health.replies >= 20, 5.0)
    h = status.bus_health
    assert h.watchdog == pytest.approx(1.0) and h.period == pytest.approx(0.02)
    assert 0.0 < h.max_gap < h.watchdog and h.margin > 0
    assert "process %d" % master.pid in h.scheduling
    assert status.cycle_rate > 0


def test_the_inbox_wake_ends_the_wait_for_the_bus_process_next_report(tmp_path, kin):
    """A thread that posted a request sets its inbox's Wake and calls nothing of the bus side: the
    link supervisor's step, waiting for the bus process's next report (the bus at 2 Hz here),
    returns at once without a cycle and the wake is taken; the report after it still comes. The
    master's own poke sets that wake-up (one wake-up, not two pipes)."""
    path = str(tmp_path / "g2")
    sim = VirtualController(pty_link=path, baud=BAUD, loop_period=0.01, kinematics=kin).start()
    params = DriverParams.from_dict({"port": path, "baud": BAUD, "cycle_rate": 2.0, "link_timeout": 3.0,
                                     "watchdog_ms": 3000, "accept_timeout": 1.0, "stop_settle_time": 1.0,
                                     "joint_command_timeout": 1.0})
    wake = Wake()
    link = LinkSupervisor(params, params.bus(), time.monotonic, wake=wake)
    def until_a_report(within: float = 10.0) -> None:
        # a step waits one bus period for a report while the card is brought up (_cycle_timeout):
        # the bus process's first reports may take longer than that to come
        end = time.monotonic() + within
        while not link.step(time.monotonic()).cycled:
            assert time.monotonic() < end, "no report from the bus process within %g s" % within
    try:
        link.step(time.monotonic())                    # opens the port: the bus process starts
        assert link.paced
        until_a_report()
        woken = []
        for _ in range(3):             # (a report due at the same instant would be taken with the wake)
            wake.set()
            sample = link.step(time.monotonic())
            assert not wake.is_set()                   # the wake taken
            woken.append(not sample.cycled)            # woken before the next report
            if woken[-1]:
                break
            until_a_report()
        assert any(woken), woken
        until_a_report()                               # the report still comes
        link._master.poke()            # the master's poke sets the same wake-up: one way to wake it
        assert wake.is_set()
        link.step(time.monotonic())
        assert not wake.is_set()
    finally:
        link.close()
        sim.stop()


def test_a_killed_bus_process_is_reported_and_replaced_and_nothing_is_sent_twice(slow_rig):
    rig = slow_rig
    rig.wait_ready(10.0)
    job = rig.core.submit(MoveRequest(MoveType.PTP, ControllerPose(*FAR)))
    assert job.wait_change(JobPhase.QUEUED, 5.0) is not JobPhase.QUEUED
    rig.sim.wait_until(lambda fb: fb is not None and fb.state.name == "BUSY", 5.0)
    old = rig.core.link._master.pid
    os.kill(old, signal.SIGKILL)
    lost = rig.wait_status(lambda s: s.link is not LinkState.CONNECTED, 5.0)
    assert "bus process" in lost.link_reason and "SIGKILL" in lost.link_reason, lost.link_reason
    result = job.wait(10.0)
    assert result is not None and not result.success            # ended with its reason, never re-sent
    # the card hears nothing more: its watchdog (1 s) stops the arm; a new bus process connects
    # (the node's reconnect_period 0.2 s and a process start) and the handshake settles (v1: READY
    # seen accept_timeout, 1 s, after the flag was cleared)
    killed = time.monotonic()
    rig.wait_status(lambda s: s.connected and rig.core.link._master.pid != old, 5.0)
    connected = time.monotonic() - killed
    status = rig.wait_ready(10.0)
    ready = time.monotonic() - killed
    print("connected again %.2f s, ready to move %.2f s after the bus process was killed" % (connected, ready))
    assert connected < 2.0
    assert status.counters.port_errors >= 1
    entries = rig.sim.log.entries()
    assert len(entries) == 1, entries                               # the one target, once
    assert entries[0].outcome is Outcome.REJECTED, entries         # stopped by the card's watchdog
    assert max(abs(a - b) for a, b in zip(entries[0].final_pose, (round(v) for v in FAR))) > 10
    job2 = rig.core.submit(MoveRequest(MoveType.PTP, ControllerPose(1100.0, 0.0, 750.0, 0.0, 45.0, 0.0)))
    assert job2.wait(30.0).success
    assert len(rig.sim.log.entries()) == 2                       # the new one, once; the old never again


@pytest.mark.parametrize("protocol", ["v1", "v3"])
def test_the_node_killed_mid_move_the_bus_process_stops_the_arm_then_ends(tmp_path, kin, protocol):
    path = str(tmp_path / "g2")
    sim = VirtualController(pty_link=path, baud=BAUD, speed_factor=1.0, loop_period=0.01,
                            kinematics=kin, protocol=protocol).start()
    brakes = []                                        # why the program braked (v2 / v3)
    if protocol != "v1":
        brake = sim.program.brake
        sim.program.brake = lambda reason, now: brakes.append(reason) or brake(reason, now)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    proc = subprocess.Popen([sys.executable, os.path.join(HERE, "_driver_process.py"), path, protocol,
                             str(BAUD)] + [str(v) for v in FAR], stdout=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        assert line.startswith("BUS "), line
        bus_pid = int(line.split()[1])
        assert proc.stdout.readline().strip() == "MOVING"
        proc.kill()                                    # the node dies: no stop of its own
        proc.wait(5.0)
        # the bus process sends the stop: the arm brakes to rest short of the target, the program
        # says the master stopped it (not the card's watchdog: the bus still cycles)
        in_dx = []
        assert sim.wait_until(lambda fb: not sim.arm.moving and not in_dx.append(str(sim.slave_state)), 10.0), \
            "the arm never stopped"
        assert "DATA_EXCH" in in_dx[-1], in_dx       # at rest while the bus still cycled: not the watchdog
        entries = sim.log.entries()
        assert entries, "nothing logged"
        if protocol == "v1":
            last = entries[-1]
            assert last.outcome is Outcome.REJECTED and "stopped by the master" in last.reason, last
        else:
            assert brakes and brakes[0] == "STOP from the master", brakes
        assert max(abs(a - b) for a, b in zip(sim.pose, (round(v) for v in FAR))) > 10    # short of it
        # then the bus process ends (after bus_stop_hold 1.5 s) and the card's watchdog follows
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and _alive(bus_pid):
            time.sleep(0.05)
        assert not _alive(bus_pid), "the bus process outlived the node"
        assert sim.wait_until(lambda fb: "DATA_EXCH" not in str(sim.slave_state), 5.0)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
        if 'bus_pid' in locals() and _alive(bus_pid):
            os.kill(bus_pid, signal.SIGKILL)
        sim.stop()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:                                     # a zombie (its parent died, not reaped yet) is gone
        with open("/proc/%d/stat" % pid) as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


# ------------------------------------------------------------------------------ the worker process (bus.worker)
CHILD = '''
import os, signal, sys, time
from vr_driver.bus.worker import child_end, child_scheduling
conn = child_end(int(sys.argv[2]))
if sys.argv[1] == "stubborn":
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
conn.send(child_scheduling(priority=int(sys.argv[3]), nice=int(sys.argv[4])))
if sys.argv[1] == "polite":
    conn.recv_bytes()                       # the polite message: the end
    sys.exit(3)
time.sleep(60)
'''


def test_a_worker_process_is_stopped_politely_then_by_sigterm_then_by_sigkill_and_says_how(tmp_path, monkeypatch):
    """bus.worker, which starts the bus process and the planning process: a child that reads the
    polite message ends by itself (its exit code); one that does not is ended by SIGTERM, one that
    ignores SIGTERM by SIGKILL; each is named, our end is closed, and the child's scheduling is said
    in words (niceness; real-time priority granted or refused, with the remedy)."""
    from vr_driver.bus.worker import FD, WorkerProcess, exit_words
    (tmp_path / "worker_child.py").write_text(CHILD)
    monkeypatch.syspath_prepend(str(tmp_path))
    polite = WorkerProcess("worker_child", ["polite", FD, "0", "5"], "test child")
    term = WorkerProcess("worker_child", ["term", FD, "0", "0"], "test child")
    stubborn = WorkerProcess("worker_child", ["stubborn", FD, "1", "0"], "test child")
    assert polite.conn.recv() == "normal scheduling, nice +5"
    assert os.getpriority(os.PRIO_PROCESS, polite.pid) == min(19, os.getpriority(os.PRIO_PROCESS, 0) + 5)
    assert term.conn.recv() == "normal scheduling (rt_priority 0)"
    words = stubborn.conn.recv()
    assert words == "SCHED_FIFO 1" or ("real-time priority 1 refused" in words and "chrt -f 1" in words), words
    assert polite.running and polite.exit_words() == "still running"
    assert polite.stop(polite=lambda: polite.conn.send_bytes(b"bye"), grace=10.0) == "exit code 3"
    assert term.stop(grace=0.2, term_grace=10.0) == "killed by SIGTERM"
    assert stubborn.stop(grace=0.2, term_grace=0.2) == "killed by SIGKILL"
    for w in (polite, term, stubborn):
        assert w.conn.closed and not w.running
    assert exit_words(None) == "still running" and exit_words(-99) == "killed by signal 99"
