"""The stream job's life on the wire (ROS-free, no I/O, no planning on the bus thread):
:class:`StreamSequencer` hands a stream's points (made from a plan by :mod:`.stream_points`, made
ready for the protocol by its stream family, :mod:`.stream_prep`) to the controller with a
look-ahead, exactly once, through the protocol object's ``stream_command`` (v2 joint targets, v3
Cartesian ones).

**On the wire** (:class:`StreamSequencer`, one step per bus cycle; doc/controller_program.md §9):
the job's points get consecutive sequence numbers from the one after the controller's
``accepted_seq``; the record offers the first point the controller has not taken in slot 0 (with
START for the stream's first point) and the one after it in slot 1. The controller takes a slot when
it has room (the target it moves to and one look-ahead) and reports ``accepted_seq``; the record
then moves on. A number the controller took is never offered again, and after a link loss nothing
of the stream is re-sent: the job fails with the reason.

- done: every point reached (``done_seq`` = the last, the arm at rest) -> SUCCEEDED at that pose;
- a point refused (``rejected_seq`` one of ours): STOP, the job FAILED when the arm is at rest;
- cancel / stop / preempt / timeout: STOP (the controller brakes along its path and drops what it
  took but did not start), the job ends when the arm is at rest, with that pose;
- a new joint path (REPLACE): the points the controller already took complete, the rest of the old
  stream is not offered any more; the new one starts from where the old one ended;
- the arm not where the stream was planned from (after a stop): the first segment is planned
  again from the arm's joints (on the core's planning thread) before anything is sent.

**A live stream** (``MoveJob.live``: the ``joint_command`` topic, :meth:`DriverCore.joint_command`):
the same job, whose points grow while commands come (:meth:`StreamSequencer.take_point`, posted
through :meth:`~vr_driver.driver.motion.inbox.Inbox.extend`). A new point replaces the job's
last point when that one was not put on the wire yet and the point the replacement was checked from
is still the last on the wire (at most one point is ever waiting: the newest command wins; a point
on the wire is never changed or recalled -- the controller may have taken it); else it is appended
with the next sequence number. Every point passes through (smooth level
``stream_smooth``): the controller blends into the next one only when it already has it, and
otherwise stops exactly at the point (state WAITING) -- it never runs past the last command. When no
command came for ``joint_command_timeout`` the job is closed: it takes no more points and ends
(SUCCEEDED) once the arm is at rest at its last point. A gap (WAITING between commands) is normal
here and not counted. A trajectory (REPLACE) closes it like any running stream; a move, a cancel or
stop_motion stops it (STOP, at rest).
"""
from __future__ import annotations

import logging
import math
from typing import Any, Callable, Optional, Tuple

from ...params import DriverParams
from ...protocol.base import WireTarget
from ...protocol.common import SEQ_MAX, StatusBits, StreamState, next_seq, seq_offset
from .jobs import JobPhase, MoveJob, StreamPoint
from ..link.link import LinkSample
from .sequencer import SESSION_RECORDS_BEFORE_REQUEST, START_TOLERANCE, SequencerBase
from .settling import Settle

log = logging.getLogger("vr_driver.driver")

__all__ = ["StreamSequencer", "wire_speed", "seq_offset"]

#: s: a stream's end is watched (:meth:`StreamSequencer.end_due`) from this long before its planned
#: end until END_WATCH after it
END_LEAD = 0.02
END_WATCH = 0.5


def wire_speed(speed: int, speed_scale: float) -> int:
    """The speed number to send for a target planned at ``speed`` (0.1 % of the joint speed limits)
    to a G2 whose MOVEP runs ``speed_scale`` times the commanded speed (its speed unit, measured by
    the commissioning: ``controller/speed_scale``): ``speed / speed_scale`` rounded up (never slower
    than planned), 1..1000 -- where the arm cannot go that fast, 1000 (slower than planned: the
    planner must have had the scaled velocity limits). ``speed_scale`` 1: ``speed`` itself."""
    if speed_scale == 1.0:
        return speed
    return min(1000, max(1, int(math.ceil(speed / speed_scale - 1e-9))))




