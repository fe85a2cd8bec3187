#!/usr/bin/python3
"""The walk of a FollowJointTrajectory goal to the wire, measured (issue 47): which of the
repository's source files run on the goal's side and which on the bus's side.

    scripts/bench goal_walk [-- --protocol v3 --goals 2 --quiet]

A v3 goal (a curved, planner-like trajectory from where the arm stands) goes through the node's
own code, without a ROS master: ``ros/trajectory_server.py``'s ``TrajectoryServer`` (its action
server made but never started: no topics) and its ``GoalRunner``, given the goal message through
the goal callback (``on_goal``, as actionlib's thread gives it) with a goal handle that records
what it is told. Behind it the ROS-free ``DriverCore`` in the stepped world of the tests
(``vr_driver/test/driver/_world.py``: the in-memory link, the virtual G2's v3 program, one fake
clock). ``rospy.get_time`` reads the wall clock (rostime marked initialised: no node, no /clock).

A tracer (``sys.settrace`` / ``threading.settrace``, call events only) records each repository
source file (``*/src/``) whose code runs:

- **goal side**: from the goal callback's entry (``GoalRunner.on_goal``: the goal validated at its
  arrival) through the goal's own thread (``TrajectoryServer._execute``: submitted -- checked,
  made a stream, posted to the sequencer's inbox, the bus woken -- and announced) until the
  supervisor takes the run over (``TrajectorySupervisor`` made: from there on the thread only
  watches);
- **bus side**: the bus iterations after the hand-off (``DriverCore.spin_once``) until the one
  whose DP cycle carried the first target (``MoveJob.left_at``): the inbox taken, the stream's
  records encoded, the link's DP cycle. In the stepped world the DP master runs in the bus thread
  (``link_port``'s in-process master); in the node it runs in the bus process
  (``bus/process.py``), the link supervisor's side the same. The virtual controller behind the
  in-memory link is not counted (its frames are fenced off).

The first goal runs what a node runs once (lazy imports, the tolerances' resolution made at the
first goal); the lists are the last goal's, the first goal's extra files said apart. Each goal is
cancelled once its first target left, and ends when the arm is at rest.

Prints both lists (in the order first run) and their counts; the last line, exactly:
  goal_side=N bus_side=N shared=N
(``shared``: files on both lists). Exit status 1 when a goal did not reach the wire.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import threading
import time
from types import SimpleNamespace
from typing import Callable, Dict, List, Optional, Set

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ("vr_driver", "pyprofibus_vendor", "panasonic_vr006l_support")
for _pkg in PACKAGES:
    _src = os.path.join(REPO, _pkg, "src")
    if _src not in sys.path:
        sys.path.insert(0, _src)
_WORLD_DIR = os.path.join(REPO, "vr_driver", "test", "driver")
if _WORLD_DIR not in sys.path:
    sys.path.insert(0, _WORLD_DIR)

#: the bus side's modules: on the goal side none of these may run (test_goal_walk.py)
BUS_SIDE = ("vr_driver/src/vr_driver/driver/bus_loop.py",
            "vr_driver/src/vr_driver/driver/link/",
            "vr_driver/src/vr_driver/bus/",
            "pyprofibus_vendor/src/")

GOAL = "goal side"
CALLBACK = "goal callback"        # on_goal, in the thread that gives it (actionlib's)
THREAD = "goal thread"            # the goal's own thread, to the supervisor
BUS = "bus side"


class FileTrace:
    """Which repository source files run, per phase: each thread records into the phase it is in
    (``phase_of``: a thread's phase at its first call, by its name; :meth:`enter` sets the calling
    thread's). ``cuts``: a code object whose call moves its thread to another phase (None: stop
    recording). ``fence``: a file whose frames, and all they call, are not recorded."""

    def __init__(self, fence: str, phase_of: Callable[[str], Optional[str]]) -> None:
        self.roots = [os.path.join(REPO, p, "src") + os.sep for p in PACKAGES]
        self.fence = os.path.abspath(fence)
        self.phase_of = phase_of
        self.cuts: Dict[object, Optional[str]] = {}
        self.cut_seen = threading.Event()
        self.files: Dict[str, Dict[str, str]] = {}      # phase -> {file: its first call}, in the order first run
        self._names: Dict[str, Optional[str]] = {}
        self._local = threading.local()

    def name(self, filename: str) -> Optional[str]:
        """``filename`` relative to the repository when it is a package's source, else None."""
        try:
            return self._names[filename]
        except KeyError:
            pass
        path = os.path.abspath(filename)
        rel = os.path.relpath(path, REPO) if any(path.startswith(r) for r in self.roots) else None
        self._names[filename] = rel
        return rel

    def enter(self, phase: Optional[str]) -> None:
        self._local.phase = phase

    def trace(self, frame, event, arg):
        local = self._local
        try:
            phase = local.phase
        except AttributeError:
            phase = local.phase = self.phase_of(threading.current_thread().name)
        if phase is None or event != "call":
            return None
        code = frame.f_code
        if code in self.cuts:
            phase = local.phase = self.cuts[code]
            self.cut_seen.set()
            if phase is None:
                return None
        filename = code.co_filename
        if filename == self.fence or os.path.abspath(filename) == self.fence:
            local.phase = None                   # until this frame returns

            def back(frame, event, arg):
                if event == "return":
                    local.phase = phase
                return back
            return back
        rel = self.name(filename)
        if rel is not None:
            files = self.files.setdefault(phase, {})
            if rel not in files:
                caller = frame.f_back
                where = ""
                while caller is not None and where == "":
                    where = self.name(caller.f_code.co_filename) or ""
                    if where:
                        where = "%s:%d" % (where, caller.f_lineno)
                    caller = caller.f_back
                files[rel] = "%s (from %s)" % (code.co_name, where or "outside")
        return None


