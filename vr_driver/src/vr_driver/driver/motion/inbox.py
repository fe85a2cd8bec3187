"""A sequencer's inbox (:mod:`vr_driver.driver.motion.sequencer`): all other threads touch of the bus
side -- the requests they post, the tickets that keep goals in the order they arrived, the wake-up
of the bus thread and the snapshot they read before they post. ROS-free, no I/O but a pipe.

Other threads never touch a sequencer's state: they post a request (:meth:`Inbox.add`,
:meth:`Inbox.cancel`, :meth:`Inbox.stop_all`, :meth:`Inbox.replanned`, :meth:`Inbox.extend`: an
:class:`AddJobs`, :class:`CancelJobs`, :class:`Replanned`, :class:`ExtendJob`), and the bus thread's
next step takes them all, in the order they were posted (:meth:`Inbox.take`). A goal that will
preempt claims a ticket when it arrives (:meth:`Inbox.claim_ticket`); a PREEMPT job whose ticket is
older than the newest claimed, or than the newest taken in, is superseded (:meth:`Inbox.superseded`).

What they read is the :class:`MotionSnapshot` the bus loop publishes here with every status
(:meth:`Inbox.snapshot`), and what they wake the bus thread with is the inbox's :class:`Wake`: so a
goal's thread runs no code of the bus side (the bus loop, the link, the DP master;
``bench/goal_walk.py`` lists what it runs).
"""
from __future__ import annotations

import collections
import math
import os
import threading
from dataclasses import dataclass, replace
from typing import Any, Deque, List, Optional, Sequence, Tuple, Union

from .jobs import MoveJob, SubmitMode

__all__ = ["AddJobs", "CancelJobs", "ExtendJob", "Inbox", "MotionSnapshot", "Replanned", "Request", "Wake",
           "no_link", "stale_reason"]


@dataclass(frozen=True)
class AddJobs:
    jobs: Tuple[MoveJob, ...]
    mode: SubmitMode


@dataclass(frozen=True)
class CancelJobs:
    job: Optional[MoveJob]      # None: stop everything
    reason: str


@dataclass(frozen=True)
class Replanned:
    job: MoveJob
    preview: Optional[Any]          # a handshake job: a Preview; a stream job: its new stream points (None: failed)
    error: str


@dataclass(frozen=True)
class ExtendJob:
    job: MoveJob                    # a live job (a joint_command stream)
    point: Any                      # the validated StreamPoint of the new command
    anchored: Any                   # the same point as the successor of ``anchor`` (see extend)
    anchor: Optional[Tuple[float, ...]]   # the joints ``anchored`` was validated from
    stamp: float                    # clock time the command was accepted


Request = Union[AddJobs, CancelJobs, Replanned, ExtendJob]


def stale_reason(now: float, time: float, feedback_time: Optional[float], limit: float) -> str:
    """Why a snapshot taken at ``time`` (its controller record arrived at ``feedback_time``) must be
    read as a lost link at ``now`` -- it or its record more than ``limit`` seconds old --, "" when it
    may be read as it is."""
    age = now - time
    fb_age = None if feedback_time is None else now - feedback_time
    if age <= limit and (fb_age is None or fb_age <= limit):
        return ""
    if age > limit:
        return "the driver's status is %.2f s old (the bus loop stalled)" % age
    return "the controller's last record is %.2f s old" % fb_age


def no_link(state: str, reason: str) -> str:
    """Why motion is not possible without a link to the controller (``state``: the link's state)."""
    return "no link to the controller (%s: %s)" % (state, reason)


@dataclass(frozen=True)
class MotionSnapshot:
    """What a request reads of the bus side before it posts: the part of the driver's status
    (:class:`~vr_driver.driver.motion.status.DriverStatus`, of the same bus iteration) that says
    whether motion is possible, the arm's joints and the measured bus cycle rate. Published by the
    bus loop with every status (:meth:`Inbox.publish`); read with :meth:`at`, as the status is read:
    one older than ``limit`` (``link_timeout``), or whose controller record is, is a lost link."""

    time: float                                  # the bus iteration's clock time
    motion_possible: bool
    why_not: str                                 # why motion is not possible ("" when it is)
    joints: Optional[Tuple[float, ...]]
    joints_valid: bool
    link_words: str                              # the link's reason, else its state (a missing joint state's words)
    cycle_rate: float                            # measured DP cycles per second (0: not measured yet)
    feedback_time: Optional[float] = None        # the controller record's arrival (None: none)
    limit: float = math.inf                      # [s] link_timeout

    def at(self, now: float) -> "MotionSnapshot":
        """This snapshot as it must be read at ``now`` (:func:`stale_reason`): unchanged while it is
        fresh, else no motion, no valid joints, the reason said."""
        reason = stale_reason(now, self.time, self.feedback_time, self.limit)
        if not reason:
            return self
        return replace(self, motion_possible=False, why_not=no_link("stale", reason), joints_valid=False,
                       link_words=reason)


