"""The plan action's planning in a worker OS process of its own, off the driver's interpreter.
ROS-free.

Why: the node `interface` runs the bus loop in a thread of its Python interpreter, and OMPL's solve
(and other C++ calls of the planner: TOPP-RA, pinocchio / coal) hold the interpreter lock for 0.6
to 5 s at a time. In the node's own interpreter that starved the bus thread past the controller
card's watchdog (300 ms: the card stops the arm). In a process of its own a plan of any length
delays no bus cycle: the node only sends a request and waits on a socket.

    planning = PlanningProcess(core)       # the DriverCore of the node (not started here)
    planning.start()                       # the worker, ready to plan; MissingDependency (naming the
                                           # package and scripts/setup) when it cannot plan here
    outcome = planning.plan(PlanGoal(named="home"), cancel=event)   # a PlanOutcome, as PlanActionCore's
    planning.kin, planning.collision_checked                          # for the plan's markers
    planning.close()

- **The worker** (``python3 -m vr_driver.driver.plan_process --fd N``, started with
  :class:`subprocess.Popen`, never forked from the node: a fork would copy the rospy threads'
  locks in whatever state they were): an unstarted :class:`~vr_driver.driver.core.DriverCore` of
  the node's parameters (it opens no port and starts no thread: its link factory refuses, and
  ``start()`` is never called) and a :class:`~vr_driver.driver.planning.PlanActionCore` on it --
  the same code that planned in the node before, the driver's own stream checks included. It runs
  at the node's CPU priority, or lower (``nice`` +:data:`WORKER_NICE`) when the bus cycles in the
  node's own thread (:func:`worker_nice`), one plan at a time. It talks over a
  ``socket.socketpair()`` (``pass_fds``) wrapped in a :class:`multiprocessing.connection.Connection`
  (pickled messages: ``("start", DriverParams)`` -> ``("ready", None)`` | ``("missing", ...)`` |
  ``("error", words)``; then ``("plan", PlanRequest)`` -> ``("outcome", PlanOutcome)`` |
  ``("exception", words)``; on the way ``("log", (level, words))``: the worker's warnings, which the
  node logs as its own). It ends when the node's end of the socket closes (EOF: the node ended
  or closed it), also in the middle of a plan; it ignores SIGINT (a Ctrl-C, roslaunch's stop of the
  process group is the node's to act on).
- **Started once**: :meth:`PlanningProcess.start` (the plan server calls it when it starts) waits
  until the worker has imported its libraries and built its models (about a second), so no plan pays
  for that, and so that a missing library is reported at once, by the worker, in
  MissingDependency's words (the node never imports the planner's OMPL and TOPP-RA; pinocchio and
  coal it has for its own collision checks).
- **The one scene**: each request carries the driver's scene as it is when the plan starts
  (:class:`SceneSnapshot`: the objects and the padding of the driver's checker, and whether it
  checks collisions, read under the driver's planning gate, the checker being replaced as a whole
  under it), the arm's joints then, and the bus's measured cycle time (the stream check's shortest
  segment). The worker plans against exactly that scene, rebuilding its checker only when the scene
  differs from its last; a scene change is seen by the next plan.
- **Cancel while planning**: the worker is stopped (SIGKILL: it holds nothing but its own copies) and
  the plan ends PREEMPTED at once; a new worker starts at the same time, for the next plan.
- **A worker that dies** (a crash, a kill) ends the plan in progress with PLANNING_FAILED, in words
  saying the planning process died and how; a worker that does not answer within its planning
  budgets (:data:`~vr_driver.driver.planning.ATTEMPTS` x the budget) + :data:`ANSWER_MARGIN` is
  stopped, with words (OMPL's PRMstar with a budget of 3 s never returned on this machine: in the
  node's interpreter that hung the goal for good). Either way a new worker is started at once, for
  the next plan. One that ended between two plans costs no plan: the next one starts a new worker
  first.
- **The node's side** costs a snapshot, a pickled request and a pickled trajectory per plan; while
  the worker plans the node waits on the socket (no interpreter lock held), waking every
  :data:`CANCEL_POLL` seconds to see whether the goal was cancelled.
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from typing import Any, List, Optional, Sequence, Tuple

from ..errors import MissingDependency, VrDriverError
from ..kinematics.scene import Scene, SceneObject
from .core import DriverCore, driver_kinematics
from .planning import (ATTEMPTS, INVALID_ROBOT_STATE, PLANNING_FAILED, PREEMPTED, PlanActionCore, PlanGoal,
                       PlanOutcome, joints_to_plan_from)
from .scene_guard import SceneGuard

log = logging.getLogger("vr_driver.driver")

__all__ = ["PlanningProcess", "PlanningProcessError", "PlanRequest", "SceneSnapshot", "PlanningCore", "WORKER_NICE", "worker_nice",
           "READY_TIMEOUT", "ANSWER_MARGIN", "CANCEL_POLL"]

#: the worker's niceness above the node's when the bus cycles in the node's own thread
#: (``bus_process: false``): then it must never compete with the bus thread for a core. With the bus
#: in a process of its own (the default; real-time where allowed) the worker runs at the node's
#: priority: niced, a loaded machine left it so little CPU that a 1 s budget found no path
WORKER_NICE = 10


def worker_nice(params: Any) -> int:
    """The worker's niceness above the node's for the driver's parameters (WORKER_NICE)."""
    return 0 if getattr(params, "bus_process", True) else WORKER_NICE