class Handle:
    """An actionlib ServerGoalHandle as far as the goal runner uses it: records how the goal ended."""

    def __init__(self, goal_id: str, goal) -> None:
        self.goal = goal
        self._id = SimpleNamespace(id=goal_id)
        self.ended = threading.Event()
        self.state = ""
        self.text = ""

    def get_goal(self):
        return self.goal

    def get_goal_id(self):
        return self._id

    def set_accepted(self, text: str = "") -> None:
        pass

    def _end(self, state: str, result, text: str) -> None:
        self.state = state
        self.text = getattr(result, "error_string", "") or text
        self.ended.set()

    def set_rejected(self, result=None, text=""):
        self._end("rejected", result, text)

    def set_succeeded(self, result=None, text=""):
        self._end("succeeded", result, text)

    def set_canceled(self, result=None, text=""):
        self._end("canceled", result, text)

    def set_aborted(self, result=None, text=""):
        self._end("aborted", result, text)

    def publish_feedback(self, feedback) -> None:
        pass


def curved_goal(names, q0, n: int = 30, duration: float = 3.0):
    """A FollowJointTrajectory goal message: a curved planner-like path of ``n`` points after ``q0``,
    each joint on its own curve, with a smooth start and stop."""
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    import rospy
    from vr_driver.msg import FollowJointTrajectoryGoal
    amp = (0.3, 0.15, -0.2, 0.4, 0.3, 0.5)
    points = []
    for k in range(1, n + 1):
        u = k / n
        s = u * u * (3.0 - 2.0 * u)
        q = [a + b * (math.sin(0.5 * math.pi * s) + 0.3 * math.sin(3 * math.pi * s)) for a, b in zip(q0, amp)]
        points.append(JointTrajectoryPoint(positions=q, time_from_start=rospy.Duration.from_sec(duration * u)))
    return FollowJointTrajectoryGoal(trajectory=JointTrajectory(joint_names=list(names), points=points))


def walk(protocol: str = "v3", goals: int = 2, timeout: float = 60.0) -> Dict[str, object]:
    """Run ``goals`` goals one after the other (module docstring); returns {"first": {phase: files},
    "last": {phase: files}, "ok": every goal reached the wire, "words": what went wrong}."""
    import rospy.rostime
    from _world import World
    from vr_driver.kinematics.solver import Kinematics
    from vr_driver.ros.trajectory_server import TrajectoryServer

    rospy.rostime.set_rostime_initialized(True)      # rospy.get_time(): the wall clock (no node)
    world = World(Kinematics.default(), protocol=protocol)
    world.ready()
    server = TrajectoryServer(world.core, feedback_rate=20.0)
    out: Dict[str, object] = {"ok": True, "words": ""}
    for n in range(goals):
        files, words = one_goal(world, server, "goal-%d" % n, time.monotonic() + timeout)
        out["first" if n == 0 else "last"] = files
        if words:
            out["ok"], out["words"] = False, "goal %d: %s" % (n, words)
            break
    out.setdefault("last", out.get("first", {}))
    return out


