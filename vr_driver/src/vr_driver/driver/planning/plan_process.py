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

- **The worker** (``python3 -m vr_driver.driver.planning.plan_process --fd N``, started, watched and
  stopped by :class:`vr_driver.bus.worker.WorkerProcess` as the bus process is: a new interpreter,
  never a fork of the node): :class:`PlanningParts` -- the parts of a driver that a plan needs
  (the model, the workspace box and the cell's checks, the protocol's stream preparation: the
  driver's own stream checks), no port, no thread, no sequencer -- and a
  :class:`~vr_driver.driver.planning.planning.PlanActionCore` on them, the same code that planned in the node
  before. It runs at the node's CPU priority, or lower (``nice`` +:data:`WORKER_NICE`) when the bus
  cycles in the node's own thread (:func:`worker_nice`), one plan at a time. It talks over a socket
  pair in typed messages (:mod:`vr_driver.driver.planning.plan_messages`: Configure -> Ready | Missing |
  StartFailed; Plan (with the scene when it changed) -> Outcome | PlanFailed; Stop; on the way
  Log: the worker's warnings, which the node logs as its own). It ends at Stop or when the node's
  end of the socket closes (EOF: the node ended or closed it), also in the middle of a plan; it
  ignores SIGINT (a Ctrl-C, roslaunch's stop of the process group is the node's to act on).
- **Started once**: :meth:`PlanningProcess.start` (the plan server calls it when it starts) waits
  until the worker has imported its libraries and built its models (about a second), so no plan pays
  for that, and so that a missing library is reported at once, by the worker, in
  MissingDependency's words (the node never imports the planner's OMPL and TOPP-RA; pinocchio and
  coal it has for its own collision checks).
- **The one scene**: before each plan the node reads the driver's scene as it is then
  (:class:`~vr_driver.driver.planning.plan_messages.SceneSnapshot`: the objects and the padding of the
  driver's checker, and whether it checks collisions, read under the driver's planning gate, the
  checker being replaced as a whole under it) and sends it when it differs from the one that worker
  got last (inside the request); the request carries the arm's joints then, and the bus's measured cycle time (the stream
  check's shortest segment). The worker plans against exactly that scene, rebuilding its checker
  only when the scene changed; a scene change is seen by the next plan.
- **Cancel while planning**: the worker is stopped (SIGKILL: it holds nothing but its own copies) and
  the plan ends PREEMPTED at once; a new worker starts at the same time, for the next plan.
- **A worker that dies** (a crash, a kill) ends the plan in progress with PLANNING_FAILED, in words
  saying the planning process died and how; a worker that does not answer within its planning
  budgets (:data:`~vr_driver.driver.planning.planning.ATTEMPTS` x the budget) + :data:`ANSWER_MARGIN` is
  stopped, with words (OMPL's PRMstar with a budget of 3 s never returned on this machine: in the
  node's interpreter that hung the goal for good). Either way a new worker is started at once, for
  the next plan. One that ended between two plans costs no plan: the next one starts a new worker
  first.
- **The node's side** costs a snapshot, a request (the scene only when it changed) and a pickled
  trajectory per plan; while
  the worker plans the node waits on the socket (no interpreter lock held), waking every
  :data:`CANCEL_POLL` seconds to see whether the goal was cancelled.
"""
from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from dataclasses import replace
from typing import TYPE_CHECKING, List, Optional, Sequence, Tuple

from ...bus.messages import Channel, Message
from ...bus.worker import FD, WorkerProcess, WorkerStartError, child_end, child_scheduling, end_with_parent
from ...errors import MissingDependency, VrDriverError
from ...kinematics.preview import MovePreviewer
from ...kinematics.scene import Scene
from ...params import DriverParams
from ...kinematics.solver import Kinematics
from ..core import DriverCore, driver_kinematics
from ..motion.jobs import Preview, StreamPoint
from ..checks.job_control import prepare_trajectory
from ..checks.path_checks import PathChecks
from .plan_messages import (Configure, Log, Missing, Outcome, Plan, PlanFailed, PlanMessageError, Ready,
                            SceneSnapshot, StartFailed, Stop, driver_end, worker_end)
from .planning import (ATTEMPTS, INVALID_ROBOT_STATE, PLANNING_FAILED, PREEMPTED, PlanActionCore, PlanGoal,
                       PlanOutcome, joints_to_plan_from)
from ..checks.scene_guard import SceneGuard
from ..checks.stream_prep import stream_preparation
from ..motion.trajectories import ValidTrajectory

if TYPE_CHECKING:
    from ...kinematics.collision import CollisionChecker

log = logging.getLogger("vr_driver.driver")

__all__ = ["PlanningProcess", "PlanningProcessError", "SceneSnapshot", "PlanningParts", "WORKER_NICE", "worker_nice",
           "READY_TIMEOUT", "ANSWER_MARGIN", "CANCEL_POLL"]

#: the worker's niceness above the node's when the bus cycles in the node's own thread
#: (``bus_process: false``): then it must never compete with the bus thread for a core. With the bus
#: in a process of its own (the default; real-time where allowed) the worker runs at the node's
#: priority: niced, a loaded machine left it so little CPU that a 1 s budget found no path
WORKER_NICE = 10


def worker_nice(params: DriverParams) -> int:
    """The worker's niceness above the node's for the driver's parameters (WORKER_NICE)."""
    return 0 if params.bus_process else WORKER_NICE


#: [s] the longest wait for a new worker to be ready (its imports and models take about a second;
#: a loaded machine, at the worker's low priority, longer)
READY_TIMEOUT = 60.0
#: [s] a worker silent this long beyond ATTEMPTS x the plan's budget is taken for hung and stopped
ANSWER_MARGIN = 30.0
#: [s] how often the node, waiting for a plan, looks whether its goal was cancelled
CANCEL_POLL = 0.05
#: the planning budget the answer deadline assumes for a budget the worker will refuse [s]
_MAX_BUDGET = 60.0


class PlanningProcessError(VrDriverError):
    """The planning process could not start, died, did not answer, or failed inside (the words say
    which and why)."""


class PlanningProcess:
    """The plan action's planning in a worker process (see the module text): :meth:`start` once,
    then :meth:`plan` per goal (one at a time; a second caller waits), :meth:`close` at the end.
    ``core``: the node's :class:`~vr_driver.driver.core.DriverCore` -- its parameters, planning
    gate, checker (the scene), status (the arm's joints) and bus cycle are read here; it is never
    touched otherwise. ``ready_timeout`` [s]: the longest wait for a new worker."""

    def __init__(self, core: DriverCore, ready_timeout: float = READY_TIMEOUT) -> None:
        self.core = core
        self.params = core.params
        self.ready_timeout = float(ready_timeout)
        self.kin: Optional[Kinematics] = None   # the node's own Kinematics for the plan's markers (start())
        self.workers_started = 0             # workers started so far (the first by start())
        self._lock = threading.Lock()        # one plan at a time; guards the worker
        self._worker: Optional[WorkerProcess] = None
        self._channel: Optional[Channel] = None
        self._scene_sent: Optional[SceneSnapshot] = None     # the scene this worker has
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
            if self._worker is None:
                self._spawn()
            try:
                self._await_ready(time.monotonic() + self.ready_timeout, None)
            except BaseException:
                self._stop_worker()
                raise

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker for good (the driver shuts down): a plan in progress ends PLANNING_FAILED
        at once, saying so, and no new worker is started; an idle worker is asked to stop."""
        self._closed = True
        if not self._lock.acquire(blocking=False):
            worker = self._worker
            if worker is not None and worker.running:
                worker.proc.kill()           # a plan waiting on it gets EOF now
            if not self._lock.acquire(timeout=timeout):
                return
        try:
            self._stop_worker(polite=True)
        finally:
            self._lock.release()

    @property
    def pid(self) -> Optional[int]:
        """The worker's process id (None: none running)."""
        return self._worker.pid if self._worker is not None else None

    @property
    def collision_checked(self) -> bool:
        """Whether plans are checked against the arm itself and the scene (as PlanActionCore's)."""
        return self.core.collision is not None and self.params.collision_check

    # ------------------------------------------------------------------ planning
    def plan(self, goal: PlanGoal, start: Optional[Sequence[float]] = None, seed: Optional[int] = None,
             cancel: Optional[threading.Event] = None) -> PlanOutcome:
        """Plan ``goal`` in the worker from ``start`` (default: the arm's joints now) against the
        driver's scene now, as :meth:`PlanActionCore.plan <vr_driver.driver.planning.planning.PlanActionCore.plan>`
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
            if self._worker is not None and not self._worker.running:     # it ended between two plans
                log.warning("planning process %d had ended (%s): starting a new one", self._worker.pid,
                            self._worker.exit_words())
                self._restart()
            try:
                if self._worker is None:
                    self._spawn()
                self._await_ready(time.monotonic() + self.ready_timeout, cancel)
            except _Cancelled:
                return replace(cancelled(), text="cancelled before it was planned")   # the new worker goes on
            except (PlanningProcessError, MissingDependency) as exc:
                self._restart()                                    # the next plan tries a new one
                return failed("no plan: the planning process could not start: %s" % exc)
            scene = SceneSnapshot.of(self.core)
            try:
                self._send(Plan(goal, tuple(float(v) for v in start), seed, float(self.core.stream_cycle_rate()),
                                None if scene == self._scene_sent else scene))
                self._scene_sent = scene
                answer = self._receive(time.monotonic() + self._answer_time(goal), cancel, "an answer")
            except _Cancelled:
                self._restart()
                return cancelled()
            except PlanningProcessError as exc:
                self._restart()
                return failed("no plan: %s" % exc)
            if isinstance(answer, Outcome):
                return answer.outcome
            raise PlanningProcessError("the planning process failed: %s" % _words(answer))

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
        try:
            worker = WorkerProcess("vr_driver.driver.planning.plan_process",
                                   ["--fd", FD, "--nice", str(worker_nice(self.params))], "planning process")
        except WorkerStartError as exc:
            raise PlanningProcessError(exc.strerror) from None
        self._worker, self._channel, self._ready, self._scene_sent = worker, driver_end(worker.conn), False, None
        self.workers_started += 1
        try:
            self._channel.send(Configure(self.params))
        except OSError:
            pass                             # it died already: the wait for its start says how
        log.info("planning process %d started", worker.pid)

    def _send(self, message: Message) -> None:
        try:
            self._channel.send(message)
        except OSError:                      # its end is closed: it is ending
            raise PlanningProcessError("the planning process (pid %d) died (%s)"
                                       % (self._worker.pid, self._worker.reap())) from None

    def _await_ready(self, deadline: float, cancel: Optional[threading.Event]) -> None:
        if self._ready:
            return
        answer = self._receive(deadline, cancel, "its start")
        if isinstance(answer, Ready):
            self._ready = True
            return
        if isinstance(answer, Missing):
            exc = MissingDependency(answer.package, answer.module, answer.feature)
            exc.args, exc.msg = (answer.text,), answer.text   # the worker's words, its reason included
            raise exc
        raise PlanningProcessError("the planning process cannot plan here: %s" % _words(answer))

    def _receive(self, deadline: float, cancel: Optional[threading.Event], what: str) -> Message:
        """The worker's next message (its log records logged here on the way); _Cancelled when
        ``cancel`` is set first; PlanningProcessError when the worker dies, sends a malformed
        message, or is silent until ``deadline`` (time.monotonic)."""
        channel, worker = self._channel, self._worker
        while True:
            if cancel is not None and cancel.is_set():
                raise _Cancelled()
            left = deadline - time.monotonic()
            if left <= 0.0:
                raise PlanningProcessError("the planning process (pid %d) did not send %s in time; it was "
                                           "stopped" % (worker.pid, what))
            try:
                if not channel.poll(min(left, CANCEL_POLL) if cancel is not None else left):
                    continue
                answer = channel.recv()
            except (EOFError, OSError):
                raise PlanningProcessError("the planning process (pid %d) died (%s)"
                                           % (worker.pid, worker.reap())) from None
            except PlanMessageError as exc:
                raise PlanningProcessError("the planning process (pid %d) sent %s; it was stopped"
                                           % (worker.pid, exc)) from None
            if not isinstance(answer, Log):
                return answer
            log.log(answer.level, "planning process: %s", answer.text)

    def _stop_worker(self, polite: bool = False) -> None:
        """The worker stopped: SIGKILL (it holds nothing but its own copies), or ``polite``: Stop,
        then EOF, SIGTERM, SIGKILL (bus.worker)."""
        worker, channel = self._worker, self._channel
        self._worker = self._channel = self._scene_sent = None
        self._ready = False
        if worker is None:
            return
        if polite and channel is not None:
            worker.stop(polite=lambda: channel.send(Stop()))
        else:
            worker.kill()

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


def _words(answer: Message) -> str:
    """A failure's words (PlanFailed, StartFailed), or what came instead."""
    if isinstance(answer, (PlanFailed, StartFailed)):
        return answer.text
    return "it answered with %s" % type(answer).__name__


class _Cancelled(Exception):
    """The goal was cancelled while the node waited for the worker."""


# ---------------------------------------------------------------------------------- the worker side
class PlanningParts:
    """The parts of a driver that :class:`~vr_driver.driver.planning.planning.PlanActionCore` plans with, and
    nothing else: the model (:attr:`kin`), the protocol, the joint names, the planning gate, the
    workspace box and the cell's checks (:attr:`checks`; its scene_guard replaced when the node's
    scene changed), the protocol's stream preparation (:attr:`streams`) and
    :meth:`prepare_trajectory` -- the driver's own check of what it would send for a plan. No port,
    no thread, no sequencer, no I/O line, no cell file. Its streams are fed at the node's bus cycle
    rate (:attr:`node_cycle_rate`, set per request): the node measures its bus cycle; until a
    request brings it, the configured rate."""

    def __init__(self, params: DriverParams) -> None:
        self.params = params
        self.kin = driver_kinematics(params)
        self.wire = params.wire
        self.joint_names = params.controller_joint_names
        self.planning_gate = threading.Lock()
        self.node_cycle_rate: Optional[float] = None
        self._cycle_rate = params.bus().cycle_rate_hz
        self.checks = PathChecks(self.kin, MovePreviewer(self.kin), params.workspace, self.planning_gate,
                                 SceneGuard(self.kin, self.planning_gate, Scene(), params.collision_padding,
                                            params.collision_check, params.prefix, model=params.model),
                                 self.wire)
        self.streams = stream_preparation(params, self.kin, self.wire, self.checks, self.stream_cycle_rate)

    @property
    def collision(self) -> Optional["CollisionChecker"]:
        """The checker of the scene set last (None: nothing checked), as DriverCore.collision."""
        return self.checks.collision

    def stream_cycle_rate(self) -> float:
        """[Hz] the node's (DriverCore.stream_cycle_rate, sent with the plan), else the configured rate."""
        return self._cycle_rate if self.node_cycle_rate is None else self.node_cycle_rate

    def prepare_trajectory(self, traj: ValidTrajectory, start: Sequence[float]
                           ) -> Tuple[List[int], Tuple[StreamPoint, ...], List[Preview]]:
        """What the driver would send for ``traj``, checked (job_control.prepare_trajectory)."""
        return prepare_trajectory(self.kin, self.checks, self.streams, traj, start)


class _Worker:
    """The worker's planning: a PlanActionCore on the planning parts, its scene set by the node."""

    def __init__(self, params: DriverParams) -> None:
        self.parts = PlanningParts(params)
        self.planning = PlanActionCore(self.parts, kinematics=self.parts.kin)   # one thread: one model
        self.scene: Optional[SceneSnapshot] = None
        self.scene_error = ""

    def set_scene(self, snap: SceneSnapshot) -> None:
        """The node's scene for the plans to come (a scene that cannot be built fails them, saying why)."""
        if snap == self.scene:
            return
        params = self.parts.params
        try:
            guard = SceneGuard(self.parts.kin, self.parts.planning_gate, snap.scene(), snap.padding, snap.checked,
                               params.prefix, model=params.model)
        except VrDriverError as exc:
            self.scene, self.scene_error = None, "the scene sent cannot be built: %s" % exc
            return
        self.parts.checks.scene_guard, self.scene, self.scene_error = guard, snap, ""

    def plan(self, request: Plan) -> PlanOutcome:
        if request.scene is not None:
            self.set_scene(request.scene)
        if self.scene_error:
            raise PlanningProcessError(self.scene_error)
        self.parts.node_cycle_rate = request.cycle_rate
        return self.planning.plan(request.goal, request.start, request.seed)


class _ToNode(logging.Handler):
    """The worker's log records (the driver's, e.g. a collision check's refusal of a plan that is
    then planned again) sent to the node, which logs them as its own (rosout); the main thread's
    only -- the socket is the main thread's -- others' on stderr."""

    def __init__(self, channel: Channel) -> None:
        super().__init__(logging.WARNING)
        self.channel = channel
        self.thread = threading.get_ident()
        self.fallback = logging.StreamHandler()

    def emit(self, record: logging.LogRecord) -> None:
        if threading.get_ident() != self.thread:
            self.fallback.handle(record)
            return
        try:
            self.channel.send(Log(record.levelno, self.format(record)))
        except OSError:
            pass                             # the node is gone: so is this process, soon


def _answer(worker: _Worker, message: Message) -> Message:
    """The worker's answer to one of the node's messages."""
    if not isinstance(message, Plan):
        return PlanFailed("planning message %s not expected once the process plans" % type(message).__name__)
    try:
        return Outcome(worker.plan(message))
    except Exception as exc:  # a planner bug: the node's goal ends with it, this process goes on
        log.exception("plan failed")
        return PlanFailed("%s: %s" % (type(exc).__name__, exc))


def main(argv: Optional[List[str]] = None) -> int:
    """The worker (module text): ``--fd N`` its end of the socket pair."""
    parser = argparse.ArgumentParser(prog="python3 -m vr_driver.driver.planning.plan_process",
                                     description="the plan action's planning process (started by the driver)")
    parser.add_argument("--fd", type=int, required=True, help="its end of the socket pair to the driver")
    parser.add_argument("--nice", type=int, default=WORKER_NICE, help="niceness above the node's (default %d)"
                        % WORKER_NICE)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="plan_process[%(process)d] %(levelname)s: %(message)s")
    child_scheduling(nice=args.nice)
    channel = worker_end(child_end(args.fd))
    end_with_parent(args.fd)
    for name in ("vr_driver", "pyprofibus_vendor"):
        logger = logging.getLogger(name)
        logger.addHandler(_ToNode(channel))
        logger.propagate = False
    try:
        first = channel.recv()
        if not isinstance(first, Configure):
            raise PlanMessageError("the first message must be the parameters, got %s" % type(first).__name__)
        worker = _Worker(first.params)
    except (EOFError, OSError):
        return 0
    except MissingDependency as exc:
        channel.send(Missing(exc.package, exc.module, exc.feature, str(exc)))
        return 1
    except Exception as exc:  # a model it cannot plan for (limits, a model file), a bad start: said in words
        channel.send(StartFailed("%s: %s" % (type(exc).__name__, exc)))
        return 1
    channel.send(Ready())
    while True:
        try:
            message = channel.recv()
        except (EOFError, OSError):
            return 0
        except PlanMessageError as exc:      # changes nothing: the plan it was ends with the words
            answer: Message = PlanFailed(str(exc))
        else:
            if isinstance(message, Stop):
                return 0
            answer = _answer(worker, message)
        try:
            channel.send(answer)
        except OSError:                       # the node is gone
            return 0


if __name__ == "__main__":
    import sys
    sys.exit(main())
