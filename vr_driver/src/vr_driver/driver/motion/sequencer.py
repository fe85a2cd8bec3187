"""The motion sequencers: the job queue, exactly-once sending, stops and outcomes, stepped by the
bus loop. ROS-free, no I/O, no planning.

:class:`SequencerBase` is what every protocol shares; a protocol's sequencer implements its small
public hook interface, :class:`SequencerHooks` (``follow``, ``advance``, ``record``, ``idle_command``,
``stop_job``, ``stop_untracked``, ``replaced``, ``apply_replan``, ``on_lost``, ``resting``,
``end_due``): :class:`~vr_driver.driver.motion.handshake.HandshakeSequencer` (v1: one target at a time
through the handshake) and :class:`~vr_driver.driver.motion.streaming.StreamSequencer` (the streaming
protocols), each in a module of its own: this one knows no protocol's records. The driver core
runs the one the protocol object names (:meth:`vr_driver.protocol.base.Protocol.sequencer`, registered
by :mod:`vr_driver.driver.sequencers`).

:meth:`SequencerBase.step` is called once per bus iteration with the link's
:class:`~vr_driver.driver.link.link.LinkSample` and the arm's current joints; it returns the command to
send next. Other threads never touch its state: they post requests to its inbox
(:attr:`SequencerBase.inbox`: :meth:`~vr_driver.driver.motion.inbox.Inbox.add`,
:meth:`~vr_driver.driver.motion.inbox.Inbox.cancel`, :meth:`~vr_driver.driver.motion.inbox.Inbox.stop_all`),
which the next step takes in the order they were posted (:mod:`vr_driver.driver.motion.inbox`).
Planning never runs here: a job whose planned start no longer matches the arm is handed to
``replan(job, joints)`` (the driver core runs it on its planning thread) and waits in REPLANNING
until the inbox's :meth:`~vr_driver.driver.motion.inbox.Inbox.replanned` brings the new plan back.

Rules (README "Reliability", doc/README.md):

- **exactly once**: a target is sent only through the protocol's own rule (v1:
  :class:`~vr_driver.protocol.v1.MasterHandshake`; a stream: its sequence numbers) and never again; a job that fails, is stopped or loses the link is never re-sent;
- **truth at the end**: a job that is stopped (cancel, stop_motion, preempted), rejected while the
  arm moved, or timed out ends only when the controller reports the arm at rest -- the in-motion
  bit clear and the reported pose unchanged for ``stop_settle_time`` -- and its result carries that
  pose; nothing new is sent before that (:mod:`vr_driver.driver.motion.settling`);
- **order**: requests take effect in the order they were posted; a PREEMPT job whose ticket is
  older than the newest ticket claimed (:meth:`~vr_driver.driver.motion.inbox.Inbox.claim_ticket`)
  is superseded, never run; a PREEMPT job stops the move in flight and drops the queue; a REPLACE
  job (a new joint path) drops every queued target, lets the one in flight complete, and runs from
  its end;
- **link loss**: everything in flight or queued fails with the reason (the last pose seen is
  reported; where the arm came to rest is unknown to the driver then).
"""
from __future__ import annotations

import collections
import logging
from dataclasses import dataclass
from typing import Any, Callable, Deque, List, Optional, Sequence, Tuple

from ...params import DriverParams
from ...poses import ControllerPose
from ...protocol.common import FeedbackRecord, StatusBits
from .inbox import AddJobs, CancelJobs, ExtendJob, Inbox, Request
from .jobs import JobPhase, MoveJob, SubmitMode
from ..link.link import LinkSample
from .settling import Settle, Settling

log = logging.getLogger("vr_driver.driver")

__all__ = ["SequencerBase", "SequencerHooks", "SequencerView", "START_TOLERANCE",
           "SESSION_RECORDS_BEFORE_REQUEST", "why_no_motion"]

# a queued job whose planned start differs from the current joints by more than this [rad] is
# planned again before it is sent (whole-mm / whole-degree feedback alone stays well below it)
START_TOLERANCE = 0.02

# the first request of a Data_Exchange session waits for this many replies in the session: the
# controller then got our record with the flag at 0 in as many telegrams, which arms it (it must
# see the flag at 0 after a link loss; the virtual controller, like a careful G2 program, acts on
# a v1 record only once it arrived unchanged in two consecutive telegrams; the streaming protocols keep the same margin)
SESSION_RECORDS_BEFORE_REQUEST = 2


