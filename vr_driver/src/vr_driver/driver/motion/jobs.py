"""Moves on their way to the controller: the request, its validated preview, the job that carries
it through the sequencer, and its result. ROS-free, no I/O.

A :class:`MoveJob` is created by :class:`~vr_driver.driver.core.DriverCore` (in the caller's
thread, after validation) and from then on changed only by the bus thread's
:class:`~vr_driver.driver.motion.handshake.HandshakeSequencer`. Other threads wait on it
(:meth:`MoveJob.wait`, :meth:`MoveJob.wait_change`) or read its phase.
"""
from __future__ import annotations

import enum
import itertools
import logging
import threading
from dataclasses import dataclass
from typing import Callable, List, Optional, Tuple

from ...kinematics.preview import Trajectory
from ...poses import ControllerPose, MoveType
from ...protocol.base import MoveCommand

log = logging.getLogger("vr_driver.driver")

__all__ = ["MoveRequest", "Preview", "JobPhase", "JobResult", "MoveJob", "SubmitMode", "StreamPoint"]


@dataclass(frozen=True)
class MoveRequest:
    """A move in controller units (mm, deg; frame base)."""

    move_type: MoveType
    target: ControllerPose
    via: Optional[ControllerPose] = None
    preview_only: bool = False
    label: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "move_type", MoveType.parse(self.move_type))
        if not isinstance(self.target, ControllerPose):
            object.__setattr__(self, "target", ControllerPose.from_sequence(self.target))
        if self.via is not None and not isinstance(self.via, ControllerPose):
            object.__setattr__(self, "via", ControllerPose.from_sequence(self.via))


@dataclass(frozen=True)
class Preview:
    """A validated move: its wire targets (rounded, checked: the protocol's
    :meth:`~vr_driver.protocol.base.Protocol.move_commands`) and the planned trajectory, checked
    sample by sample against the joint limits and the workspace box."""

    request: MoveRequest
    commands: Tuple[MoveCommand, ...]
    trajectory: Trajectory
    joint_target: Tuple[float, ...]

    @property
    def duration(self) -> float:
        return self.trajectory.duration

    @property
    def target(self) -> ControllerPose:
        return self.commands[-1].pose


@dataclass(frozen=True)
class StreamPoint:
    """One target of a stream (a streaming protocol): where (controller joint order, rad), how fast
    (speed in 0.1 % of the joint speed limits, 1..1000, as on the wire) and whether the arm may
    blend through it (smooth level; 0 = stop exactly there)."""

    joints: Tuple[float, ...]
    speed: int
    smooth: int
    time: float                  # planned arrival, seconds from the stream's start
    index: int                   # the planned point it is (index into the trajectory's points)
    release: float = 0.0         # not offered before this many seconds from the stream's start (the
    #                              end of a pause of the plan: the arm holds at the point before),
    #                              nor before the arm reached that point
    pose: Optional[ControllerPose] = None   # FK of ``joints`` in controller units (mm, deg): what a
    #                              Cartesian streaming protocol sends (None for a joint protocol)
    fed: Optional[float] = None  # the arrival its speed is set for, seconds from the stream's start: no
    #                              sooner than the bus can have brought the next target (later than
    #                              ``time`` by the lead and any later shift, stream_points.fed_schedule;
    #                              None: ``time``)
    hold: bool = False           # the hold at the stream's start: a target just off it toward the first
    #                              point, reached ``fed`` s after the start while the bus fills the
    #                              controller's ring (stream_points.hold_point; ``index`` the start's)


class JobPhase(enum.Enum):
    QUEUED = "queued"
    REPLANNING = "replanning"      # the arm is not where the job was planned from: planned again
    SENDING = "sending"            # target sent, waiting for the controller to accept it
    MOVING = "moving"
    STOPPING = "stopping"          # stop sent; waiting for the arm to come to rest
    SUCCEEDED = "succeeded"
    FAILED = "failed"              # rejected, timed out, link lost, not plannable from here
    CANCELLED = "cancelled"        # cancelled, preempted or replaced; ``reached`` = the rest pose

    @property
    def final(self) -> bool:
        return self in (JobPhase.SUCCEEDED, JobPhase.FAILED, JobPhase.CANCELLED)


class SubmitMode(enum.Enum):
    """How a new job relates to the jobs already there."""

    APPEND = "append"      # queue behind the others
    PREEMPT = "preempt"    # a new goal: the running move is stopped (ends at rest), the queue dropped
    REPLACE = "replace"    # a new joint path: the queued targets are dropped, the one in flight
                           # completes, then the new path runs from its end


@dataclass(frozen=True)
class JobResult:
    success: bool
    phase: JobPhase
    reason: str = ""
    reached: Optional[ControllerPose] = None     # where the arm was at rest at the end (None: it
                                                 # never moved for this job, or the link was lost)


