"""Job control (ROS-free, no I/O): the requests that put motion on the sequencer's queue or take it
off -- a move, a joint path, a planner trajectory, a cancel, a stop -- and the planning thread.

Requests from other threads validate and plan in the caller's thread -- never on the bus thread,
and under no lock the bus needs -- and then post the job to the sequencer and wake the bus loop.
A job that must be planned again (the arm is not where it was planned from) is planned on the
planning thread (:class:`PlanningThread`; :meth:`PlanningThread.run_pending` in stepped tests).
Nothing is queued that was not validated first (README "Reliability"): a request that fails any
check raises with the reason and queues nothing.
"""
from __future__ import annotations

import collections
import logging
import threading
from typing import Callable, Deque, List, Optional, Sequence, Tuple

from ...errors import CollisionError, VrDriverError
from ...kinematics.solver import Kinematics
from ...params import DriverParams
from ...poses import MoveType
from ..motion.jobs import MoveJob, MoveRequest, Preview, StreamPoint, SubmitMode
from ..own_thread import OwnThread
from .path_checks import PathChecks
from .scene_guard import hand_over
from ..motion.sequencer import SequencerBase, SequencerView
from ..motion.inbox import MotionSnapshot
from ..motion.status import DriverError
from .stream_prep import JointStreams
from ..motion.trajectories import ValidTrajectory, thin

log = logging.getLogger("vr_driver.driver")

__all__ = ["JobControl", "PlanningThread", "TrajectoryRun"]


class TrajectoryRun:
    """A planner trajectory on its way (v1: a joint path of its thinned points). ``jobs[i]``
    goes to ``traj.positions[kept[i + 1]]``. ``started``: the driver's clock at the plan's time 0
    -- the goal's arrival (its start time, when its header stamp lies ahead), so that the figures
    of the run (time, start delay, deviation) include the preparation; ``prepared``: when it was
    checked and queued (the end of the preparation; None: not known)."""

    def __init__(self, traj: ValidTrajectory, kept: List[int], jobs: List[MoveJob], started: float,
                 prepared: Optional[float] = None) -> None:
        self.traj = traj
        self.kept = kept
        self.jobs = jobs
        self.started = started
        self.prepared = prepared

    @property
    def first_sent(self) -> Optional[float]:
        """The clock time the bus cycle that carried the first target ran (:attr:`MoveJob.left_at`);
        None while none did (or the run sends nothing)."""
        return self.jobs[0].left_at if self.jobs else None

    @property
    def done(self) -> bool:
        return all(job.done for job in self.jobs)

    @property
    def success(self) -> bool:
        return self.done and all(job.result is not None and job.result.success for job in self.jobs)

    def failure(self) -> Optional[MoveJob]:
        """The first job that ended without success (None: none so far)."""
        for job in self.jobs:
            if job.done and job.result is not None and not job.result.success:
                return job
        return None

    def points_done(self) -> int:
        """How many planned points have been reached (kept points passed, dropped ones between)."""
        if len(self.jobs) == 1 and self.jobs[0].points:          # a stream
            job = self.jobs[0]
            return job.points[job.points_done - 1].index if job.points_done else 0
        n = 0
        for job, index in zip(self.jobs, self.kept[1:]):
            if job.done and job.result is not None and job.result.success:
                n = index
        return n


class PlanningThread(OwnThread):
    """The driver's planning thread: runs posted tasks in order, off the bus thread. ``stop``: the
    driver's stop event (shared with the bus loop)."""

    thread_name = "vr_driver-planning"

    def __init__(self, stop: threading.Event) -> None:
        self._stop = stop
        self._tasks: Deque[Callable[[], None]] = collections.deque()
        self._cond = threading.Condition()

    def post(self, task: Callable[[], None]) -> None:
        with self._cond:
            self._tasks.append(task)
            self._cond.notify_all()

    def run_pending(self) -> int:
        """Run the tasks waiting now, in the caller's thread (stepped tests); returns how many ran."""
        n = 0
        while True:
            with self._cond:
                if not self._tasks:
                    return n
                task = self._tasks.popleft()
            task()
            n += 1

    def wake_to_stop(self) -> None:
        """Let the thread see the stop event (not safe from a signal handler: takes a lock)."""
        with self._cond:
            self._cond.notify_all()

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._cond:
                self._cond.wait_for(lambda: self._tasks or self._stop.is_set())
                if self._stop.is_set():
                    return
                task = self._tasks.popleft()
            try:
                task()
            except Exception:  # the planning thread must survive a planner bug
                log.exception("planning thread: unexpected error")


