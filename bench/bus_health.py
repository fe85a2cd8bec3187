#!/usr/bin/python3
"""The bus's gaps at the controller's card, with the bus in the driver's thread and in a process of
its own, idle and under load (printed, never asserted).

    scripts/bench bus_health [-- --bauds 19200,187500 --designs before,after --loads idle,plan,validate,hog,plan+hog
                                 --goals 100 --points 400000 --validate-window 12 --window 6 --protocol v1 | --quick]

The card's DP watchdog (300 ms, the driver's default) stops the arm when the master is silent: what
counts is the time between two Data_Exchange telegrams as the card receives them. Target: 0 watchdog
expiries and every gap below half the watchdog (150 ms) with the bus in its own process ("after"),
in every case.

Each case (bit rate x load x design) runs in a worker process of its own (a fresh interpreter: no
planner, no garbage of the case before), and in it:

- **The card's side**, in processes of their own (``bus_health.py --card`` / ``--line``, SCHED_FIFO 30
  where the system allows it: they stand for hardware, which is never late, and must not add delays
  of their own): the virtual G2 (vr_driver.controller.virtual_controller.VirtualController: the protocol's
  program and simulated arm) on a pty, and the virtual line (vr_driver.controller.line) joining it to
  the driver at the bit rate: the bytes take their wire time. The card records the arrival time of
  every Data_Exchange telegram it takes (a wrapper around its DpSlave's ``handle``: no library code
  changed), its DP watchdog expiries (the DpSlave's counter) and each time it left Data_Exchange,
  between the bench's ``start`` and ``report``.
- **The driver's side** in the worker's own interpreter, as in the node: a DriverCore (the example
  cell as its scene, the parameter file's 20 Hz bus, the card's 300 ms watchdog) and the load:

  ``idle``      nothing for --window s;
  ``plan``      --goals plan goals back to back in the example cell, each from the arm's joints
                (home: it does not move; given, so that a link loss does not end the load): each
                joint up to GOAL_SPREAD_DEG from there, free, its TCP in the workspace box -- in
                front of the arm, about the pillar, the shelf and the table; every other one as a
                TCP pose; the same goals for both designs;
  ``validate``  a --points-point joint trajectory goal checked as joint_trajectory_action checks it,
                in a thread of its own (driver.motion.trajectories.validate, segment_speeds, then
                DriverCore.submit_trajectory, whose collision check walks every sample): a joint_1
                sweep that reaches the pillar at its last points, so it would be refused at the end.
                What counts is the load while it is checked: the window ends with the validation or
                --validate-window s into it (400 000 points take about a minute, most of it the same
                collision check sample after sample); the worker then ends without waiting for it;
  ``hog``       two CPU hog processes (busy loops at normal priority) for --window s;
  ``plan+hog``  the plan goals with the two hogs running beside them.

  Designs: ``before`` -- ``bus_process`` false (the DP master in the driver's bus thread) and the
  planning in the driver's interpreter (driver.planning.planning.PlanActionCore, the plan action's old way);
  ``after`` -- ``bus_process`` true (vr_driver.bus.process, SCHED_FIFO 20 where allowed) and the
  planning in a worker process (driver.planning.plan_process.PlanningProcess, started before the window as the
  plan action starts it).

Figures per case: the window's length, the Data_Exchange telegrams the card took, the longest gap
and the gaps' p99.9 (the window's edges count as gaps: silence is silence), the card's watchdog
expiries and how often it left Data_Exchange, the driver's link losses, the driver's longest bus-loop
iteration (DriverCore.spin_once timed: with a bus process, one past bus_node_timeout, 3 s, makes the
bus process take the driver for dead and stop the arm); beside them the driver's own view
(DriverStatus.bus_health: its worst gap since it started, its gaps past half the watchdog in the
window, how the bus is scheduled). The last line says whether the target holds for "after" in every
case measured. The machine's load average is printed: compare figures of one run, on a machine that
runs nothing else. --quick: a smoke run (5 goals, one validation of 20 000 points, 3 s windows).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import queue
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HERE = os.path.dirname(os.path.abspath(__file__))
for _pkg in ("vr_driver", "pyprofibus_vendor", "panasonic_vr006l_support"):
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)
if HERE not in sys.path:
    sys.path.insert(0, HERE)
import driver_latency  # noqa: E402 (ROS-free: its worker runner and signal handling serve here too)

CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")
RESULT_TAG = "@@BUS_HEALTH_RESULT "
CARD_TAG = "@@BUS_HEALTH_CARD "
BAUDS = (19200, 187500)
DESIGNS = ("before", "after")
LOADS = ("idle", "plan", "validate", "hog", "plan+hog")
#: [s] the target: every gap below this (half the card's 300 ms watchdog)
TARGET_GAP = 0.150
#: SCHED_FIFO priority of the card's and the line's processes (above the bus process's 20: the rig
#: stands for hardware, which is never late)
RIG_PRIORITY = 30
#: [s] from the driver's first "motion possible" to the window: the start-up settles
SETTLE = 1.0
#: [s] the longest wait for the driver to reach the card and for motion to be possible
READY_TIMEOUT = 30.0
#: [rad] the validated sweep goes this far into the pillar past its first contact
INTO_PILLAR = math.radians(0.5)
#: [deg] plan goals: each joint within this of the start (home): in front of the arm, the pillar to
#: its left, the shelf to its right, the table below
GOAL_SPREAD_DEG = (60.0, 25.0, 25.0, 40.0, 20.0, 60.0)
#: [s] between two points of the validated goal (400 000 points: 400 s of a slow joint_1 sweep)
POINT_DT = 0.001


# ------------------------------------------------------------------------------------ small helpers

def percentile(values: Sequence[float], p: float) -> float:
    """The ``p`` percentile (nearest rank) of ``values``; nan when there are none."""
    s = sorted(values)
    if not s:
        return float("nan")
    return s[min(len(s) - 1, max(0, int(math.ceil(p / 100.0 * len(s))) - 1))]


def gap_figures(arrivals: Sequence[float], start: float, end: float) -> Dict[str, Any]:
    """The gaps of a window [start, end] with telegrams at ``arrivals``: the edges count (from the
    window's start to the first telegram, from the last one to the end) -- the card hears nothing
    there either. n telegrams, the longest gap, p99.9, the gaps past TARGET_GAP, the five longest [s]."""
    times = [start] + sorted(t for t in arrivals if start <= t <= end) + [end]
    gaps = [b - a for a, b in zip(times, times[1:])]
    return {"telegrams": len(times) - 2, "max": max(gaps), "p999": percentile(gaps, 99.9),
            "median": percentile(gaps, 50.0), "over_target": sum(1 for g in gaps if g >= TARGET_GAP),
            "longest": sorted(gaps, reverse=True)[:5]}


def set_rig_priority() -> str:
    """SCHED_FIFO RIG_PRIORITY for this process, every thread it has, where allowed; how it is
    scheduled, in words. Called once the device serves: its imports and its construction (the
    virtual G2's kinematics: some 0.35 s of CPU, the line's 0.15 s) at SCHED_FIFO 30 took both
    cores from everything below -- the driver's bus processes at 20 included -- for as long (the
    benches run in the suite's real-time phase, beside the rostests)."""
    from vr_driver.bus.worker import set_process_priority
    words = set_process_priority(RIG_PRIORITY)
    return words if words.startswith("SCHED_FIFO") else words.split(":")[0] + " (SCHED_FIFO refused)"


# ------------------------------------------------------------------------- the card's side (processes)

def card_main(cfg: Dict[str, Any]) -> int:
    """``--card CFG``: the virtual G2 on a pty linked at cfg["path"], recording what its card sees.
    Prints ``CARD_TAG {"ready": ...}``, then reads commands on stdin: ``start`` (a window begins:
    answers its start time), ``report`` (answers the window's figures); end of input ends it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # the bench's Ctrl-C is the bench's to act on
    import logging

    from pyprofibus_vendor.dp_slave import SlaveState
    from vr_driver.controller.virtual_controller import VirtualController
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    sim = VirtualController(pty_link=cfg["path"], baud=cfg["baud"], protocol=cfg["protocol"])
    slave = sim.slave
    clock = slave.clock
    arrivals: List[float] = []           # Data_Exchange telegrams taken by the card (server thread)
    left: List[Tuple[float, str]] = []   # the card left Data_Exchange: when, why
    handle, chained = slave.handle, slave.on_state_change

    def recording_handle(frame: Any, now: Optional[float] = None) -> Any:
        now = clock() if now is None else now
        before = slave.counters.data_exchanges
        reply = handle(frame, now)
        if slave.counters.data_exchanges != before:
            arrivals.append(now)
        return reply

    def recording_state(old: Any, new: Any, reason: str) -> None:
        if old is SlaveState.DATA_EXCH:
            left.append((clock(), reason))
        if chained is not None:
            chained(old, new, reason)
    slave.handle = recording_handle                     # the server thread calls slave.handle(frame, now)
    slave.on_state_change = recording_state
    sim.start()
    scheduling = set_rig_priority()

    def say(payload: Dict[str, Any]) -> None:
        sys.stdout.write(CARD_TAG + json.dumps(payload) + "\n")
        sys.stdout.flush()
    say({"ready": sim.device_path, "scheduling": scheduling})
    mark = (0.0, 0, 0, 0)
    try:
        for line in sys.stdin:
            command = line.strip()
            if command == "start":
                mark = (clock(), len(arrivals), len(left), slave.counters.watchdog_expiries)
                say({"start": mark[0]})
            elif command == "report":
                end = clock()
                t0, n0, l0, w0 = mark
                figures = gap_figures(arrivals[n0:], t0, end)
                figures.update(start=t0, end=end, watchdog_expiries=slave.counters.watchdog_expiries - w0,
                               left_dx=[reason for _, reason in left[l0:]], watchdog=slave.watchdog_time,
                               state=slave.state.value, server_error=str(sim.server_error or ""))
                say(figures)
    finally:
        sim.stop()
    return 0


def line_main(argv: List[str]) -> int:
    """``--line ARGS``: the virtual line (vr_driver.controller.line's command line) at rig priority;
    its first line on stdout is the master's device path."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from vr_driver.controller.line import main as line
    set_rig_priority()                  # after the import; the line's own set-up is light
    return line(argv)


class Child:
    """A process of the rig: its own session, stdout read line by line by a thread, stderr to
    ``log``. :meth:`expect` waits for a line; :meth:`stop` ends it (end of input, SIGTERM, SIGKILL)."""

    def __init__(self, args: List[str], log: str, stdin: bool = False) -> None:
        self.log = log
        with open(log, "wb") as fh:
            self.proc = subprocess.Popen(args, stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
                                         stdout=subprocess.PIPE, stderr=fh, text=True, bufsize=1,
                                         start_new_session=True)
        self.lines: "queue.Queue[Optional[str]]" = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for text in self.proc.stdout:
            self.lines.put(text.rstrip("\n"))
        self.lines.put(None)

    def expect(self, what: str, timeout: float, tag: str = "") -> str:
        """The next stdout line starting with ``tag`` (the tag removed), RuntimeError naming ``what``
        and the log's tail when it does not come."""
        end = time.monotonic() + timeout
        while True:
            try:
                text = self.lines.get(timeout=max(0.0, end - time.monotonic()))
            except queue.Empty:
                text = None
                if time.monotonic() < end:
                    continue
            if text is None:
                raise RuntimeError("%s: not seen within %.0f s (exit status %s); its log:\n%s"
                                   % (what, timeout, self.proc.poll(), self.tail()))
            if text.startswith(tag):
                return text[len(tag):]

    def command(self, text: str, timeout: float = 10.0) -> Dict[str, Any]:
        """Send a command line to the card and return its JSON answer."""
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()
        return json.loads(self.expect("the card's answer to %r" % text, timeout, CARD_TAG))

    def tail(self, lines: int = 15) -> str:
        try:
            with open(self.log, errors="replace") as fh:
                return "".join(fh.readlines()[-lines:])
        except OSError:
            return ""

    def end(self) -> None:
        """Ask it to end without waiting: end of input for the card, SIGTERM for the line."""
        if self.proc.stdin is not None:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        elif self.proc.poll() is None:
            self.proc.terminate()

    def stop(self) -> None:
        """:meth:`end`, then wait; SIGTERM, SIGKILL when it does not end."""
        self.end()
        for sig, wait in ((None, 3.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
            if sig is not None:
                try:
                    self.proc.send_signal(sig)
                except ProcessLookupError:
                    return
            try:
                self.proc.wait(wait)
                return
            except subprocess.TimeoutExpired:
                continue


# ------------------------------------------------------------------------------------------- loads

class Load:
    """A load on the driver's interpreter: :meth:`prepare` before the window (not measured),
    :meth:`run` in it (returns words for the report), :meth:`close` after; :meth:`running`: the
    load goes on past the window (the worker does not wait for it)."""

    def __init__(self, core: Any, cfg: Dict[str, Any]) -> None:
        self.core, self.cfg = core, cfg

    def prepare(self) -> None:
        pass

    def run(self) -> str:
        raise NotImplementedError

    def running(self) -> bool:
        return False

    def close(self) -> None:
        pass


class Idle(Load):
    def run(self) -> str:
        time.sleep(self.cfg["window"])
        return "nothing for %.0f s" % self.cfg["window"]


class Hogs(Load):
    """Two busy-loop processes at normal priority for the window."""

    def __init__(self, core: Any, cfg: Dict[str, Any]) -> None:
        super().__init__(core, cfg)
        self.procs: List[subprocess.Popen] = []

    def run(self) -> str:
        for _ in range(2):
            self.procs.append(subprocess.Popen([sys.executable, "-c", "while True: pass"],
                                               stdin=subprocess.DEVNULL, start_new_session=True))
        time.sleep(self.cfg["window"])
        return "2 busy loops for %.0f s" % self.cfg["window"]

    def close(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait(5.0)
        self.procs = []


def cell_goals(core: Any, n: int, seed: int) -> List[Any]:
    """``n`` plan goals in the example cell about the arm's joints now (the home pose): each joint
    within GOAL_SPREAD_DEG of it, within its limits, free (the driver's padding), the TCP inside the
    driver's workspace box, joint_5 on the side of the start's (no wrist flip for a Cartesian
    protocol); every other one as the TCP pose of those joints, the others as the joints."""
    from vr_driver.driver.planning.planning import PlanGoal
    from vr_driver.kinematics.collision import CollisionChecker
    from vr_driver.kinematics.scene import load_scene
    kin, params = core.kin, core.params
    checker = CollisionChecker.default(scene=load_scene(CELL), padding=params.collision_padding)
    start = tuple(core.status().joints)
    lower, upper = kin.limits.lower, kin.limits.upper
    rng = random.Random(seed)
    goals: List[Any] = []
    while len(goals) < n:
        q = tuple(h + math.radians(rng.uniform(-d, d)) for h, d in zip(start, GOAL_SPREAD_DEG))
        if not all(lo <= v <= hi for v, lo, hi in zip(q, lower, upper)) or q[4] * start[4] <= 0.0 \
                or checker.in_collision(q):
            continue
        pose = kin.fk_pose(q)
        try:
            params.workspace.check(pose)
        except Exception:  # noqa: BLE001 - outside the box (a VrDriverError): not a goal
            continue
        # at the full speed, as measured (the plan action's default, 0.1, makes 10 times longer plans to check)
        goals.append(PlanGoal(pose=pose, velocity_scaling=1.0) if len(goals) % 2
                     else PlanGoal(joints=(tuple(core.joint_names), q), velocity_scaling=1.0))
    return goals


class Plans(Load):
    """--goals goals planned back to back from the arm's joints at the start: in the driver's
    interpreter (PlanActionCore) or in the plan action's worker process (PlanningProcess)."""

    def prepare(self) -> None:
        self.goals = cell_goals(self.core, self.cfg["goals"], self.cfg["seed"])
        # the arm does not move: every goal from its joints now, also after a link loss (when the
        # plan action would refuse at once: the load would end with the loss)
        self.start = tuple(self.core.status().joints)
        if self.cfg["design"] == "before":
            from vr_driver.driver.planning.planning import PlanActionCore
            self.planner: Any = PlanActionCore(self.core)
        else:
            from vr_driver.driver.planning.plan_process import PlanningProcess
            self.planner = PlanningProcess(self.core)
            self.planner.start()                    # as the plan action starts it: before any goal

    def run(self) -> str:
        ok, times = 0, []
        failures: Dict[str, int] = {}
        for i, goal in enumerate(self.goals):
            t = time.monotonic()
            outcome = self.planner.plan(goal, start=self.start, seed=self.cfg["seed"] + i)
            times.append(time.monotonic() - t)
            ok += outcome.ok
            if not outcome.ok:
                words = outcome.text[:70]
                failures[words] = failures.get(words, 0) + 1
        common = max(failures, key=failures.__getitem__) if failures else ""
        return "%d goals planned in %s, %d with a plan%s, %.2f s each (median), %.2f s max" % (
            len(times), "the driver's interpreter" if self.cfg["design"] == "before" else "the planning process",
            ok, " (most failures: %d x '%s')" % (failures[common], common) if common else "",
            percentile(times, 50.0), max(times))

    def close(self) -> None:
        closer = getattr(getattr(self, "planner", None), "close", None)
        if closer is not None:
            closer()


class Validation(Load):
    """A --points-point joint_1 sweep from the arm's joints into the pillar, checked as
    joint_trajectory_action checks a goal (in a thread of its own, as the action server's callback):
    validate, segment_speeds, then DriverCore.submit_trajectory (its collision check of every sample
    refuses it at the end). The window ends with the validation, or after --validate-window s
    (0: no limit) while its collision check goes on -- the rest is more of the same, sample after
    sample; the worker then ends without waiting for it."""

    def prepare(self) -> None:
        from vr_driver.driver.motion.trajectories import TrajectoryGoal
        core = self.core
        start = tuple(core.status().joints)
        end = self._into_pillar(start)
        n = self.cfg["points"]
        positions = tuple(tuple(a + (b - a) * k / (n - 1) for a, b in zip(start, end)) for k in range(n))
        self.goal = TrajectoryGoal(tuple(core.joint_names), positions, tuple(k * POINT_DT for k in range(n)))
        self.sweep = math.degrees(end[0] - start[0])
        self.phases: List[Tuple[str, float]] = []
        self.verdict = ""
        self.thread: Optional[threading.Thread] = None

    def _into_pillar(self, start: Tuple[float, ...]) -> Tuple[float, ...]:
        """The end of the sweep: joint_1 turned to the left until the arm meets the pillar, a little
        further (the driver's checker and padding); the whole left range when it never does."""
        guard = self.core.scene_guard
        upper = self.core.kin.limits.upper[0]

        def at(angle: float) -> Tuple[float, ...]:
            return (angle,) + tuple(start[1:])

        def hits(angle: float) -> bool:
            with self.core.planning_gate:           # the checker is not thread-safe
                checker = guard.checker
                return checker is not None and checker.in_collision(at(angle))
        free, step = start[0], math.radians(1.0)
        while free + step <= upper and not hits(free + step):
            free += step
        if free + step > upper:
            return at(upper)
        lo, hi = free, free + step
        while hi - lo > math.radians(0.01):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if hits(mid) else (mid, hi)
        return at(min(upper, hi + INTO_PILLAR))

    def _validate(self) -> None:
        from vr_driver.driver.motion.trajectories import segment_speeds, validate
        from vr_driver.errors import VrDriverError
        core = self.core
        lim, wire = core.kin.limits, core.wire
        t = time.monotonic()
        try:
            traj = validate(self.goal, core.joint_names, core.status().joints, lim.lower, lim.upper, time.time(),
                            default_path_tolerance=wire.default_path_tolerance,
                            default_goal_tolerance=wire.default_goal_tolerance)
            self.phases.append(("validate", time.monotonic() - t))
            segment_speeds(traj, lim.velocity, core.joint_names)
            self.phases.append(("segment_speeds", time.monotonic() - t))
            core.submit_trajectory(traj)
            self.verdict = "accepted (stopped at once)"
            core.stop_motion("bus_health bench: the validated goal is not to run")
        except VrDriverError as exc:
            self.verdict = "refused: %s" % str(exc).split(";")[0]
        self.phases.append(("end", time.monotonic() - t))

    def run(self) -> str:
        self.thread = threading.Thread(target=self._validate, name="bench-validate", daemon=True)
        self.thread.start()
        self.thread.join(self.cfg["validate_window"] or None)
        done = dict(self.phases)
        steps = ", ".join("%s %.1f s" % (k, v) for k, v in self.phases if k != "end")
        if "end" in done:
            return "%d points (joint_1 %+.1f deg) validated in %.1f s (%s, then the collision check); %s" % (
                len(self.goal.positions), self.sweep, done["end"], steps, self.verdict[:100])
        return "%d points (joint_1 %+.1f deg): the window ended %.0f s into the validation (%s, then the " \
               "collision check, still running)" % (len(self.goal.positions), self.sweep,
                                                    self.cfg["validate_window"], steps or "validate running")

    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive()


class PlansBesideHogs(Plans):
    """The plan goals (Plans) with the two busy loops (Hogs) running all the while: the planning
    process and the hogs take both cores from the bus process."""

    def run(self) -> str:
        self.hogs = Hogs(self.core, dict(self.cfg, window=0.0))
        self.hogs.run()
        try:
            return super().run() + ", 2 busy loops beside"
        finally:
            self.hogs.close()

    def close(self) -> None:
        hogs = getattr(self, "hogs", None)
        if hogs is not None:
            hogs.close()
        super().close()


LOAD_CLASSES = {"idle": Idle, "plan": Plans, "validate": Validation, "hog": Hogs, "plan+hog": PlansBesideHogs}


# ------------------------------------------------------------------------------------------ worker

class LoopTimer:
    """The driver's bus loop as it runs: the duration of each BusLoop.spin_once (one bus iteration:
    the DP cycle or, with a bus process, the wait for its report, then the joints, the sequencer and
    the snapshot), wrapped on the core's bus loop before the core starts (its thread calls that, not
    DriverCore.spin_once: wrapping the core's measured nothing, 0.0 ms, once the core was carved). A long one is the driver's loop
    held up: the interpreter lock, or no CPU for the driver's process -- with a bus process, one
    beyond bus_node_timeout (3 s) makes the bus process take the driver for dead and stop the arm."""

    def __init__(self, core: Any) -> None:
        self.times: List[float] = []
        self._from = 0
        bus_loop = core.bus_loop
        spin = bus_loop.spin_once

        def timed() -> Any:
            t = time.monotonic()
            try:
                return spin()
            finally:
                self.times.append(time.monotonic() - t)
        bus_loop.spin_once = timed

    def mark(self) -> None:
        """The window starts: only iterations from here on count."""
        self._from = len(self.times)

    def longest(self) -> float:
        return max(self.times[self._from:], default=0.0)


def health_words(h: Any, late_before: int) -> Dict[str, Any]:
    """The driver's DriverStatus.bus_health as plain numbers ({}: none yet); ``late_gaps``: those of
    the window (the count at its start was ``late_before``), ``worst_gap``: since the driver started."""
    if h is None:
        return {}
    late = h.late_gaps - late_before if h.late_gaps >= late_before else h.late_gaps   # a new bus / master
    return {"worst_gap": h.worst_gap, "late_gaps": late, "window_max": h.max_gap,
            "jitter_p99": h.jitter_p99, "scheduling": h.scheduling}


def worker(cfg: Dict[str, Any]) -> int:
    """One case (see the module docstring); prints its result after RESULT_TAG. Exit status 1 when
    it could not be measured."""
    import logging
    driver_latency.interrupt_once((signal.SIGINT, signal.SIGTERM, signal.SIGHUP))
    logging.basicConfig(level=logging.ERROR, stream=sys.stderr)   # the figures say it; no warning per gap
    tmp = tempfile.mkdtemp(prefix="vr_bus_health_")
    card = line = core = load = None
    label = "%d bit/s, %s, %s" % (cfg["baud"], cfg["load"], cfg["design"])
    left_running = False
    try:
        here = os.path.abspath(__file__)
        g2, port = os.path.join(tmp, "g2"), os.path.join(tmp, "line")
        # the card's side starts while the driver is built (the line retries the card's pty until it is there)
        card = Child([sys.executable, here, "--card", json.dumps({
            "path": g2, "baud": cfg["baud"], "protocol": cfg["protocol"]})], os.path.join(tmp, "card.log"), stdin=True)
        line = Child([sys.executable, here, "--line", "--pty-link", port, "--baud", str(cfg["baud"]), g2],
                     os.path.join(tmp, "line.log"))
        from vr_driver.driver import DriverCore
        from vr_driver.params import DriverParams
        params = DriverParams.from_dict({
            "port": port, "baud": cfg["baud"], "protocol": cfg["protocol"], "cycle_rate": cfg["cycle_rate"],
            "bus_process": cfg["design"] == "after", "scene": CELL if cfg["scene"] else ""})
        core = DriverCore(params)
        ready = json.loads(card.expect("the virtual G2", 30.0, CARD_TAG))
        line.expect("the virtual line's device", 30.0)
        loop = LoopTimer(core)
        up = threading.Event()
        core.add_listener(lambda s: up.set() if s.motion_possible and s.joints_valid else None)
        core.start()
        if not up.wait(READY_TIMEOUT):
            raise RuntimeError("%s: motion not possible within %.0f s: %s" % (
                label, READY_TIMEOUT, core.status().why_no_motion()))
        load = LOAD_CLASSES[cfg["load"]](core, cfg)
        load.prepare()
        time.sleep(SETTLE)
        before = core.status()
        loop.mark()
        card.command("start")
        t0 = time.monotonic()
        words = load.run()
        report = card.command("report")
        wall = time.monotonic() - t0
        after = core.status()
        late0 = before.bus_health.late_gaps if before.bus_health is not None else 0
        result = {"baud": cfg["baud"], "load": cfg["load"], "design": cfg["design"], "wall": wall,
                  "card": report, "card_scheduling": ready["scheduling"], "load_words": words,
                  "driver_losses": after.counters.losses - before.counters.losses,
                  "health": health_words(after.bus_health, late0), "loop_max": loop.longest(),
                  "loadavg": os.getloadavg()[0]}
        print(RESULT_TAG + json.dumps(result), flush=True)
        left_running = load.running()
        return 0
    except KeyboardInterrupt:
        print("interrupted: stopping what was started", flush=True)
        return 130
    except Exception as exc:  # noqa: BLE001 - report, clean up, exit 1
        import traceback
        traceback.print_exc()
        print("FAILED: %s: %s: %s" % (label, type(exc).__name__, exc), flush=True)
        return 1
    finally:
        for step in (load.close if load is not None else None, core.stop if core is not None else None,
                     card.end if card is not None else None, line.end if line is not None else None,
                     card.stop if card is not None else None, line.stop if line is not None else None):
            if step is not None:
                try:
                    step()
                except Exception as exc:  # noqa: BLE001 - clean up the rest all the same
                    print("clean-up: %s: %s" % (type(exc).__name__, exc), flush=True)
        shutil.rmtree(tmp, ignore_errors=True)
        if left_running:                # a validation cut short at the window's end: not waited for
            sys.stdout.flush()
            os._exit(0)


# ------------------------------------------------------------------------------------------ parent

def ms(value: Optional[float]) -> str:
    return "-" if value is None else "%.1f" % (1e3 * value)


def case_line(r: Dict[str, Any]) -> str:
    """What one case measured, as it ends."""
    c = r["card"]
    return ("%d bit/s %-8s %-6s: %d DX in %.1f s, longest gaps %s ms, p99.9 %s ms, %d watchdog expiries%s; "
            "driver loop %s ms; load average %.1f; %s"
            % (r["baud"], r["load"], r["design"], c["telegrams"], r["wall"], ", ".join(ms(g) for g in c["longest"][:3]),
               ms(c["p999"]), c["watchdog_expiries"],
               " (the card left Data_Exchange: %s)" % "; ".join(c["left_dx"]) if c["left_dx"] else "",
               ms(r["loop_max"]), r["loadavg"], r["load_words"]))


def table(results: List[Dict[str, Any]]) -> List[str]:
    """One row per case: the card's figures, the driver's link losses and loop, the driver's view."""
    rows = ["%-7s %-8s %-6s %6s %6s %8s %8s %4s %6s %8s   %s" % (
        "bit/s", "load", "design", "run s", "DX", "max ms", "p99.9 ms", "wd", "losses", "loop ms",
        "the driver's view: worst gap since its start [ms], gaps past 150 ms in the window, the bus")]
    for r in results:
        c, h = r["card"], r["health"]
        rows.append("%-7d %-8s %-6s %6.1f %6d %8s %8s %4d %2d / %-2d %8s   %s, %s, %s" % (
            r["baud"], r["load"], r["design"], r["wall"], c["telegrams"], ms(c["max"]), ms(c["p999"]),
            c["watchdog_expiries"], len(c["left_dx"]), r["driver_losses"], ms(r["loop_max"]),
            ms(h.get("worst_gap")), h.get("late_gaps", "-"), h.get("scheduling", "-")))
    return rows


def verdict(results: List[Dict[str, Any]], expected: int) -> str:
    after = [r for r in results if r["design"] == "after"]
    bad = ["%d %s (%s ms, %d expiries)" % (r["baud"], r["load"], ms(r["card"]["max"]), r["card"]["watchdog_expiries"])
           for r in after if r["card"]["watchdog_expiries"] or r["card"]["max"] >= TARGET_GAP]
    if not after:
        return "MISS target: no \"after\" case measured"
    if bad:
        return "MISS target (after: 0 watchdog expiries, every gap < %.0f ms) in %s" % (1e3 * TARGET_GAP, "; ".join(bad))
    missing = " (%d of %d cases not measured)" % (expected - len(after), expected) if len(after) < expected else ""
    return "PASS target (after: 0 watchdog expiries, every gap < %.0f ms) in every case: %d of %d%s" % (
        1e3 * TARGET_GAP, len(after), len(after), missing)


def choice_list(text: str, allowed: Sequence[str], what: str) -> List[str]:
    items = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in items if t not in allowed]
    if bad or not items:
        raise argparse.ArgumentTypeError("%s: %s not one of %s" % (what, ", ".join(bad) or "none", ", ".join(allowed)))
    return items


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(json.loads(argv[1]))
    if argv[:1] == ["--card"]:
        return card_main(json.loads(argv[1]))
    if argv[:1] == ["--line"]:
        return line_main(argv[1:])
    sigs = [signal.SIGTERM, signal.SIGHUP]
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        sigs.append(signal.SIGINT)
    driver_latency.interrupt_once(sigs)
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bauds", default=",".join(str(b) for b in BAUDS),
                   help="bit rates, comma-separated (default %s)" % ",".join(str(b) for b in BAUDS))
    p.add_argument("--designs", default=",".join(DESIGNS), help="before, after (default both)")
    p.add_argument("--loads", default=",".join(LOADS), help="of %s (default all)" % ", ".join(LOADS))
    p.add_argument("--goals", type=int, default=100, help="plan: goals planned back to back (default 100)")
    p.add_argument("--points", type=int, default=400_000, help="validate: points of the goal (default 400000)")
    p.add_argument("--validate-window", type=float, default=12.0,
                   help="validate: the window ends this many seconds into the validation, or with it "
                        "(default 12; 0: the whole validation, about a minute for 400000 points)")
    p.add_argument("--window", type=float, default=None, help="idle and hog: the window [s] (default 6; --quick 3)")
    p.add_argument("--cycle-rate", type=float, default=20.0, help="bus cycles per second (default 20, the parameter file's)")
    p.add_argument("--protocol", default="v1", choices=("v1", "v2", "v3"), help="controller protocol (default v1)")
    p.add_argument("--seed", type=int, default=1, help="seed of the plan goals (default 1)")
    p.add_argument("--quick", action="store_true",
                   help="smoke run: 5 goals, 20 000 points, 3 s windows (unless --window says otherwise)")
    args = p.parse_args(argv)
    try:
        bauds = [int(b) for b in args.bauds.split(",") if b.strip()]
        if not bauds:
            raise ValueError("--bauds: no bit rate given")
        designs = choice_list(args.designs, DESIGNS, "--designs")
        loads = choice_list(args.loads, LOADS, "--loads")
    except (argparse.ArgumentTypeError, ValueError) as exc:
        p.error(str(exc))
    if args.window is None:
        args.window = 3.0 if args.quick else 6.0
    if args.quick:
        args.goals, args.points, args.validate_window = min(args.goals, 5), min(args.points, 20_000), 0.0
    if args.goals < 1 or args.points < 2 or args.window <= 0 or args.validate_window < 0:
        p.error("--goals >= 1, --points >= 2, --window > 0 and --validate-window >= 0")
    from vr_driver.kinematics.deps import missing_dependencies
    missing = missing_dependencies()
    if missing:
        skipped = [x for x in loads if x in ("plan", "validate", "plan+hog")]
        loads = [x for x in loads if x not in ("plan", "validate", "plan+hog")]
        print("without the example cell and the loads %s: %s" % (", ".join(skipped) or "-",
                                                                 "; ".join(reason for _, reason in missing)))
        if not loads:
            print("bus health benchmark skipped: no load left to measure")
            return 0
    started = time.perf_counter()
    print("bus health benchmark: protocol %s, %g Hz bus, %d cases (bit rates %s x loads %s x designs %s), "
          "%d plan goals, a %d-point goal validated; the card's side (virtual G2, paced virtual line) in "
          "processes of their own; load average %.1f at the start"
          % (args.protocol, args.cycle_rate, len(bauds) * len(loads) * len(designs), ", ".join(map(str, bauds)),
             ", ".join(loads), ", ".join(designs), args.goals, args.points, os.getloadavg()[0]), flush=True)
    results, status = [], 0
    for baud in bauds:
        for load in loads:
            for design in designs:
                cfg = {"baud": baud, "design": design, "load": load, "protocol": args.protocol,
                       "cycle_rate": args.cycle_rate, "goals": args.goals, "points": args.points,
                       "window": args.window, "validate_window": args.validate_window, "seed": args.seed,
                       "scene": not missing}
                code, result = driver_latency.run_worker(cfg, __file__, RESULT_TAG)
                if code == 130:
                    print("interrupted")
                    return 130
                if code != 0 or result is None:
                    status = 1
                    continue
                results.append(result)
                print(case_line(result), flush=True)
    print("=== the card's Data_Exchange gaps: the card's watchdog %s ms; rig (virtual G2, virtual line) %s; "
          "DX: telegrams the card took; wd: its watchdog expiries; losses: the card left Data_Exchange / the "
          "driver's link losses; loop: the driver's longest bus-loop iteration"
          % (ms(results[0]["card"]["watchdog"]) if results else "?",
             results[0]["card_scheduling"] if results else "?"))
    for row in table(results):
        print(row)
    print(verdict(results, len(bauds) * len(loads)))
    print("python %s, %d CPUs, load %.2f, wall time %.1f s%s" % (
        sys.version.split()[0], os.cpu_count() or 0, os.getloadavg()[0], time.perf_counter() - started,
        "; FAILED (see above)" if status else ""))
    return status


if __name__ == "__main__":
    sys.exit(main())