#: [s] the longest wait for a new worker to be ready (its imports and models take about a second;
#: a loaded machine, at the worker's low priority, longer)
READY_TIMEOUT = 60.0
#: [s] a worker silent this long beyond ATTEMPTS x the plan's budget is taken for hung and stopped
ANSWER_MARGIN = 30.0
#: [s] how often the node, waiting for a plan, looks whether its goal was cancelled
CANCEL_POLL = 0.05
#: the planning budget the answer deadline assumes for a budget the worker will refuse [s]
_MAX_BUDGET = 60.0

#: a scene object as the socket carries it: (name, shape, size, position, quaternion)
ObjectTuple = Tuple[str, str, Tuple[float, ...], Tuple[float, ...], Tuple[float, ...]]


class PlanningProcessError(VrDriverError):
    """The planning process could not start, died, did not answer, or failed inside (the words say
    which and why)."""


@dataclass(frozen=True)
class SceneSnapshot:
    """The driver's scene as a plan uses it: the objects of its checker (as tuples: a SceneObject
    itself does not pickle), the checker's padding [m], and ``checked``: whether the driver checks
    collisions (it has a checker). Without checking the objects are left out (nothing checks them)."""

    objects: Tuple[ObjectTuple, ...]
    padding: float
    checked: bool

    @classmethod
    def of(cls, core: Any) -> "SceneSnapshot":
        """The scene of ``core``'s checker now, read under the core's planning gate (the checker,
        its scene and padding are replaced as a whole under it, never changed in place)."""
        with core.planning_gate:
            checker = core.collision
            if checker is None or not getattr(core.params, "collision_check", True):
                return cls((), float(core.params.collision_padding), False)
            objects = tuple((o.name, o.shape, tuple(o.size), tuple(o.position), tuple(o.quaternion))
                            for o in checker.scene.objects())
            return cls(objects, float(checker.padding), True)

    def scene(self) -> Scene:
        """The objects as a Scene (each rebuilt by SceneObject's own checks)."""
        return Scene([SceneObject(name, shape, size, position, quaternion=quaternion)
                      for name, shape, size, position, quaternion in self.objects])


@dataclass(frozen=True)
class PlanRequest:
    """One plan for the worker: the goal, the arm's joints to plan from, the planner's seed (None:
    random), the scene, and the node's shortest stream segment [s] (its measured bus cycle:
    :meth:`DriverCore.min_segment`), so that the worker's stream check is the node's."""

    goal: PlanGoal
    start: Tuple[float, ...]
    seed: Optional[int]
    scene: SceneSnapshot
    min_segment: float


def _exit_words(returncode: Optional[int]) -> str:
    if returncode is None:
        return "still running"
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = "signal %d" % -returncode
        return "killed by %s" % name
    return "exit status %d" % returncode