class JobControl:
    """The requests of one driver (module docstring). ``snapshot()``: what the bus side says now of
    motion and the arm's joints (:class:`~vr_driver.driver.motion.inbox.MotionSnapshot`); requests
    are posted to the sequencer's inbox, whose wake runs a bus cycle now (:attr:`wake`): nothing of
    the bus side runs in the caller's thread. ``streams``: the protocol's stream preparation (None: v1)."""

    def __init__(self, params: DriverParams, kinematics: Kinematics, clock: Callable[[], float],
                 sequencer: SequencerBase, checks: PathChecks, streams: Optional[JointStreams],
                 snapshot: Callable[[], MotionSnapshot]) -> None:
        self.params = params
        self.kin = kinematics
        self.clock = clock
        self.sequencer = sequencer
        self.inbox = sequencer.inbox
        self.checks = checks
        self.streams = streams
        self.snapshot = snapshot
        self.wake: Callable[[], None] = self.inbox.wake.set
        self._last_posted: Optional[MoveJob] = None

    @property
    def last_posted(self) -> Optional[MoveJob]:
        """The job posted last (a move, a trajectory, a joint_command stream), or None."""
        return self._last_posted

    @property
    def view(self) -> SequencerView:
        """The sequencer's queue and job in flight, as of its last step."""
        return self.sequencer.view

    # ------------------------------------------------------------------------ moves
    def preview(self, request: MoveRequest, start_joints: Optional[Sequence[float]] = None) -> Preview:
        """Validate and plan ``request`` from the current joints (or ``start_joints``); sends
        nothing (:meth:`PathChecks.preview`). Raises VrDriverError (PoseError, KinematicsError,
        MotionError, EnvelopeError, ProtocolError, CollisionError, DriverError) with the reason."""
        return self.checks.preview(request, self._current_joints() if start_joints is None else start_joints)

    def submit(self, request: MoveRequest, on_update: Optional[Callable[[MoveJob], None]] = None,
               mode: SubmitMode = SubmitMode.APPEND, ticket: Optional[int] = None) -> MoveJob:
        """Validate, preview and queue a move. Raises (and queues nothing) when it is invalid,
        unreachable, leaves the envelope, or the controller cannot move now. ``mode``: APPEND
        (behind the queue) or PREEMPT (stop the running move, drop the queue; ``ticket`` from
        :meth:`claim_ticket` keeps arrival order). A streaming protocol runs it as a stream of its
        previewed samples (:meth:`JointStreams.preview_stream`)."""
        self._require_motion_possible()
        preview = self.preview(request, self._planning_start(mode))
        if self.streams is not None:
            job = MoveJob(preview, on_update, ticket=ticket, points=self.streams.preview_stream(preview))
        else:
            job = MoveJob(preview, on_update, ticket=ticket)
        self._last_posted = job
        self.inbox.add([job], mode)
        self.wake()
        log.info("job %d queued (%s): %s %s", job.id, mode.value, request.move_type.name,
                 " then ".join(c.describe() for c in job.preview.commands))
        return job

    def submit_joint_path(self, names: Sequence[str], points: Sequence[Sequence[float]],
                          on_update: Optional[Callable[[MoveJob], None]] = None) -> List[MoveJob]:
        """Each joint point -> FK -> a PTP target, streamed in order. All points are validated
        and previewed first (in the caller's thread; the bus keeps cycling); if any is bad,
        nothing is queued and DriverError names the point. The new path replaces every queued
        target of an earlier one; the target in flight completes and the new path runs from its
        end. An empty ``points`` stops the motion."""
        if not points:
            self.stop_motion("empty joint path: stop requested")
            return []
        if self.streams is not None:
            raise DriverError("protocol %s runs a joint path with its timing: give each point a "
                              "time_from_start (see submit_trajectory); nothing was sent" % self.streams.wire.name)
        order = self._joint_order(names)
        self._require_motion_possible()
        previews = self._ptp_path(points, order, self._planning_start(SubmitMode.REPLACE),
                                  "joint path point {}".format)
        return self._post_path(previews, on_update)

    def _ptp_path(self, points: Sequence[Sequence[float]], order: Sequence[int], start: Sequence[float],
                  describe: Callable[[int], str]) -> List[Preview]:
        return ptp_path(self.kin, self.checks, points, order, start, describe)

    def _post_path(self, previews: Sequence[Preview], on_update: Optional[Callable[[MoveJob], None]]
                   ) -> List[MoveJob]:
        """Queue the previewed points of a joint path as one group, in place of the queued targets
        of an earlier one."""
        jobs = [MoveJob(p, on_update) for p in previews]
        for job in jobs[1:]:
            job.group = jobs[0].group
        self._last_posted = jobs[-1]
        self.inbox.add(jobs, SubmitMode.REPLACE)
        self.wake()
        log.info("joint path: %d PTP targets queued (jobs %d..%d)", len(jobs), jobs[0].id, jobs[-1].id)
        return jobs

    # ------------------------------------------------------------------------ trajectories
    def prepare_trajectory(self, traj: ValidTrajectory, start: Sequence[float]
                           ) -> Tuple[List[int], Tuple[StreamPoint, ...], List[Preview]]:
        """:func:`prepare_trajectory` with the driver's checks."""
        return prepare_trajectory(self.kin, self.checks, self.streams, traj, start)

    def submit_trajectory(self, traj: ValidTrajectory,
                          on_update: Optional[Callable[[MoveJob], None]] = None,
                          mode: SubmitMode = SubmitMode.REPLACE, started: Optional[float] = None) -> TrajectoryRun:
        """Run a validated planner trajectory: its samples and the chords between them checked
        against the cell (CollisionError, nothing queued), then what :meth:`prepare_trajectory`
        makes of it, queued.

        A streaming protocol: one streamed job (:func:`stream_points.stream_points`: thinned with its
        timing to ``stream_path_tolerance``, each segment's speed from its planned duration,
        blended through with ``stream_smooth``). ``mode`` as :meth:`submit` (REPLACE, the default:
        the points the controller already took complete, then this one).

        Protocol v1: thinned to the fewest stop points that keep the path within its path
        tolerance (:func:`trajectories.thin`), each kept point a PTP target of a joint path (it
        replaces the queued targets of an earlier path). The v1 program stops at every point and
        moves at its own speed: the result says how much slower than planned it ran. Raises
        DriverError (nothing queued) naming the point or segment refused.

        ``started``: the clock time of the plan's time 0 (the goal's arrival; default: now, when it
        is queued) -- the run's :attr:`TrajectoryRun.started`."""
        try:
            self.checks.check_collision_path(traj.positions, "trajectory", traj.times)
        except CollisionError as exc:
            raise CollisionError("%s; nothing was sent" % exc, exc.contacts, exc.sample, exc.time) from None
        if self.streams is None and len(traj.positions) < 2:   # only the start, where the arm is
            return self._run(traj, [0], [], started)
        self._require_motion_possible()
        start = traj.positions[0] if self.streams is not None else self._planning_start(SubmitMode.REPLACE)
        kept, points, previews = self.prepare_trajectory(traj, start)
        if previews:
            jobs = self._post_path(previews, on_update)
            log.info("trajectory: %d points planned over %.2f s, %d stop points after thinning",
                     len(traj.positions) - 1, traj.duration, len(previews))
            return self._run(traj, kept, jobs, started)
        if not points:                          # a stream that does not move
            return self._run(traj, kept, [], started)
        job = MoveJob(None, on_update, points=points, start=tuple(traj.positions[0]))
        self._last_posted = job
        self.inbox.add([job], mode)
        self.wake()
        log.info("trajectory: %d points planned over %.2f s streamed as %d targets (job %d)",
                 len(traj.positions) - 1, traj.duration, len(points), job.id)
        return self._run(traj, kept, [job], started)

    def _run(self, traj: ValidTrajectory, kept: List[int], jobs: List[MoveJob], started: Optional[float]
             ) -> TrajectoryRun:
        now = self.clock()
        return TrajectoryRun(traj, kept, jobs, now if started is None else min(started, now), now)

    # ------------------------------------------------------------------------ the queue
    def claim_ticket(self) -> int:
        """A ticket in arrival order for a goal that preempts (take it as the goal arrives, pass it
        to :meth:`submit`): of two goals, the one that arrived later wins, whichever is planned
        first; an older one submitted after a newer ticket was claimed is superseded."""
        return self.inbox.claim_ticket()

    def post_job(self, job: MoveJob) -> None:
        """Queue ``job`` (validated already) behind the others and run a bus cycle now."""
        self._last_posted = job
        self.inbox.add([job], SubmitMode.APPEND)
        self.wake()

    def extend_live(self, job: MoveJob, point: StreamPoint, anchored: StreamPoint,
                    anchor: Optional[Tuple[float, ...]], now: float) -> None:
        """Add ``point`` to the live stream ``job`` (``anchored``: the same point, validated and
        its speed worked out from ``anchor``, the last target on the wire as the view showed it);
        see :meth:`~vr_driver.driver.motion.inbox.Inbox.extend`."""
        self.inbox.extend(job, point, anchored, anchor, now)

    def cancel(self, job: MoveJob, reason: str = "cancelled") -> None:
        """Cancel one job: a queued one is dropped; the one in flight is stopped and ends when
        the arm is at rest."""
        self.inbox.cancel(job, reason)
        self.wake()

    def stop_motion(self, reason: str = "stop requested") -> int:
        """Drop the queue and stop the target in flight; returns the number of jobs it ends."""
        view = self.sequencer.view
        n = view.queue_length + (1 if view.job is not None and not view.settling else 0)
        self.inbox.stop_all(reason)
        self.wake()
        log.info("stop motion: %s (%d job(s) to end)", reason, n)
        return n

    def replan(self, job: MoveJob, joints: Tuple[float, ...]) -> None:
        """Plan ``job`` again from ``joints`` (the planning thread) and hand the sequencer the
        result, or why there is none."""
        try:
            if job.points:
                preview = self.streams.restream(job, joints)     # type: ignore[union-attr]
            else:
                preview = self.preview(job.preview.request, joints)
        except VrDriverError as exc:
            self.inbox.replanned(job, None, str(exc))
        else:
            self.inbox.replanned(job, preview)
        self.wake()

    # ------------------------------------------------------------------------ helpers
    def _require_motion_possible(self) -> None:
        snap = self.snapshot()
        if not snap.motion_possible:
            raise DriverError("motion is not possible: %s" % snap.why_not)

    def _current_joints(self) -> Tuple[float, ...]:
        snap = self.snapshot()
        if snap.joints is None or not snap.joints_valid:
            raise DriverError("no valid current joint state to plan from (%s)" % snap.link_words)
        return snap.joints

    def _planning_start(self, mode: SubmitMode) -> Tuple[float, ...]:
        """Where a new job will start: for APPEND the last queued job's target, for REPLACE the
        target in flight, else (and for PREEMPT) the arm's joints now. A guess when the arm moves
        meanwhile: the sequencer plans the job again if the arm is elsewhere when it is sent."""
        if mode is SubmitMode.APPEND:
            last = self._last_posted
            if last is not None and not last.done:
                return last.joint_target
            tail = self.sequencer.view.tail_joints
            if tail is not None:
                return tail
        elif mode is SubmitMode.REPLACE:
            inflight = self.sequencer.view.inflight_joints
            if inflight is not None:
                return inflight
        return self._current_joints()

    def _joint_order(self, names: Sequence[str]) -> List[int]:
        expected = list(self.params.controller_joint_names)
        names = list(names)
        if sorted(names) != sorted(expected) or len(names) != len(set(names)):
            raise DriverError("joint names %s do not match the controller's joints %s"
                              % (names, expected))
        return [expected.index(n) for n in names]