def one_goal(world, server, goal_id: str, end: float):
    """One goal through ``server`` (a TrajectoryServer on ``world.core``) to its first target on the
    wire, then cancelled and run to its end: ({phase: files}, "" or what went wrong)."""
    from vr_driver.driver.joints.supervision import TrajectorySupervisor
    trace = FileTrace(os.path.join(_WORLD_DIR, "_world.py"),
                      lambda name: THREAD if name.startswith("trajectory") else None)
    trace.cuts[TrajectorySupervisor.__init__.__code__] = None      # the run handed over: only watched now
    runs: List[object] = []
    server.on_run = runs.append
    loop = world.core.bus_loop
    spin = loop.spin_once

    def traced_spin():
        trace.enter(BUS)
        try:
            return spin()
        finally:
            trace.enter(None)

    handle = Handle(goal_id, curved_goal(world.core.joint_names, world.status().joints))
    threading.settrace(trace.trace)
    sys.settrace(trace.trace)
    trace.enter(CALLBACK)
    try:
        server.goals.on_goal(handle)
    finally:
        trace.enter(None)
        sys.settrace(None)
        threading.settrace(None)        # (the goal's thread keeps its tracer: started under it)
    while not trace.cut_seen.wait(0.05):         # the goal's thread prepares; the bus waits meanwhile
        if handle.ended.is_set() or time.monotonic() > end:
            return trace.files, "never reached its supervisor: %s %s" % (handle.state, handle.text)
    job = runs[-1].jobs[0] if runs and runs[-1].jobs else None
    sys.settrace(trace.trace)
    loop.spin_once = traced_spin
    try:
        while job is not None and job.left_at is None and not job.done and time.monotonic() < end:
            world.tick()
    finally:
        del loop.spin_once
        sys.settrace(None)
    words = ""
    if job is None or job.left_at is None:
        words = "no target left (%s)" % (job.result.reason if job is not None and job.result else "no job")
    server.goals.on_cancel(handle)
    while not handle.ended.is_set() and time.monotonic() < end:
        world.tick()
    if not handle.ended.is_set():
        words = words or "did not end after its cancel"
    files = trace.files
    files[GOAL] = dict(files.get(CALLBACK, {}), **{k: v for k, v in files.get(THREAD, {}).items()
                                                   if k not in files.get(CALLBACK, {})})
    return files, words


def bus_side(path: str) -> bool:
    return any(path.startswith(p) for p in BUS_SIDE)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--protocol", default="v3", choices=("v2", "v3"), help="a streaming protocol (default v3)")
    ap.add_argument("--goals", type=int, default=2, help="goals run one after the other; the last is listed")
    ap.add_argument("--why", action="store_true", help="each file's first call and where it came from")
    ap.add_argument("--quick", action="store_true", help="(the smoke run's flag: the same run)")
    args = ap.parse_args(argv)
    t0 = time.monotonic()
    res = walk(args.protocol, max(1, args.goals))
    last: Dict[str, Dict[str, str]] = res["last"]      # type: ignore[assignment]
    first: Dict[str, Dict[str, str]] = res.get("first", {})      # type: ignore[assignment]
    goal, bus = list(last.get(GOAL, ())), list(last.get(BUS, ()))
    for phase, files in ((GOAL, goal), (BUS, bus)):
        print("%s (%d files):" % (phase, len(files)))
        for f in files:
            where = ""
            if phase == GOAL:
                where = "   (%s)" % "+".join(w for w, p in (("callback", CALLBACK), ("thread", THREAD))
                                             if f in last.get(p, ()))
            print("  %s%s%s%s" % (f, where, "   <- bus side" if phase == GOAL and bus_side(f) else "",
                                  "   " + last[phase][f] if args.why else ""))
        once = [f for f in first.get(phase, ()) if f not in files] if args.goals > 1 else []
        if once:
            print("  first goal only: %s" % " ".join(once))
    shared: Set[str] = set(goal) & set(bus)
    print("on both sides: %s" % (" ".join(sorted(shared)) or "none"))
    print("walked in %.1f s" % (time.monotonic() - t0))
    if not res["ok"]:
        print("FAILED: %s" % res["words"])
    print("goal_side=%d goal_thread=%d bus_side=%d shared=%d"
          % (len(goal), len(last.get(THREAD, ())), len(bus), len(shared)))
    return 0 if res["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