class PlanningProcess:
    """The plan action's planning in a worker process (see the module text): :meth:`start` once,
    then :meth:`plan` per goal (one at a time; a second caller waits), :meth:`close` at the end.
    ``core``: the node's :class:`~vr_driver.driver.core.DriverCore` -- its parameters, planning
    gate, checker (the scene), status (the arm's joints) and bus cycle are read here; it is never
    touched otherwise. ``ready_timeout`` [s]: the longest wait for a new worker."""

    def __init__(self, core: Any, ready_timeout: float = READY_TIMEOUT) -> None:
        self.core = core
        self.params = core.params
        self.ready_timeout = float(ready_timeout)
        self.kin: Any = None                 # the node's own Kinematics for the plan's markers (start())
        self.workers_started = 0             # workers started so far (the first by start())
        self._lock = threading.Lock()        # one plan at a time; guards the worker
        self._proc: Optional[subprocess.Popen] = None
        self._conn: Optional[Connection] = None
        self._ready = False
        self._closed = False

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start the worker and wait until it is ready to plan. Raises MissingDependency (the
        worker's words: the package, scripts/setup) when OMPL, TOPP-RA or, with collision_check on,
        the checker's libraries cannot be imported, PlanningProcessError when it cannot start for
        another reason (the worker's words); no worker is left running then."""
        with self._lock:
            if self.kin is None:
                self.kin = driver_kinematics(self.params)   # its own: none shared with the bus thread
            if self._proc is None:
                self._spawn()
            try:
                self._await_ready(time.monotonic() + self.ready_timeout, None)
            except BaseException:
                self._stop_worker()
                raise

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker for good (the driver shuts down): a plan in progress ends PLANNING_FAILED
        at once, saying so, and no new worker is started."""
        self._closed = True
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.kill()                      # a plan waiting on it gets EOF now
        if self._lock.acquire(timeout=timeout):
            try:
                self._stop_worker()
            finally:
                self._lock.release()

    @property
    def pid(self) -> Optional[int]:
        """The worker's process id (None: none running)."""
        return self._proc.pid if self._proc is not None else None

    @property
    def collision_checked(self) -> bool:
        """Whether plans are checked against the arm itself and the scene (as PlanActionCore's)."""
        return getattr(self.core, "collision", None) is not None and getattr(self.params, "collision_check", True)

    # ------------------------------------------------------------------ planning
    def plan(self, goal: PlanGoal, start: Optional[Sequence[float]] = None, seed: Optional[int] = None,
             cancel: Optional[threading.Event] = None) -> PlanOutcome:
        """Plan ``goal`` in the worker from ``start`` (default: the arm's joints now) against the
        driver's scene now, as :meth:`PlanActionCore.plan <vr_driver.driver.planning.PlanActionCore.plan>`
        would. ``cancel`` set while it plans: the worker is stopped and the outcome is PREEMPTED.
        Never raises for a bad goal or a worker that dies (the outcome says);
        PlanningProcessError when the worker failed inside (a planner bug: its words)."""
        t0 = time.monotonic()
        planner_id = goal.planner_id or self.params.planner_id

        def failed(words: str) -> PlanOutcome:
            return PlanOutcome(PLANNING_FAILED, words, planning_time=time.monotonic() - t0, planner_id=planner_id)

        def cancelled() -> PlanOutcome:
            return PlanOutcome(PREEMPTED, "cancelled while planning (the planning process was stopped)",
                               planning_time=time.monotonic() - t0, planner_id=planner_id)

        with self._lock:
            if cancel is not None and cancel.is_set():      # cancelled while an earlier plan ran
                return replace(cancelled(), text="cancelled before it was planned")
            if self._closed:
                return failed("no plan: the planning process was closed (the driver is shutting down)")
            if start is None:
                start = joints_to_plan_from(self.core.status())
                if isinstance(start, str):
                    return PlanOutcome(INVALID_ROBOT_STATE, start, planner_id=planner_id)
            if self._proc is not None and self._proc.poll() is not None:     # it ended between two plans
                log.warning("planning process %d had ended (%s): starting a new one", self._proc.pid,
                            _exit_words(self._proc.returncode))
                self._restart()
            try:
                if self._proc is None:
                    self._spawn()
                self._await_ready(time.monotonic() + self.ready_timeout, cancel)
            except _Cancelled:
                return replace(cancelled(), text="cancelled before it was planned")   # the new worker goes on
            except (PlanningProcessError, MissingDependency) as exc:
                self._restart()                                    # the next plan tries a new one
                return failed("no plan: the planning process could not start: %s" % exc)
            request = PlanRequest(goal, tuple(float(v) for v in start), seed, SceneSnapshot.of(self.core),
                                  float(self.core.min_segment()))
            try:
                self._send(("plan", request))
                kind, payload = self._receive(time.monotonic() + self._answer_time(goal), cancel, "an answer")
            except _Cancelled:
                self._restart()
                return cancelled()
            except PlanningProcessError as exc:
                self._restart()
                return failed("no plan: %s" % exc)
            if kind == "outcome":
                return payload
            raise PlanningProcessError("the planning process failed: %s" % (payload,))

    def _answer_time(self, goal: PlanGoal) -> float:
        """[s] how long a plan of ``goal`` may take before the worker is taken for hung."""
        budget = goal.planning_time or self.params.planning_time
        if not (isinstance(budget, (int, float)) and math.isfinite(budget) and 0.0 < budget <= _MAX_BUDGET):
            budget = _MAX_BUDGET
        return ATTEMPTS * budget + ANSWER_MARGIN

    # ------------------------------------------------------------------ the worker
    def _spawn(self) -> None:
        """Start a worker (not waiting for it): a new interpreter that imports this module, with
        the node's module path, and its end of a socket pair; it gets the parameters at once."""
        ours, theirs = socket.socketpair()
        # blocking, whatever socket.setdefaulttimeout() says: rospy sets one (60 s), which makes new
        # sockets non-blocking underneath -- the worker's end shares the flag and its recv raised
        # BlockingIOError (the worker died at the node's first request)
        ours.setblocking(True)
        theirs.setblocking(True)
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)   # the node's modules, e.g. a source tree
        try:
            proc = subprocess.Popen([sys.executable, "-m", "vr_driver.driver.plan_process",
                                     "--fd", str(theirs.fileno()), "--nice", str(worker_nice(self.params))],
                                    pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env)
        except OSError as exc:
            ours.close()
            raise PlanningProcessError("cannot start the planning process (%s -m vr_driver.driver."
                                       "plan_process): %s" % (sys.executable, exc)) from None
        finally:
            theirs.close()                   # the worker's copy is its only one: its death is our EOF
        self._proc, self._conn, self._ready = proc, Connection(ours.detach()), False
        self.workers_started += 1
        try:
            self._conn.send(("start", self.params))
        except OSError:
            pass                             # it died already: the wait for its start says how
        log.info("planning process %d started", proc.pid)

    def _send(self, message: Tuple[str, Any]) -> None:
        try:
            self._conn.send(message)
        except OSError:                      # its end is closed: it is ending
            raise PlanningProcessError("the planning process (pid %d) died (%s)"
                                       % (self._proc.pid, self._reap())) from None

    def _await_ready(self, deadline: float, cancel: Optional[threading.Event]) -> None:
        if self._ready:
            return
        kind, payload = self._receive(deadline, cancel, "its start")
        if kind == "ready":
            self._ready = True
            return
        if kind == "missing":
            package, module, feature, text = payload
            exc = MissingDependency(package, module, feature)
            exc.args, exc.msg = (text,), text    # the worker's words, its reason included (ImportError's str: msg)
            raise exc
        raise PlanningProcessError("the planning process cannot plan here: %s" % (payload,))

    def _receive(self, deadline: float, cancel: Optional[threading.Event], what: str) -> Tuple[str, Any]:
        """The worker's next message (its log records logged here on the way); _Cancelled when
        ``cancel`` is set first; PlanningProcessError when the worker dies or is silent until
        ``deadline`` (time.monotonic)."""
        conn = self._conn
        while True:
            if cancel is not None and cancel.is_set():
                raise _Cancelled()
            left = deadline - time.monotonic()
            if left <= 0.0:
                raise PlanningProcessError("the planning process (pid %d) did not send %s in time; it was "
                                           "stopped" % (self._proc.pid, what))
            try:
                if not conn.poll(min(left, CANCEL_POLL) if cancel is not None else left):
                    continue
                kind, payload = conn.recv()
            except (EOFError, OSError):
                raise PlanningProcessError("the planning process (pid %d) died (%s)"
                                           % (self._proc.pid, self._reap())) from None
            if kind != "log":
                return kind, payload
            level, text = payload
            log.log(level, "planning process: %s", text)

    def _reap(self) -> str:
        """How the worker ended (it closed its socket: it is ending)."""
        try:
            self._proc.wait(5.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
            return "its socket closed; it was stopped"
        return _exit_words(self._proc.returncode)

    def _stop_worker(self) -> None:
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        self._ready = False
        if conn is not None:
            conn.close()                     # EOF: a worker that still reads ends by itself
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()

    def _restart(self) -> None:
        """Stop the worker and start a new one at once (its imports overlap the wait for the next
        goal); a new one that cannot start is reported by the next plan."""
        self._stop_worker()
        if self._closed:
            return
        try:
            self._spawn()
        except PlanningProcessError as exc:
            log.error("%s", exc)


class _Cancelled(Exception):
    """The goal was cancelled while the node waited for the worker."""


# ---------------------------------------------------------------------------------- the worker side
def _no_port(device: str, baud: int) -> Any:
    raise PlanningProcessError("the planning process opens no port (%s)" % device)


class PlanningCore(DriverCore):
    """The worker's DriverCore, never started: no port (its link factory refuses; the link is never
    stepped), no thread (``start()`` is never called), no I/O line, no cell file (each request brings
    the scene). Its shortest stream segment is the node's (:attr:`node_min_segment`, set per
    request): the node measures its bus cycle, this core never runs one."""

    node_min_segment: Optional[float] = None

    def __init__(self, params: Any) -> None:
        super().__init__(replace(params, scene="", io_signals=""), open_link=_no_port)

    def min_segment(self) -> float:
        return self.node_min_segment if self.node_min_segment is not None else super().min_segment()


class _Worker:
    """The worker's planning: a PlanActionCore on an unstarted core, its scene set per request."""

    def __init__(self, params: Any) -> None:
        self.core = PlanningCore(params)
        self.planning = PlanActionCore(self.core, kinematics=self.core.kin)   # one thread: one model
        self.scene: Optional[SceneSnapshot] = None

    def plan(self, request: PlanRequest) -> PlanOutcome:
        if request.scene != self.scene:
            snap, params = request.scene, self.core.params
            self.core.scene_guard = SceneGuard(self.core.kin, self.core.planning_gate, snap.scene(), snap.padding,
                                               snap.checked, params.prefix, model=params.model)
            self.scene = snap
        self.core.node_min_segment = request.min_segment
        return self.planning.plan(request.goal, request.start, request.seed)


def _exit_with_parent(fd: int) -> None:
    """A daemon thread that ends the process when the node's end of the socket closes -- also while
    a plan runs (the main thread reads the socket only between plans)."""
    def watch() -> None:
        poller = select.poll()
        poller.register(fd, select.POLLRDHUP)
        while True:
            for _fd, events in poller.poll():
                if events & (select.POLLRDHUP | select.POLLHUP | select.POLLERR | select.POLLNVAL):
                    os._exit(0)
    threading.Thread(target=watch, name="plan_process-parent", daemon=True).start()


class _ToNode(logging.Handler):
    """The worker's log records (the driver's, e.g. a collision check's refusal of a plan that is
    then planned again) sent to the node, which logs them as its own (rosout); the main thread's
    only -- the socket is the main thread's -- others' on stderr."""

    def __init__(self, conn: Connection) -> None:
        super().__init__(logging.WARNING)
        self.conn = conn
        self.thread = threading.get_ident()
        self.fallback = logging.StreamHandler()

    def emit(self, record: logging.LogRecord) -> None:
        if threading.get_ident() != self.thread:
            self.fallback.handle(record)
            return
        try:
            self.conn.send(("log", (record.levelno, self.format(record))))
        except OSError:
            pass                             # the node is gone: so is this process, soon


def main(argv: Optional[List[str]] = None) -> int:
    """The worker (module text): ``--fd N`` its end of the socket pair."""
    parser = argparse.ArgumentParser(prog="python3 -m vr_driver.driver.plan_process",
                                     description="the plan action's planning process (started by the driver)")
    parser.add_argument("--fd", type=int, required=True, help="its end of the socket pair to the driver")
    parser.add_argument("--nice", type=int, default=WORKER_NICE, help="niceness above the node's (default %d)"
                        % WORKER_NICE)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="plan_process[%(process)d] %(levelname)s: %(message)s")
    if args.nice > 0:
        os.nice(args.nice)
    # a Ctrl-C (roslaunch's SIGINT to the process group) is the node's to act on: this process ends
    # when the node's end of the socket closes (a SIGTERM or SIGKILL still ends it at once)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.set_blocking(args.fd, True)
    conn = Connection(args.fd)
    _exit_with_parent(args.fd)
    for name in ("vr_driver", "pyprofibus_vendor"):
        logger = logging.getLogger(name)
        logger.addHandler(_ToNode(conn))
        logger.propagate = False
    try:
        kind, params = conn.recv()
    except EOFError:
        return 0
    try:
        if kind != "start":
            raise PlanningProcessError("the first message must be the parameters, got %r" % (kind,))
        worker = _Worker(params)
    except MissingDependency as exc:
        conn.send(("missing", (exc.package, exc.module, exc.feature, str(exc))))
        return 1
    except Exception as exc:  # a model it cannot plan for (limits, a model file): said in words
        conn.send(("error", "%s: %s" % (type(exc).__name__, exc)))
        return 1
    conn.send(("ready", None))
    while True:
        try:
            kind, request = conn.recv()
        except EOFError:
            return 0
        try:
            answer: Tuple[str, Any] = ("outcome", worker.plan(request))
        except Exception as exc:  # a planner bug: the node's goal ends with it, this process goes on
            log.exception("plan failed")
            answer = ("exception", "%s: %s" % (type(exc).__name__, exc))
        try:
            conn.send(answer)
        except OSError:                       # the node is gone
            return 0


if __name__ == "__main__":
    # run as the module itself, not as __main__: the pickled messages name its classes
    from vr_driver.driver import plan_process
    sys.exit(plan_process.main())