def prepare_trajectory(kin: Kinematics, checks: PathChecks, streams: Optional[JointStreams],
                       traj: ValidTrajectory, start: Sequence[float]
                       ) -> Tuple[List[int], Tuple[StreamPoint, ...], List[Preview]]:
    """What the driver sends for ``traj`` run from ``start``, checked, as (the planned points
    kept, the stream's points, the PTP previews): a streaming protocol's stream (its points:
    their configurations with a Cartesian protocol, and their segments; no previews); v1's PTP
    moves between the plan's thinned stop points (no stream points), each previewed as the
    controller runs it -- a straight joint move, against the box and the cell -- from the end of
    the one before. The driver's job control and the planning process's stream check
    (driver/planning/plan_process.py) share it. Sends nothing; raises DriverError naming the point or
    segment refused."""
    if streams is not None:
        points = streams.trajectory(traj.times, traj.positions)
        return [0] + [p.index for p in points if not p.hold], points, []      # (the hold: no planned point)
    kept = thin(traj)
    previews = ptp_path(kin, checks, [traj.positions[k] for k in kept[1:]], range(len(traj.positions[0])), start,
                        lambda n: "PTP %d to stop point %d of the plan" % (n + 1, kept[n + 1]))
    return kept, (), previews


def ptp_path(kin: Kinematics, checks: PathChecks, points: Sequence[Sequence[float]], order: Sequence[int],
             start: Sequence[float], describe: Callable[[int], str]) -> List[Preview]:
    """The PTP preview of each joint point (its values in the joint order ``order``: controller
    index of each) from the end of the one before (the first from ``start``); DriverError
    naming the point (``describe(index)``) when one is refused."""
    previews = []
    for index, point in enumerate(points):
        try:
            if len(point) != len(order):
                raise DriverError("has %d positions for %d joint names" % (len(point), len(order)))
            q = [0.0] * len(order)
            for src, dst in enumerate(order):
                q[dst] = float(point[src])
            q = kin.check_limits(kin.joint_vector(q))
            request = MoveRequest(MoveType.PTP, kin.fk_pose(q), label="joint path point %d" % index)
            preview = checks.preview(request, start)
        except (VrDriverError, TypeError, ValueError) as exc:
            raise DriverError("%s: %s; nothing was sent" % (describe(index), exc)) from None
        previews.append(preview)
        start = preview.joint_target
        hand_over()     # the bus thread must not wait on a long validation
    return previews