class MoveJob:
    """One move on its way to the controller. Wait with :meth:`wait`; the bus thread sets the
    phase and the result. ``on_update(job)`` (optional) is called from the bus thread on changes."""

    _ids = itertools.count(1)

    def __init__(self, preview: Optional[Preview], on_update: Optional[Callable[["MoveJob"], None]] = None,
                 group: Optional[int] = None, ticket: Optional[int] = None,
                 points: Tuple[StreamPoint, ...] = (), start: Optional[Tuple[float, ...]] = None,
                 live: bool = False, stamp: float = 0.0) -> None:
        self.id = next(MoveJob._ids)
        self.group = self.id if group is None else group   # the jobs of one joint path share it
        self.ticket = ticket                                # arrival order of the goal (or None)
        self.preview = preview
        self.on_update = on_update
        self.phase = JobPhase.QUEUED
        self.result: Optional[JobResult] = None
        self.next_command = 0           # index into preview.commands of the next one to send
        self.seqs: List[int] = []       # handshake sequence numbers of what was sent
        self.stop_reason = ""           # set when a stop was requested for it
        #: the clock time of the bus step that first put one of its targets in the record handed to
        #: the bus (it goes out with the next bus cycle); None while none was
        self.sent_at: Optional[float] = None
        #: ... and of the bus cycle that carried that record to the controller (when the driver learnt
        #: that it ran: the controller has the target by then)
        self.left_at: Optional[float] = None
        self.sent_serial: Optional[int] = None    # a bus process's serial of the record that first offered it
        #: the clock time of the bus step that ended it (None: not ended by a bus step, or not yet)
        self.ended_at: Optional[float] = None
        # a streaming protocol: the stream's targets (empty for a handshake job), where it was planned to
        # start, how many of its points the controller took / reached so far, and how often the
        # arm stood at a point waiting for the next target (a gap: the look-ahead ran dry)
        self.points = tuple(points)
        self.start = start if start is not None else (
            preview.trajectory.start if preview is not None else None)
        self.points_taken = 0
        self.points_done = 0
        self.gaps = 0
        # a joint_command stream (DriverCore.joint_command): its points grow while commands come
        # (StreamSequencer.extend); ``closed`` once none came for joint_command_timeout (or a
        # trajectory took over): then it ends like any stream, at rest at its last point.
        # ``last_command``: the clock time the newest command was accepted
        self.live = live
        self.closed = False
        self.last_command = stamp
        self.replaced = 0               # commands that replaced a point not yet on the wire
        if preview is None and not self.points:
            raise ValueError("a job needs a preview (a handshake) or stream points (a stream)")
        self._done = threading.Event()
        self._changed = threading.Condition()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    @property
    def sent(self) -> bool:
        """True once any of its commands went to the controller."""
        return self.next_command > 0

    @property
    def joint_target(self) -> Tuple[float, ...]:
        """Where the arm ends when the job succeeds."""
        if self.points:
            return self.points[-1].joints
        assert self.preview is not None
        return self.preview.joint_target

    @property
    def duration(self) -> float:
        """The planned duration [s]."""
        if self.points:
            return self.points[-1].time
        assert self.preview is not None
        return self.preview.duration

    def wait(self, timeout: Optional[float] = None) -> Optional[JobResult]:
        self._done.wait(timeout)
        return self.result

    def wait_change(self, phase: JobPhase, timeout: float) -> JobPhase:
        """Wait until the phase differs from ``phase`` (or ``timeout``); return the phase."""
        with self._changed:
            self._changed.wait_for(lambda: self.phase is not phase, timeout)
            return self.phase

    def set_phase(self, phase: JobPhase) -> None:
        if self.phase is not phase and not self.done:
            with self._changed:
                self.phase = phase
                self._changed.notify_all()
            self._notify()

    def finish(self, success: bool, phase: JobPhase, reason: str,
               reached: Optional[ControllerPose]) -> bool:
        """Set the result once (later calls do nothing and return False)."""
        if self._done.is_set():
            return False
        with self._changed:
            self.phase = phase
            self.result = JobResult(success, phase, reason, reached)
            self._done.set()
            self._changed.notify_all()
        self._notify()
        return True

    def _notify(self) -> None:
        if self.on_update is not None:
            try:
                self.on_update(self)
            except Exception:  # a client callback must never kill the bus thread
                log.exception("job %d: update callback failed", self.id)

    def __repr__(self) -> str:
        kind = self.preview.request.move_type.name if self.preview is not None else \
            "stream of %d" % len(self.points)
        return "MoveJob(%d, %s, %s)" % (self.id, kind, self.phase.value)