class StreamSequencer(SequencerBase):
    """The sequencer of a streaming protocol (v2, v3; same requests, queue, tickets, settle and outcome
    rules as every sequencer, :class:`~vr_driver.driver.motion.sequencer.SequencerBase`; see the module
    docstring for the stream). :meth:`step` returns the protocol's command, built by
    ``params.wire.stream_command`` from the job's points."""

    def __init__(self, params: DriverParams, clock: Callable[[], float],
                 replan: Callable[[MoveJob, Tuple[float, ...]], None]) -> None:
        super().__init__(params, clock, replan)
        self._base = 0                     # sequence number of the current job's point 0 (0: not started)
        self._limit = 0                    # points of the current job still offered up to (REPLACE cuts it)
        self._rejected_before = 0          # the controller's rejected_seq when the job started
        self._started = 0.0
        self._stopping = False             # send STOP until the arm is at rest
        self._offered: Optional[int] = None   # the last point of the current job put on the wire
        self._high = -1                       # the highest point of the current job ever put on it
        self._acked = -1                      # points_taken at the last record
        self._ahead = True                    # send ahead of the acknowledgements (send_ahead)
        self._woken: Optional[Tuple[Any, ...]] = None   # what was offered before a woken step's record
        self._last_state: Optional[StreamState] = None
        self._unarmed_since: Optional[float] = None   # the controller reported "not armed" since
        # the controller's general-purpose outputs 1..16 (§9.5), sent in every record; back to 0 (their
        # safe state, as the controller sets them) when the link is lost, until set again
        self.outputs = 0

    # ------------------------------------------------------------------ hooks
    def idle_command(self, now: float) -> Any:
        return self.wire.idle_command()

    def end_due(self, now: float) -> bool:
        """Every target of the running stream taken and its planned end near (from END_LEAD before
        it to END_WATCH after it): the arm's arrival is due, the core polls for it faster."""
        job = self._job
        if job is None or not self._base or self._stopping or job.points_taken < self._limit:
            return False
        if job.live:                 # a live stream ends when closed and the arm reached its end
            return job.closed and now - job.last_command <= \
                self.params.joint_command_timeout + END_WATCH
        end = self._started + job.duration
        return end - END_LEAD <= now <= end + END_WATCH

    def resting(self, fb: Any) -> bool:
        return fb.state in (StreamState.IDLE, StreamState.WAITING)

    def apply_replan(self, job: MoveJob, plan: Any) -> None:
        job.points, job.start = plan

    def live_anchor(self) -> Optional[Tuple[float, ...]]:
        job = self._job
        if job is None or not job.live or not self._base or self._high < 0:
            return None
        return job.points[self._high].joints

    def take_point(self, job: MoveJob, point: StreamPoint, anchored: StreamPoint,
                   anchor: Optional[Tuple[float, ...]], stamp: float) -> None:
        """A new command of the live job ``job`` (module docstring): it replaces the job's last point
        when that one is not on the wire yet and ``anchor`` (what ``anchored`` was validated from
        and timed from) is still the last point that is; else it is appended (``point``: validated
        from the last accepted command, which is the job's last point). The commander reads the
        view before this step: when points went on the wire since (two commands in one step, a
        bus stall), the anchor is an older point, and a replacement would run a segment nobody
        checked at a speed worked out for another (at a turning point, the wire's slowest)."""
        if job.done or job.closed:
            log.warning("job %d: a joint command arrived as its stream ended (%s); dropped -- the next "
                        "one starts a new stream", job.id, job.phase.value)
            return
        job.last_command = stamp
        started = job is self._job and bool(self._base)
        high = self._high if started else -1
        on_wire = job.points[high].joints if high >= 0 else job.start
        if len(job.points) - 1 > high and anchor is not None and tuple(anchor) == tuple(on_wire):
            job.points = job.points[:-1] + (anchored,)
            job.replaced += 1
        else:
            job.points = job.points + (point,)
            if started:
                job.seqs.append(self._seq(len(job.points) - 1))
        if started:
            self._limit = len(job.points)

    def replaced(self, job: MoveJob) -> None:
        if job.live:
            job.closed = True
        if not self._stopping:
            # the points the controller took run to their end; the rest of the old stream is dropped
            self._limit = min(self._limit, max(job.points_taken, 1))
            job.stop_reason = "replaced by a newer joint path"
            log.info("job %d: replaced by a newer joint path after %d of its %d points", job.id,
                     self._limit, len(job.points))

    def stop_untracked(self, reason: str, now: float) -> None:
        if self._last_state in (StreamState.MOVING, StreamState.STOPPING):
            self._stopping = True                 # not ours (an earlier stream's end): stop it too
            if self._settle is None:
                self._settle = Settle(None, JobPhase.CANCELLED, reason, now)

    def stop_job(self, job: MoveJob, reason: str, now: float) -> None:
        self._end_current()
        job.closed = True                     # a live stream takes no more points
        if job.sent:
            self._stopping = True
            if job.points_taken > job.points_done:
                self.targets_aborted += 1
            log.info("job %d: STOP sent (%s); waiting for the arm to come to rest", job.id, reason)
            self.begin_settle(job, JobPhase.CANCELLED, reason, now)
        else:
            job.finish(False, JobPhase.CANCELLED, reason, None)

    # ------------------------------------------------------------------ the stream
    def follow(self, now: float, fb: Any, sample: LinkSample) -> None:
        """Read the controller's progress on the current job; end it when it is over."""
        was = self._last_state
        self._last_state = fb.state
        job = self._job
        if job is None or not self._base:
            return
        n = len(job.points)
        taken = seq_offset(fb.accepted_seq, self._base) + 1 if fb.accepted_seq else 0
        taken = taken if taken <= n else 0
        done = seq_offset(fb.done_seq, self._base) + 1 if fb.done_seq else 0
        done = done if done <= n else 0
        if job.live and not job.closed and now - job.last_command > self.params.joint_command_timeout:
            job.closed = True
            log.info("job %d: no joint command for %.3g s (joint_command_timeout): the stream ends at "
                     "its last point (%d points, %d replaced before they were sent)", job.id,
                     self.params.joint_command_timeout, n, job.replaced)
        if fb.state is StreamState.WAITING and was is not StreamState.WAITING and 0 < done < n \
                and not self._stopping and not job.live:
            job.gaps += 1
            log.warning("job %d: the arm stopped at point %d of %d waiting for the next target (the "
                        "look-ahead ran dry: the bus did not bring it in time)", job.id, done, n)
        if taken > job.points_taken:
            self.targets_sent += taken - job.points_taken
            job.points_taken = taken
            if job.phase is JobPhase.SENDING:
                job.set_phase(JobPhase.MOVING)
        if done > job.points_done:
            self.targets_done += done - job.points_done
            job.points_done = done
            job._notify()
        if fb.rejected_seq and fb.rejected_seq != self._rejected_before \
                and seq_offset(fb.rejected_seq, self._base) < n:
            k = seq_offset(fb.rejected_seq, self._base)
            self.targets_rejected += 1
            reason = ("the controller refused point %d of %d (target #%d): %s" % (
                k + 1, n, fb.rejected_seq, fb.reject_code.name))
            self._fail_current(job, reason, now, fb)
            return
        resting = fb.state in (StreamState.IDLE, StreamState.WAITING) and \
            not fb.status & StatusBits.IN_MOTION
        if done >= n and resting and (job.closed or not job.live):
            self._end_current()
            log.info("job %d done: %d points, at %s", job.id, n, fb.describe())
            job.finish(True, JobPhase.SUCCEEDED, "", fb.pose)
            return
        if self._limit < n and done >= max(job.points_taken, 1) and resting:
            self._end_current()
            job.finish(False, JobPhase.CANCELLED, "%s after %d of its %d points" % (
                job.stop_reason or "replaced", done, n), fb.pose)
            return
        if taken == 0 and now - self._started > self.params.accept_timeout:
            self._fail_current(job, "the controller did not take the stream's first target within "
                               "%.3g s (accept_timeout; %s)" % (self.params.accept_timeout,
                                                                fb.describe()), now, fb)
            return
        if job.live:
            # a live stream lasts as long as commands come; once closed, its last segment lasts at
            # most joint_command_timeout (DriverCore.joint_command's speed check)
            limit = self.params.joint_command_timeout + self.params.motion_timeout_margin
            if job.closed and now - job.last_command > limit:
                self._fail_current(job, "the arm did not come to rest at the stream's last point "
                                   "within %.3g s of the last joint command (joint_command_timeout "
                                   "+ motion_timeout_margin)" % limit, now, fb)
            return
        timeout = self.params.motion_timeout_factor * job.duration + self.params.motion_timeout_margin
        if now - self._started > timeout:
            self._fail_current(job, "the stream did not end within %.3g s (motion timeout: %g x the "
                               "planned %.3g s + %g s)" % (timeout, self.params.motion_timeout_factor,
                                                           job.duration, self.params.motion_timeout_margin),
                               now, fb)

    def _end_current(self) -> None:
        self._job = None
        self._woken = None
        self._base = 0
        self._limit = 0
        self._high = -1

    def _fail_current(self, job: MoveJob, reason: str, now: float, fb: Any) -> None:
        log.warning("job %d ended: %s", job.id, reason)
        self._end_current()
        self._stopping = True
        self.begin_settle(job, JobPhase.FAILED, reason, now)
        self.fail_queue("an earlier target of the same path failed (%s)" % reason, job.group)

    def advance(self, now: float, fb: Any, sample: LinkSample, joints: Optional[Tuple[float, ...]]) -> None:
        """Start the next job when nothing runs and the arm is at rest."""
        if self._settle is None:
            self._stopping = False
        if self._settle is not None or self._stopping:
            return
        if sample.session_records < SESSION_RECORDS_BEFORE_REQUEST:
            return          # the controller has not surely seen our empty record (it arms on it) yet
        if fb.armed:
            self._unarmed_since = None
        else:
            # it arms on our empty record; a stream sent before would be refused (NOT_ARMED). Wait
            # for it up to accept_timeout, then send anyway: the refusal ends the goal with a reason
            if self._unarmed_since is None:
                self._unarmed_since = now
            if now - self._unarmed_since < self.params.accept_timeout:
                return
        job = self.next_job(fb)
        if job is None or self._base or job.phase is JobPhase.REPLANNING:
            return
        if fb.state not in (StreamState.IDLE, StreamState.WAITING) or fb.status & StatusBits.IN_MOTION:
            return          # an earlier stream still ends
        if job.live and joints is not None and job.start is not None and \
                max(abs(a - b) for a, b in zip(joints, job.start)) > START_TOLERANCE:
            # its first point was checked from job.start: never send it from elsewhere
            self._job = None
            job.finish(False, JobPhase.FAILED, "not sent: the arm moved since the joint command was "
                       "checked (it is %.2f deg from there); the next command starts a new stream"
                       % math.degrees(max(abs(a - b) for a, b in zip(joints, job.start))), None)
            return
        if not self.starts_here(job, joints):
            return
        self._base = next_seq(fb.accepted_seq)
        self._offered, self._acked, self._ahead, self._high = None, -1, True, -1
        self._woken = None
        self._limit = len(job.points)
        self._rejected_before = fb.rejected_seq
        self._started = now
        job.next_command = 1                    # sent (MoveJob.sent): it may move from now on
        job.seqs = [self._seq(k) for k in range(len(job.points))]
        job.set_phase(JobPhase.SENDING)
        log.info("job %d: streaming %d targets #%d..#%d over %.2f s", job.id, len(job.points),
                 self._base, job.seqs[-1], job.duration)

    def _seq(self, k: int) -> int:
        return (self._base - 1 + k) % SEQ_MAX + 1

    def _target(self, job: MoveJob, k: int) -> WireTarget:
        point = job.points[k]
        return WireTarget(self._seq(k), point.joints, point.pose,
                          wire_speed(point.speed, self.params.controller.speed_scale), point.smooth)

    def before_record(self, sample: LinkSample) -> None:
        """A step woken by a request (no bus cycle) makes a record while the bus process may be
        under way with a cycle; the report of that cycle then finds it not carried, and this step's
        record replaces it before any telegram did. So what it offered counts as never offered: the
        state before it comes back, and this record offers it again (a START replaced by the next
        target sent ahead left the controller without a stream: the arm stood at point 1)."""
        if not sample.cycled:
            if self._woken is None:
                self._woken = (self._offered, self._high, self._acked, self._ahead)
            return
        if self._woken is not None and not sample.carried and self._base:
            self._offered, self._high, self._acked, self._ahead = self._woken
        self._woken = None

    def record(self, now: float) -> Any:
        outputs = self.outputs
        if self._stopping:
            return self.wire.stream_command((), stop=True, outputs=outputs)
        job = self._job
        if job is None or not self._base:
            return self.wire.stream_command((), outputs=outputs)
        k = job.points_taken
        elapsed = now - self._started

        def offered(i: int) -> bool:
            # not past the limit, and its pause (if any) over: its time passed, and the arm reached the
            # point it holds at (a G2 that solves a target nearest its joints when it takes it then
            # solves this one from there: stream_prep.CartesianStreams.with_poses)
            point = job.points[i] if i < self._limit else None
            return point is not None and point.release <= elapsed and (point.release <= 0.0 or job.points_done >= i)
        # the first target not acknowledged -- or, when the record has fewer slots than the master
        # may send ahead (protocol.send_ahead), the one after the last offered: the acknowledgement
        # of a record comes two records later (the reply to the telegram that carries it was
        # written before the controller read it), so in the steady state the last offered is the
        # first unacknowledged one and the next goes out now. When the acknowledgements did not
        # follow (the controller had no room, or missed a record) the master falls back to the
        # first unacknowledged target until the controller takes it.
        if k != self._acked:
            self._acked, self._ahead = k, True
        first = k
        ahead = self.wire.send_ahead - self.wire.look_ahead_slots
        last = self._offered
        if ahead > 0 and last is not None:
            if last - k >= ahead:
                self._ahead = False           # sent ahead, not taken: wait for the acknowledgement
            elif self._ahead and last >= k and offered(last + 1):
                first = last + 1
        targets = []
        for i in range(first, first + self.wire.look_ahead_slots):
            if not offered(i):
                break
            targets.append(self._target(job, i))
        self._offered = first + len(targets) - 1 if targets else None
        if targets and job.sent_at is None:
            job.sent_at = now
        if self._offered is not None:
            self._high = max(self._high, self._offered)
        return self.wire.stream_command(targets, start=first == 0 and bool(targets), outputs=outputs)

    def on_lost(self, now: float, reason: str) -> None:
        job = self._job
        if job is not None and job.points_taken > job.points_done:
            self.targets_aborted += 1
        self._stopping = False
        self._unarmed_since = None
        if self.outputs:
            log.warning("controller outputs 0x%04X back to their safe state 0 (link lost); they stay "
                        "there until set again", self.outputs)
        self.outputs = 0
        self._base = self._limit = 0         # the job itself is ended by the base (end_all)
        self._high = -1
