"""Bus health: how regularly the controller's card hears from the master. ROS-free.

The card's DP watchdog (``watchdog_ms`` of the bus config, 300 ms by default) stops the arm and
resets the G2's program when no valid telegram reaches it for that long. What the driver can see of
that margin is the time between two Data_Exchange replies of the card: :class:`BusHealth` is fed
each reply's arrival time (:meth:`BusHealth.reply`) in the process that owns the master, and
summarises the last minute (:meth:`BusHealth.summary`): the longest gap, the cycle jitter (how far a
gap strays from the nominal period; p99 and max) and the watchdog margin (the watchdog less the
longest gap). A gap past half the watchdog is counted and logged at once: the next such gap may be
a watchdog expiry.

Only gaps inside one Data_Exchange session count (:meth:`BusHealth.session_ended`): the time the card
spends out of Data_Exchange (a reconnection, a new Set_Prm) is a link loss, reported as such.
"""
from __future__ import annotations

import collections
import logging
import math
from dataclasses import dataclass
from typing import Deque, Optional, Tuple

log = logging.getLogger("vr_driver.driver")

__all__ = ["BusHealth", "BusHealthSummary", "HEALTH_WINDOW"]

#: [s] the window of the summary
HEALTH_WINDOW = 60.0


@dataclass(frozen=True)
class BusHealthSummary:
    """The last :data:`HEALTH_WINDOW` seconds of Data_Exchange replies (times in seconds)."""

    period: float                  # the nominal bus period (1 / cycle rate)
    watchdog: Optional[float]      # the card's watchdog, None = off
    replies: int                   # replies in the window
    max_gap: float                 # the longest gap between two replies in the window (0: < 2 replies)
    jitter_p99: float              # p99 of |gap - period| in the window
    jitter_max: float              # max of |gap - period| in the window
    worst_gap: float               # the longest gap since the start
    late_gaps: int                 # gaps past half the watchdog since the start
    scheduling: str = ""           # how the owning process is scheduled (e.g. "SCHED_FIFO 20")

    @property
    def margin(self) -> Optional[float]:
        """The watchdog less the longest gap of the window (None without a watchdog)."""
        return None if self.watchdog is None else self.watchdog - self.max_gap

    @property
    def late(self) -> bool:
        """A gap of the window passed half the watchdog."""
        return self.watchdog is not None and self.max_gap > 0.5 * self.watchdog

    def describe(self) -> str:
        text = "longest gap %.1f ms, jitter p99 %.1f ms / max %.1f ms over %d replies" % (
            1e3 * self.max_gap, 1e3 * self.jitter_p99, 1e3 * self.jitter_max, self.replies)
        if self.watchdog is not None:
            text += ", watchdog margin %.0f ms of %.0f ms" % (1e3 * self.margin, 1e3 * self.watchdog)
        return text


class BusHealth:
    """See the module docstring. ``period``: the nominal bus period [s]; ``watchdog``: the card's
    watchdog [s] or None; ``window``: the summary's span [s]."""

    def __init__(self, period: float, watchdog: Optional[float], window: float = HEALTH_WINDOW,
                 scheduling: str = "") -> None:
        if not period > 0:
            raise ValueError("period must be > 0 s, got %r" % (period,))
        self.period = float(period)
        self.watchdog = watchdog if watchdog else None
        self.window = float(window)
        self.scheduling = scheduling
        self._gaps: Deque[Tuple[float, float]] = collections.deque()    # (time, gap)
        self._last: Optional[float] = None
        self.worst_gap = 0.0
        self.late_gaps = 0
        self.replies = 0

    def reply(self, at: float) -> Optional[float]:
        """A Data_Exchange reply of the card arrived at ``at``; returns the gap to the previous
        one of this session (None for the first)."""
        self.replies += 1
        last, self._last = self._last, at
        if last is None:
            return None
        gap = at - last
        self._gaps.append((at, gap))
        self._trim(at)
        if gap > self.worst_gap:
            self.worst_gap = gap
        if self.watchdog is not None and gap > 0.5 * self.watchdog:
            self.late_gaps += 1
            log.warning("%.0f ms between two Data_Exchange cycles: more than half the card's watchdog "
                        "(%.0f ms); at the watchdog the G2 stops the arm and resets its program",
                        1e3 * gap, 1e3 * self.watchdog)
        return gap

    def session_ended(self) -> None:
        """The card left Data_Exchange: the next reply starts a new series."""
        self._last = None

    def _trim(self, now: float) -> None:
        gaps = self._gaps
        while gaps and gaps[0][0] < now - self.window:
            gaps.popleft()

    def summary(self, now: float) -> BusHealthSummary:
        """The window ending at ``now`` (a sort of its gaps: call it about once a second)."""
        self._trim(now)
        gaps = [g for _, g in self._gaps]
        jitter = sorted(abs(g - self.period) for g in gaps)
        p99 = jitter[min(len(jitter) - 1, int(math.ceil(0.99 * len(jitter))) - 1)] if jitter else 0.0
        return BusHealthSummary(
            period=self.period, watchdog=self.watchdog, replies=len(gaps) + (1 if gaps else 0),
            max_gap=max(gaps) if gaps else 0.0, jitter_p99=p99, jitter_max=jitter[-1] if jitter else 0.0,
            worst_gap=self.worst_gap, late_gaps=self.late_gaps, scheduling=self.scheduling)