def why_no_motion(fb: FeedbackRecord) -> str:
    """What in the controller's status bits forbids motion ("" when nothing does)."""
    bits = fb.status
    reasons = []
    if bits & StatusBits.ESTOP:
        reasons.append("the emergency stop is active")
    if bits & StatusBits.ERROR:
        reasons.append("the controller reports an error")
    if not bits & StatusBits.DRIVES_POWERED:
        reasons.append("the drives are off")
    if not bits & StatusBits.PROGRAM_RUNNING:
        reasons.append("the controller program is not running (manual mode)")
    return "; ".join(reasons)


@dataclass(frozen=True)
class SequencerView:
    """What other threads may read of the sequencer (replaced whole after every step)."""

    job: Optional[MoveJob]                        # the job being sent / executed / stopped
    queue_length: int
    tail_joints: Optional[Tuple[float, ...]]      # where a job queued now would start (None: the arm)
    inflight_joints: Optional[Tuple[float, ...]]  # the target of the job in flight (None: none)
    settling: bool                                # waiting for the arm to come to rest
    targets_sent: int = 0
    targets_done: int = 0
    targets_rejected: int = 0
    targets_aborted: int = 0
    live_anchor: Optional[Tuple[float, ...]] = None  # a live job: its last point put on the wire
    #                                              (None: none yet, the job's start is the anchor)




class SequencerHooks:
    """What a protocol's sequencer implements, and nothing else: :class:`SequencerBase` calls
    these hooks from its :meth:`~SequencerBase.step` (a protocol's sequencer may call the base's
    helpers: :meth:`~SequencerBase.next_job`, :meth:`~SequencerBase.starts_here`,
    :meth:`~SequencerBase.begin_settle`, :meth:`~SequencerBase.fail_queue`,
    :meth:`~SequencerBase.end_all`):

    - :meth:`follow` reads the controller's progress from a feedback record and ends jobs;
    - :meth:`advance` sends (or starts) what is next when everything allows it;
    - :meth:`record` / :meth:`idle_command`: the command to send (with / without feedback);
    - :meth:`stop_job` / :meth:`stop_untracked`: stop the job in flight / a motion of no job;
    - :meth:`replaced`: a REPLACE request arrived while ``job`` runs;
    - :meth:`apply_replan`: put a new plan (from ``replan``) into a job;
    - :meth:`on_lost`: the link was lost (the base then ends every job);
    - :meth:`resting` (the protocol's own "at rest" condition) and :meth:`end_due`;
    - a streaming protocol's: :meth:`take_point` (a live job's new command) and
      :meth:`live_anchor`.
    """

    def follow(self, now: float, fb: Any, sample: LinkSample) -> None:
        """Read the controller's progress in ``fb`` (this session's latest record; ``sample.fresh``
        is set when it arrived in this cycle); end the jobs it ends."""
        raise NotImplementedError

    def advance(self, now: float, fb: Any, sample: LinkSample, joints: Optional[Tuple[float, ...]]) -> None:
        """Send or start what is next, when nothing forbids it (a job settling, the controller not
        armed, a job being planned again...)."""
        raise NotImplementedError

    def record(self, now: float) -> Any:
        """The command to send in this cycle."""
        raise NotImplementedError

    def idle_command(self, now: float) -> Any:
        """The command to send while there is no feedback of this session (link down, new session)."""
        raise NotImplementedError

    def stop_job(self, job: MoveJob, reason: str, now: float) -> None:
        """Stop the job in flight (it is no longer the current job when this is called): stop the
        arm and :meth:`~SequencerBase.begin_settle`, or end the job at once when nothing of it was
        sent."""
        raise NotImplementedError

    def stop_untracked(self, reason: str, now: float) -> None:
        """No job in flight, but a motion may still run (after a timeout, an earlier stream's end):
        stop it."""
        raise NotImplementedError

    def replaced(self, job: MoveJob) -> None:
        """A REPLACE request (a new joint path) arrived while ``job`` runs and was sent."""

    def apply_replan(self, job: MoveJob, plan: Any) -> None:
        """Put a new plan into ``job`` (what ``replan`` produced from the arm's joints)."""
        raise NotImplementedError

    def on_lost(self, now: float, reason: str) -> None:
        """The link was lost or a new session began: forget what was in flight on the wire (the
        base then ends every job with the reason)."""
        raise NotImplementedError

    def take_point(self, job: MoveJob, point: Any, anchored: Any, anchor: Optional[Tuple[float, ...]],
                   stamp: float) -> None:
        """A new command of a live job (:meth:`~vr_driver.driver.motion.inbox.Inbox.extend`). Only a
        streaming protocol's sequencer takes one (the driver core refuses joint commands on the others)."""
        raise NotImplementedError("this protocol does not stream joint commands")

    def resting(self, fb: Any) -> bool:
        """The protocol's own condition for the arm at rest, besides the in-motion bit clear and
        the pose unchanged for ``stop_settle_time``."""
        return True

    def end_due(self, now: float) -> bool:
        """True while the current motion's end is due and worth polling for."""
        return False

    def live_anchor(self) -> Optional[Tuple[float, ...]]:
        """The last point of the live job in flight put on the wire (None: none)."""
        return None


