"""v1's sequencer (ROS-free, no I/O, no planning): the job queue and rules of
:class:`~vr_driver.driver.motion.sequencer.SequencerBase` with one target at a time through v1's
request / done handshake (:class:`~vr_driver.protocol.v1.MasterHandshake`). Registered for v1 by
:mod:`vr_driver.driver.sequencers`; the only driver module besides that registration that knows v1's
records."""
from __future__ import annotations

import logging
from typing import Any, Callable, Optional, Tuple

from ...errors import HandshakeError
from ...params import DriverParams
from ...protocol.common import StatusBits
from ...protocol.v1 import Accepted, Command, Done, Feedback, MasterHandshake, MasterPhase, Rejected, TimedOut
from .announced import program_duration
from .jobs import JobPhase, MoveJob
from ..link.link import LinkSample
from .sequencer import SESSION_RECORDS_BEFORE_REQUEST, SequencerBase
from .settling import pose_text

log = logging.getLogger("vr_driver.driver")

__all__ = ["HandshakeSequencer"]


class HandshakeSequencer(SequencerBase):
    """v1's handshake sequencer: one target at a time through :class:`~vr_driver.protocol.v1.MasterHandshake`
    (request, accepted, done / rejected; the arm stops at each target). :meth:`step` returns a
    :class:`~vr_driver.protocol.v1.Command`."""

    def __init__(self, params: DriverParams, clock: Callable[[], float],
                 replan: Callable[[MoveJob, Tuple[float, ...]], None]) -> None:
        super().__init__(params, clock, replan)
        self.handshake = MasterHandshake(params.accept_timeout, params.release_timeout, clock=clock)

    # ------------------------------------------------------------------ hooks
    def idle_command(self, now: float) -> Command:
        self.handshake.update(None, now)
        return self.handshake.outputs()

    def record(self, now: float) -> Command:
        return self.handshake.outputs()

    def apply_replan(self, job: MoveJob, plan: Any) -> None:
        """v1: the job's new preview, which starts where the arm now is."""
        job.preview = plan
        job.start = plan.trajectory.start

    def stop_untracked(self, reason: str, now: float) -> None:
        if self.handshake.phase not in (MasterPhase.IDLE, MasterPhase.SYNC):
            self.handshake.abort(reason, now, stop=True)

    def stop_job(self, job: MoveJob, reason: str, now: float) -> None:
        aborted = self.handshake.abort(reason, now, stop=True)
        if aborted is not None:
            self.targets_aborted += 1
            log.info("job %d: stop sent (%s); waiting for the arm to come to rest", job.id, reason)
            self.begin_settle(job, JobPhase.CANCELLED, reason, now)
        elif job.sent:
            # between the via point and the end point of a CIRC: nothing in flight, the arm is
            # where the last target left it -- still, report the pose at rest
            self.begin_settle(job, JobPhase.CANCELLED, reason, now)
        else:
            job.finish(False, JobPhase.CANCELLED, reason, None)

    def on_lost(self, now: float, reason: str) -> None:
        if self.handshake.reset(reason, now) is not None:
            self.targets_aborted += 1

    # ------------------------------------------------------------------ handshake events
    def follow(self, now: float, fb: Feedback, sample: LinkSample) -> None:
        event = self.handshake.update(sample.fresh, now)
        if event is None:
            return
        job = self._job
        if isinstance(event, Accepted):
            if job is not None:
                job.set_phase(JobPhase.MOVING)
            return
        if isinstance(event, Done):
            self.targets_done += 1
            if job is None:
                return
            if job.next_command < len(job.preview.commands):
                return                       # the via point of a CIRC: the end point follows
            self._job = None
            log.info("job %d done at %s", job.id, pose_text(fb.pose))
            job.finish(True, JobPhase.SUCCEEDED, "", fb.pose)
            return
        if isinstance(event, TimedOut) and not event.final:
            log.warning("%s", event.reason)
            return
        if isinstance(event, Rejected):
            self.targets_rejected += 1
        else:
            self.targets_aborted += 1
        if job is None:
            return
        self._job = None
        reason = event.reason
        log.warning("job %d ended: %s", job.id, reason)
        if isinstance(event, TimedOut):
            # the controller may still be moving: stop it, and end the job at rest
            self.handshake.abort(reason, now, stop=True)
        moved = job.phase is JobPhase.MOVING or bool(fb.status & StatusBits.IN_MOTION)
        if moved or isinstance(event, TimedOut):
            self.begin_settle(job, JobPhase.FAILED, reason, now)
        else:
            job.finish(False, JobPhase.FAILED, reason, fb.pose)
        # a failed target ends the rest of its joint path too: never skip ahead silently
        self.fail_queue("an earlier target of the same path failed (%s)" % reason, job.group)

    # ------------------------------------------------------------------ sending
    def advance(self, now: float, fb: Feedback, sample: LinkSample,
                joints: Optional[Tuple[float, ...]]) -> None:
        if self._settle is not None or not self.handshake.ready:
            return
        if sample.session_records < SESSION_RECORDS_BEFORE_REQUEST:
            return          # the controller has not surely seen our flag at 0 twice yet
        job = self.next_job(fb)
        if job is None or job.phase is JobPhase.REPLANNING or job.next_command >= len(job.preview.commands):
            return
        if job.next_command == 0 and not self.starts_here(job, joints):
            return
        command = job.preview.commands[job.next_command]
        # the move at the program's own speed (MOVEP / MOVEL), not the arm's full speed it was previewed at
        timeout = (self.params.motion_timeout_factor * program_duration(self.wire, job.preview,
                                                                    self.params.controller)
                   + self.params.motion_timeout_margin)
        try:
            seq = self.handshake.submit(command, timeout, now)
        except HandshakeError as exc:   # cannot happen when ready; keep the job
            log.warning("job %d: %s", job.id, exc)
            return
        job.seqs.append(seq)
        if job.sent_at is None:
            job.sent_at = now
        job.next_command += 1
        self.targets_sent += 1
        log.info("job %d: sent target %d: %s", job.id, seq, command.describe())
        job.set_phase(JobPhase.SENDING)

