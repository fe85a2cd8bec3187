"""A sequencer's inbox (:mod:`vr_driver.driver.motion.sequencer`): the requests other threads post, and
the tickets that keep goals in the order they arrived. ROS-free, no I/O.

Other threads never touch a sequencer's state: they post a request (:class:`AddJobs`,
:class:`CancelJobs`, :class:`Replanned`, :class:`ExtendJob`), and the bus thread's next step takes
them all, in the order they were posted (:meth:`Inbox.take`). A goal that will preempt claims a
ticket when it arrives (:meth:`Inbox.claim_ticket`); a PREEMPT job whose ticket is older than the
newest claimed, or than the newest taken in, is superseded (:meth:`Inbox.superseded`).
"""
from __future__ import annotations

import collections
import threading
from dataclasses import dataclass
from typing import Any, Deque, List, Optional, Tuple, Union

from .jobs import MoveJob, SubmitMode

__all__ = ["AddJobs", "CancelJobs", "ExtendJob", "Inbox", "Replanned", "Request"]


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


class Inbox:
    """See the module docstring. :meth:`claim_ticket` and :meth:`post` are safe from any thread;
    :meth:`take`, :meth:`superseded` and :meth:`preempts` are the bus thread's."""

    def __init__(self) -> None:
        self._lock = threading.Lock()            # guards only the requests and the ticket counter
        self._requests: Deque[Request] = collections.deque()
        self._claimed = 0                         # newest ticket handed out
        self._newest = 0                          # newest ticket of a PREEMPT job taken in

    def claim_ticket(self) -> int:
        """A number in arrival order for a goal that will preempt."""
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