class SequencerBase(SequencerHooks):
    """What every protocol's sequencer shares (see the module docstring): the requests posted by
    other threads (:class:`~vr_driver.driver.motion.inbox.Inbox`), tickets, the queue, the job in flight,
    waiting for rest (:class:`~vr_driver.driver.motion.settling.Settling`), outcomes, the link session and
    the view. A protocol's sequencer implements the hooks of :class:`SequencerHooks`."""

    def __init__(self, params: DriverParams, clock: Callable[[], float],
                 replan: Callable[[MoveJob, Tuple[float, ...]], None]) -> None:
        self.params = params
        self.wire = params.wire                   # the protocol object (the string: params.protocol)
        self.clock = clock
        self.replan = replan
        # the only state other threads touch: they post there (Inbox.add ...), read the bus side's
        # MotionSnapshot there and wake the bus thread with its Wake
        self.inbox = Inbox()
        self._queue: Deque[MoveJob] = collections.deque()
        self._job: Optional[MoveJob] = None
        self._settling = Settling(params)         # the stopped job waiting for rest (_settle)
        self._session: Optional[int] = None       # the link session our handshake belongs to
        self._last_pose: Optional[ControllerPose] = None
        self.targets_sent = self.targets_done = self.targets_rejected = self.targets_aborted = 0
        self.view = SequencerView(None, 0, None, None, False)

    # ------------------------------------------------------------------ bus thread
    def step(self, now: float, sample: LinkSample, joints: Optional[Tuple[float, ...]]) -> Any:
        """One bus iteration: take the requests, follow the controller, end jobs, send the next
        target when everything allows it. Returns the command to send."""
        watched = self._unended()
        try:
            return self._step(now, sample, joints)
        finally:
            for job in watched:
                if job.done and job.ended_at is None:
                    job.ended_at = now
            job = self._job
            if job is not None and job.sent_at == now and job.sent_serial is None \
                    and sample.outputs_serial is not None:
                job.sent_serial = sample.outputs_serial + 1      # the serial this step's record gets

    def _unended(self) -> List[MoveJob]:
        """The jobs this step may end (in flight, waiting for rest, queued): each gets
        :attr:`MoveJob.ended_at` = the step's time when it does (a status taken at or after it shows
        the arm after the job)."""
        out = list(self._queue)
        if self._job is not None:
            out.append(self._job)
        settle = self._settle
        if settle is not None and settle.job is not None:
            out.append(settle.job)
        return out

    def _step(self, now: float, sample: LinkSample, joints: Optional[Tuple[float, ...]]) -> Any:
        fb = self._begin_step(now, sample)
        if fb is None:
            command = self.idle_command(now)
            self._publish()
            return command
        self._note_carried(sample)
        self._settling.track(now, fb)
        self.follow(now, fb, sample)
        self._settling.check(now, fb, self.resting)
        self.advance(now, fb, sample, joints)
        self.before_record(sample)
        command = self.record(now)
        self._publish()                 # after the record: the view's live_anchor is what it put on the wire
        return command

    def _note_carried(self, sample: LinkSample) -> None:
        """The job in flight's first target went out with this bus cycle (:attr:`MoveJob.left_at`):
        the first cycle that carried the record that first offered it (a bus process's serials: the
        record set last may be a newer one) or a later one, dated when the
        driver learnt that it ran (its end: an upper bound of when the target left; the record's own
        stamp dates the controller's reply, which it may have written before it read the target)."""
        job = self._job
        if job is None or job.sent_at is None or job.left_at is not None or not sample.cycled:
            return
        if job.sent_serial is not None and sample.carried_serial is not None:
            carried = sample.carried_serial >= job.sent_serial    # that record, or a later one offering it again
        else:
            carried = sample.carried
        if carried:
            job.left_at = sample.time

    def before_record(self, sample: LinkSample) -> None:
        """Hook before :meth:`record`: ``sample`` says whether this step follows a bus cycle and
        whether that cycle carried the record set last (a streaming sequencer forgets a record that
        a woken step made and the next one replaces before any telegram carried it)."""

    def _begin_step(self, now: float, sample: LinkSample) -> Optional[Any]:
        """The start of every step (every sequencer): take the posted requests; on a lost link or a new
        Data_Exchange session end everything in flight (:meth:`_lost`). Returns the feedback to act
        on, or None when there is none of this session."""
        fb = sample.feedback
        if fb is not None:
            self._last_pose = fb.pose
        for request in self.inbox.take():
            self._take(request, now, fb)
        if not sample.connected or (self._session is not None and sample.session != self._session):
            if self._session is not None:
                self._lost(now, sample.reason if not sample.connected else "a new Data_Exchange session")
            if sample.connected:
                self._session = sample.session
            return None
        self._session = sample.session
        assert fb is not None
        return fb

    def shutdown(self, reason: str) -> None:
        """End every job (after the bus loop stopped): queued, in flight, posted but not taken."""
        posted = [job for request in self.inbox.take() if isinstance(request, AddJobs)
                  for job in request.jobs]
        self.end_all(JobPhase.CANCELLED, reason, posted)
        self._publish()

    # ------------------------------------------------------------------ requests
    def _take(self, request: Request, now: float, fb: Optional[FeedbackRecord]) -> None:
        if isinstance(request, AddJobs):
            self._take_add(request, now)
        elif isinstance(request, ExtendJob):
            self.take_point(request.job, request.point, request.anchored, request.anchor, request.stamp)
        elif isinstance(request, CancelJobs):
            if request.job is None:
                self._stop_everything(request.reason, now)
            else:
                self._cancel(request.job, request.reason, now)
        else:
            job = request.job
            if job is not self._job or job.done or job.phase is not JobPhase.REPLANNING:
                return                                   # cancelled meanwhile
            if request.preview is None:
                self._job = None
                log.warning("job %d not sent: the arm is not where it was planned from, and from "
                            "here: %s", job.id, request.error)
                job.finish(False, JobPhase.FAILED, "not sent: from the arm's current pose: %s"
                           % request.error, None)
                self.fail_queue("an earlier target of the same path failed (%s)" % request.error,
                                 job.group)
            else:
                self.apply_replan(job, request.preview)
                log.info("job %d planned again from the arm's current pose (%.1f s)", job.id,
                         job.duration)
                job.set_phase(JobPhase.QUEUED)

    def _take_add(self, request: AddJobs, now: float) -> None:
        jobs = [j for j in request.jobs if not j.done]
        if not jobs:
            return
        if request.mode is SubmitMode.PREEMPT:
            ticket = jobs[0].ticket
            if self.inbox.superseded(ticket):
                for job in jobs:
                    job.finish(False, JobPhase.CANCELLED, "superseded by a newer goal (received "
                               "later, it takes precedence); nothing was sent for this one", None)
                log.info("job %d superseded by a newer goal", jobs[0].id)
                return
            self.inbox.preempts(ticket)
            self._stop_everything("preempted by a newer goal", now)
        elif request.mode is SubmitMode.REPLACE:
            dropped = len(self._queue)
            for queued in list(self._queue):
                queued.finish(False, JobPhase.CANCELLED, "replaced by a newer joint path", None)
            self._queue.clear()
            if self._job is not None and not self._job.sent:     # not started: replaced as well
                job, self._job = self._job, None
                job.finish(False, JobPhase.CANCELLED, "replaced by a newer joint path", None)
                dropped += 1
            if dropped:
                log.info("joint path: %d queued target(s) of the previous path dropped", dropped)
            if self._job is not None and self._job.sent:
                self.replaced(self._job)
        self._queue.extend(jobs)

    def _cancel(self, job: MoveJob, reason: str, now: float) -> None:
        if job.done:
            return
        if job in self._queue:
            self._queue.remove(job)
            job.finish(False, JobPhase.CANCELLED, reason, None)
            return
        if job is self._job:
            self._stop_current(reason, now)
        elif self._settle is not None and self._settle.job is job:
            self._settle.phase, self._settle.reason = JobPhase.CANCELLED, reason
        # else: not posted yet (its AddJobs is behind this request) or already finished

    def _stop_everything(self, reason: str, now: float) -> None:
        for queued in list(self._queue):
            queued.finish(False, JobPhase.CANCELLED, reason, None)
        self._queue.clear()
        if self._job is not None:
            self._stop_current(reason, now)
        else:
            self.stop_untracked(reason, now)

    def _stop_current(self, reason: str, now: float) -> None:
        job = self._job
        assert job is not None
        self._job = None
        job.stop_reason = reason
        self.stop_job(job, reason, now)

    # ------------------------------------------------------------------ at rest
    @property
    def _settle(self) -> Optional[Settle]:
        """The stopped job waiting for the arm to come to rest (None: none; set by
        :meth:`begin_settle`, by a protocol's sequencer for a motion of no job)."""
        return self._settling.pending

    @_settle.setter
    def _settle(self, settle: Optional[Settle]) -> None:
        self._settling.pending = settle

    def begin_settle(self, job: MoveJob, phase: JobPhase, reason: str, now: float) -> None:
        """``job`` was stopped: it ends with ``phase`` and ``reason`` when the arm is at rest
        (:class:`~vr_driver.driver.motion.settling.Settling`)."""
        self._settling.begin(job, phase, reason, now)

    # ------------------------------------------------------------------ helpers
    def next_job(self, fb: Any) -> Optional[MoveJob]:
        """The job in flight, else the next queued one (None: none; the queue fails when motion is
        no longer possible)."""
        if self._job is None:
            if not self._queue:
                return None
            why = why_no_motion(fb)
            if why:
                self.fail_queue("motion is no longer possible: %s" % why)
                return None
            self._job = self._queue.popleft()
        return self._job

    def starts_here(self, job: MoveJob, joints: Optional[Tuple[float, ...]]) -> bool:
        """True when ``job`` may be sent from ``joints``. Otherwise it failed (no valid joint state
        to check its planned start against; the rest of its path fails too) or is being planned
        again from ``joints`` (the arm is not where it was planned to start)."""
        if joints is None:
            self._job = None
            job.finish(False, JobPhase.FAILED, "not sent: no valid joint state to check the planned "
                       "start against", None)
            self.fail_queue("an earlier target of the same path failed", job.group)
            return False
        if job.start is not None and max(abs(a - b) for a, b in zip(joints, job.start)) > START_TOLERANCE:
            job.set_phase(JobPhase.REPLANNING)
            self.replan(job, joints)
            return False
        return True

    def fail_queue(self, reason: str, group: Optional[int] = None) -> None:
        """End the queued jobs (of one group only, when given) with ``reason``."""
        for queued in list(self._queue):
            if group is None or queued.group == group:
                queued.finish(False, JobPhase.FAILED, reason, None)
                self._queue.remove(queued)

    def _lost(self, now: float, reason: str) -> None:
        self.on_lost(now, reason)
        self._session = None
        self._settling.forget()
        self.end_all(JobPhase.FAILED, "link to the controller lost (%s); what was sent is not re-sent; "
                     "the last pose seen is reported, where the arm came to rest is unknown" % reason)

    def end_all(self, phase: JobPhase, reason: str, extra: Sequence[MoveJob] = ()) -> None:
        """End every job: settling, in flight, queued (and ``extra``); a job that was sent
        reports the last pose seen."""
        jobs: List[MoveJob] = list(extra)
        if self._settle is not None and self._settle.job is not None:
            jobs.append(self._settle.job)
        if self._job is not None:
            jobs.append(self._job)
        jobs.extend(self._queue)
        self._settle, self._job = None, None
        self._queue.clear()
        for job in jobs:
            job.finish(False, phase, reason, self._last_pose if job.sent else None)

    def _publish(self) -> None:
        job = self._job
        tail = None
        if self._queue:
            tail = self._queue[-1].joint_target
        elif job is not None:
            tail = job.joint_target
        settle_job = self._settle.job if self._settle is not None else None
        self.view = SequencerView(
            job=job if job is not None else settle_job, queue_length=len(self._queue),
            tail_joints=tail, inflight_joints=job.joint_target if job is not None else None,
            settling=self._settle is not None, targets_sent=self.targets_sent,
            targets_done=self.targets_done, targets_rejected=self.targets_rejected,
            targets_aborted=self.targets_aborted, live_anchor=self.live_anchor())
