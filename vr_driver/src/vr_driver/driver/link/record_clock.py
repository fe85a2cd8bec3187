"""When the controller took a record: the time joint_states and the trajectory feedback carry.
ROS-free, no I/O.

A reply arrives at the master some time after the controller's program wrote the record into the
card: the reply's time on the wire (known: the telegram's length at the baud) plus the time the
record waited in the card (unknown: up to one program loop, more when the loop is slow). On the
paced 19.2 kbit/s line, 10 ms of unknown age is half a degree at 50 deg/s.

Protocols whose records carry the program's loop counter (the heartbeat of v2 and v3: +1 every
program loop, modulo 65536) tell more: a program that loops at a steady period P wrote record k at
``t0 + k P``. :class:`RecordClock` estimates P and t0 from the records seen: P as the slope of the
observed times (arrival less wire time) over the unwrapped loop counts (each observation is late by
an age in [0, P) that does not depend on k, so the slope is unbiased), t0 from the lower envelope
(the freshest records of the window were taken just before they were sent). The stamp of a record
is then ``t0 + k P``, never later than its observation. A record whose counter did not change is
the same record: it keeps its stamp (it is not a new sample).

Until the window holds enough records (and for protocols without a heartbeat: v1) the stamp is
the observation itself. A counter that jumps back or far ahead (a program restarted), or a new
Data_Exchange session, starts the estimate afresh.
"""
from __future__ import annotations

import collections
from typing import Deque, Optional, Tuple

__all__ = ["RecordClock"]


class RecordClock:
    """See the module docstring. ``window``: records the estimate uses; ``min_records`` /
    ``min_loops``: before the window holds that many records spanning that many loops, stamps are
    the observations; ``max_jump``: a counter step larger than this (loops) is a restart."""

    def __init__(self, modulus: int = 65536, window: int = 200, min_records: int = 20,
                 min_loops: int = 50, max_jump: int = 5000) -> None:
        self.modulus = modulus
        self.window = window
        self.min_records = min_records
        self.min_loops = min_loops
        self.max_jump = max_jump
        self.resets = 0
        self._samples: Deque[Tuple[int, float]] = collections.deque(maxlen=window)
        self._raw: Optional[int] = None        # the last heartbeat as received
        self._k = 0                            # ... unwrapped
        self._last_stamp: Optional[float] = None
        self.period: Optional[float] = None    # the estimated loop period [s] (None: not yet)

    def reset(self) -> None:
        self._samples.clear()
        self._raw = None
        self._last_stamp = None
        self.period = None
        self.resets += 1

    def stamp(self, observed: float, heartbeat: Optional[int]) -> float:
        """The time the record with ``heartbeat`` was taken; ``observed``: its arrival less its time
        on the wire (an upper bound). Without a heartbeat: ``observed``."""
        if heartbeat is None:
            return observed
        if self._raw is not None:
            step = (heartbeat - self._raw) % self.modulus
            if step == 0 and self._last_stamp is not None:
                return self._last_stamp            # the same record again: the same sample
            if step > self.max_jump:
                self.reset()
        if self._raw is None:
            self._k = 0
        else:
            self._k += (heartbeat - self._raw) % self.modulus
        self._raw = heartbeat
        self._samples.append((self._k, observed))
        stamp = self._estimate(observed)
        if self._last_stamp is not None and stamp <= self._last_stamp:
            stamp = min(observed, self._last_stamp + 1e-6)     # never out of order
        self._last_stamp = stamp
        return stamp

    def _estimate(self, observed: float) -> float:
        samples = self._samples
        if len(samples) < self.min_records or samples[-1][0] - samples[0][0] < self.min_loops:
            self.period = None
            return observed
        n = len(samples)
        mk = sum(k for k, _ in samples) / n
        mt = sum(t for _, t in samples) / n
        var = sum((k - mk) ** 2 for k, _ in samples)
        if var <= 0.0:
            return observed
        period = sum((k - mk) * (t - mt) for k, t in samples) / var
        if period <= 0.0:
            return observed
        self.period = period
        t0 = min(t - period * k for k, t in samples)           # the lower envelope
        return min(observed, t0 + period * samples[-1][0])
