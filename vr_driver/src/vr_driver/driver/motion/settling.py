"""Truth at the end of a stopped job, for the sequencers (:mod:`vr_driver.driver.motion.sequencer`):
whether the arm is at rest, and the end of a job that waits for it. ROS-free, no I/O.

A job that is stopped (cancel, stop_motion, preempted), rejected while the arm moved, or timed out
ends only when the controller reports the arm at rest -- the protocol's own condition (the
sequencer's ``resting``), the in-motion bit clear and the reported pose unchanged for
``stop_settle_time`` -- and its result carries that pose. One that does not come to rest within
``stop_timeout`` fails, with the last pose reported. :class:`Settling` keeps the job that waits
(at most one: nothing new is sent before it ended) and the arm's rest, record by record.
"""
from __future__ import annotations

import logging
from typing import Any, Callable, Optional, Tuple

from ...params import DriverParams
from ...protocol.common import FeedbackRecord, StatusBits
from .jobs import JobPhase, MoveJob

log = logging.getLogger("vr_driver.driver")

__all__ = ["Settle", "Settling", "pose_text"]


def pose_text(pose: Any) -> str:
    """A reported pose in a log line, in controller units (a record's values are the wire's
    integers: 0.1 mm / 0.01 deg on v3, 0.01 mm / 0.001 deg on v2)."""
    return "(%.1f, %.1f, %.1f mm, %.2f, %.2f, %.2f deg)" % pose.as_tuple()


class Settle:
    """A job that ends when the arm is at rest (``job`` None: a motion of no job is stopped),
    with ``phase`` and ``reason``; it waits since ``since``."""

    def __init__(self, job: Optional[MoveJob], phase: JobPhase, reason: str, since: float) -> None:
        self.job = job
        self.phase = phase
        self.reason = reason
        self.since = since


class Settling:
    """See the module docstring. :attr:`pending` is the :class:`Settle` waiting (None: none);
    :meth:`track` follows every record of the link session, :meth:`check` ends the pending job."""

    def __init__(self, params: DriverParams) -> None:
        self.params = params
        self.pending: Optional[Settle] = None
        self._rest_values: Optional[Tuple[int, ...]] = None   # the reported values last seen
        self._rest_since = 0.0                                 # unchanged and not in motion since

    def begin(self, job: MoveJob, phase: JobPhase, reason: str, now: float) -> None:
        """``job`` was stopped (or failed while the arm may move): it ends with ``phase`` and
        ``reason`` once the arm is at rest."""
        job.set_phase(JobPhase.STOPPING)
        self.pending = Settle(job, phase, reason, now)

    def track(self, now: float, fb: FeedbackRecord) -> None:
        """A record of this session: the reported values changed or the arm moves -- not at rest
        since now."""
        values = fb.values
        if values != self._rest_values or fb.status & StatusBits.IN_MOTION:
            self._rest_values = values
            self._rest_since = now

    def forget(self) -> None:
        """The link was lost: the first record of the next session starts the rest anew."""
        self._rest_values = None

    def at_rest(self, now: float, fb: Any, resting: Callable[[Any], bool]) -> bool:
        """The arm at rest: the protocol's own condition (``resting``), the in-motion bit clear and
        the reported pose unchanged for ``stop_settle_time``."""
        return resting(fb) and not fb.status & StatusBits.IN_MOTION and \
            now - self._rest_since >= self.params.stop_settle_time

    def check(self, now: float, fb: FeedbackRecord, resting: Callable[[Any], bool]) -> None:
        """End the pending job: at rest, with the pose reported; after ``stop_timeout``, failed
        with the last pose reported."""
        settle = self.pending
        if settle is None:
            return
        job = settle.job
        if self.at_rest(now, fb, resting):
            self.pending = None
            if job is not None:
                log.info("job %d: the arm is at rest at %s", job.id, pose_text(fb.pose))
                job.finish(False, settle.phase, settle.reason, fb.pose)
            return
        if now - settle.since > self.params.stop_timeout:
            self.pending = None
            why = ("%s; the arm did not come to rest within %.3g s (stop_timeout); last reported "
                   "pose %s" % (settle.reason, self.params.stop_timeout, pose_text(fb.pose)))
            log.error("job %s: %s", job.id if job is not None else "-", why)
            if job is not None:
                job.finish(False, JobPhase.FAILED, why, fb.pose)