class Wake:
    """Run a bus cycle now: set by any thread that posted a request (no lock of the bus side: also
    safe from a signal handler), waited for by the bus thread -- :meth:`wait` where it cycles the bus
    itself, or :meth:`fileno` (a pipe's end, made at the first call) where it waits for a bus
    process's reports (``src/vr_driver/bus/process.py``), which then :meth:`clear` s it."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self._read: Optional[int] = None
        self._write: Optional[int] = None
        self._lock = threading.Lock()          # only the pipe's making

    def set(self) -> None:
        self._event.set()                      # first: fileno() writes for a set it sees
        self._poke()

    def _poke(self) -> None:
        fd = self._write
        if fd is not None:
            try:
                os.write(fd, b"!")
            except OSError:
                pass                           # a wake is pending already (a full pipe), or closed

    def is_set(self) -> bool:
        return self._event.is_set()

    def wait(self, timeout: Optional[float]) -> bool:
        """Wait at most ``timeout`` s for :meth:`set`; True when it was set."""
        return self._event.wait(timeout)

    def clear(self) -> None:
        """Taken: the event cleared, the pipe emptied (a set after this wakes the next wait)."""
        self._event.clear()
        fd = self._read
        if fd is not None:
            try:
                while os.read(fd, 64):
                    pass
            except OSError:
                pass

    def fileno(self) -> int:
        """The read end of a pipe a byte is written to at each :meth:`set` (made at the first call)."""
        with self._lock:
            if self._read is None:
                read, write = os.pipe()
                os.set_blocking(read, False)
                os.set_blocking(write, False)
                self._write = write
                self._read = read
                if self._event.is_set():
                    self._poke()
            return self._read

    def __del__(self) -> None:
        for fd in (self._read, self._write):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass


class Inbox:
    """See the module docstring. :meth:`claim_ticket`, :meth:`post` (and the requests made into
    posts: :meth:`add` ... :meth:`extend`), :meth:`snapshot` and :attr:`wake` are safe from any
    thread; :meth:`take`, :meth:`superseded`, :meth:`preempts` and :meth:`publish` are the bus
    thread's."""

    def __init__(self) -> None:
        self._lock = threading.Lock()            # guards only the requests and the ticket counter
        self._requests: Deque[Request] = collections.deque()
        self._claimed = 0                         # newest ticket handed out
        self._newest = 0                          # newest ticket of a PREEMPT job taken in
        self.wake = Wake()                        # set by the poster: the bus thread runs a cycle now
        self._snapshot: Optional[MotionSnapshot] = None

    # ------------------------------------------------------------------ any thread
    def add(self, jobs: Sequence[MoveJob], mode: SubmitMode = SubmitMode.APPEND) -> None:
        self.post(AddJobs(tuple(jobs), mode))

    def cancel(self, job: MoveJob, reason: str) -> None:
        self.post(CancelJobs(job, reason))

    def stop_all(self, reason: str) -> None:
        self.post(CancelJobs(None, reason))

    def replanned(self, job: MoveJob, preview: Optional[Any], error: str = "") -> None:
        self.post(Replanned(job, preview, error))

    def extend(self, job: MoveJob, point: Any, anchored: Any, anchor: Optional[Tuple[float, ...]],
               stamp: float) -> None:
        """A new command of the live job ``job`` (a joint_command stream): ``point`` follows the
        job's last point; ``anchored`` is the same target as the successor of ``anchor`` (the
        view's ``live_anchor`` when it was validated: the last point put on the wire then), used
        where the new point replaces one not put on the wire yet -- and only while ``anchor`` is
        still the last point on the wire (streaming protocols only)."""
        self.post(ExtendJob(job, point, anchored, anchor, stamp))

    def snapshot(self, now: float) -> MotionSnapshot:
        """The latest :class:`MotionSnapshot`, read at ``now`` (:meth:`MotionSnapshot.at`)."""
        snap = self._snapshot
        if snap is None:
            return MotionSnapshot(now, False, "the bus loop has not run yet", None, False, "not started", 0.0)
        return snap.at(now)

    # ------------------------------------------------------------------ bus thread
    def publish(self, snapshot: MotionSnapshot) -> None:
        """The bus iteration's snapshot (with its status)."""
        self._snapshot = snapshot

    def claim_ticket(self) -> int:
        """A number in arrival order for a goal that will preempt (take it when the goal arrives; a
        job carrying an older ticket than the newest claimed one is superseded)."""
        with self._lock:
            self._claimed += 1
            return self._claimed

    def post(self, request: Request) -> None:
        with self._lock:
            self._requests.append(request)

    def take(self) -> List[Request]:
        """Every request posted since the last call, in the order posted."""
        with self._lock:
            requests = list(self._requests)
            self._requests.clear()
        return requests

    def superseded(self, ticket: Optional[int]) -> bool:
        """A PREEMPT job of ``ticket`` arrived before a newer goal (claimed or taken in): it
        must not run. A job without a ticket never is."""
        with self._lock:
            newest_claimed = self._claimed
        return ticket is not None and (ticket < self._newest or ticket < newest_claimed)

    def preempts(self, ticket: Optional[int]) -> None:
        """A PREEMPT job of ``ticket`` was taken in (not superseded)."""
        if ticket is not None:
            self._newest = ticket
