"""The cycle rate the line really gives, against the one asked, and why. ROS-free.

Nothing fails when a bus cycles slower than ``cycle_rate``: the bus process starts the next cycle
at once and the rate is what the line, the stations and the USB adapter allow. At 19.2 kbit/s the
controller's and the I/O island's telegrams fill most of a 15 Hz cycle on their own; an adapter
that holds each reply up to its latency timer (an FTDI's default is 16 ms) or a line that needs
resends takes the rest. :class:`LineCheck` is fed the DP master's counters after each cycle
(:meth:`LineCheck.update`, in the link supervisor's thread) and says, in words:

- the measured cycles per second over the last ``window`` seconds against the asked rate; when it
  stays under ``ratio`` of it for ``hold`` seconds: a warning (once, until the rate recovers) with
  the likely cause -- the line itself (its telegrams' time per cycle at the baud rate), the
  adapter's latency (each reply's mean time beyond its time on the wire, with the latency timer
  read from sysfs where there is one), resends (the share of requests repeated; replies that lose
  their first bytes: an adapter slow to turn around) -- and the fix;
- an adapter that echoes its transmission (the master's ``echoes``): said once, as the adapter's
  echo (the master skips those frames);
- what opening the port found about the adapter (:class:`pyprofibus_vendor.adapter.AdapterSetup`).

:meth:`LineCheck.verdict` is the snapshot for /diagnostics. vr_driver/doc/adapters.md explains
the warning.
"""
from __future__ import annotations

import collections
import logging
from dataclasses import dataclass
from typing import Any, Deque, Mapping, Optional, Sequence, Tuple

from pyprofibus_vendor.adapter import AdapterSetup
from pyprofibus_vendor.dp_master import BusTiming

log = logging.getLogger("vr_driver.driver")

__all__ = ["LineCheck", "LineVerdict", "line_time"]

#: counters the check follows (of pyprofibus_vendor.dp_master.MasterCounters)
_KEYS = ("cycles", "requests", "retries", "timeouts", "dx_timed", "reply_wait", "garbage_bytes", "echoes")
#: a mean reply wait beyond the wire above this [s] is the adapter's (a station answers in < 1 ms)
ADAPTER_WAIT = 0.002
#: a share of requests resent above this is named as a cause
RESEND_SHARE = 0.02


def line_time(baud: int, exchanges: Sequence[Tuple[int, int]]) -> float:
    """[s] the wire time of one bus cycle: per station a Data_Exchange request and reply (SD2, 9
    characters of framing each, ``(outputs, inputs)`` bytes of data), the idle time before each
    request (TSYN, 33 bits) and the station's shortest delay (11 bits)."""
    t = BusTiming.for_baud(baud)
    return sum(t.chars(18 + n_out + n_in) + t.bits(t.tsyn_bits + t.min_tsdr_bits) for n_out, n_in in exchanges)


@dataclass(frozen=True)
class LineVerdict:
    """The line's rate and the adapter, for /diagnostics (a snapshot of :class:`LineCheck`)."""

    asked: float                   # cycle_rate [1/s]
    measured: float                # cycles per second over the window (0: not measured yet)
    line_max: float                # what the telegrams alone allow [1/s]
    reply_wait: Optional[float]    # [s] mean time of a reply beyond the wire, over the window
    resent: float                  # share of requests repeated over the window
    echoes: int                    # the adapter's echoes since the port opened
    slow: bool                     # the rate stays under ratio * asked
    summary: str                   # one line: OK text, or the warning with cause and fix
    adapter: str = ""              # what opening the port found (low-latency mode, latency timer)


class LineCheck:
    """See the module docstring. ``exchanges``: per station cycled, its (outputs, inputs) bytes;
    ``setup``: the port's :class:`~pyprofibus_vendor.adapter.AdapterSetup` (or None)."""

    def __init__(self, baud: int, asked: float, exchanges: Sequence[Tuple[int, int]],
                 setup: Optional[AdapterSetup] = None,
                 window: float = 5.0, hold: float = 5.0, ratio: float = 0.9) -> None:
        self.baud = baud
        self.asked = float(asked)
        self.exchanges = tuple(exchanges)
        self.setup = setup
        self.window = window
        self.hold = hold
        self.ratio = ratio
        self.line_time = line_time(baud, self.exchanges) if self.exchanges else 0.0
        self._samples: Deque[Tuple[float, Tuple[float, ...]]] = collections.deque()
        self._under_since: Optional[float] = None
        self._warned = False
        self._echo_said = 0
        self._garbled_said = False
        self.warnings = 0
        self._verdict = LineVerdict(self.asked, 0.0, self._line_max(), None, 0.0, 0, False,
                                    "not measured yet", self._adapter_words())
        for note in (setup.notes if setup is not None else ()):
            log.info("adapter: %s", note)

    def _line_max(self) -> float:
        return 1.0 / self.line_time if self.line_time > 0 else 0.0

    def _adapter_words(self) -> str:
        return self.setup.describe() if self.setup is not None else ""

    def verdict(self) -> LineVerdict:
        return self._verdict

    def update(self, now: float, counters: Mapping[str, Any], connected: bool = True) -> None:
        """After a bus cycle: the master's counters at ``now``; ``connected``: the controller is in
        Data_Exchange (a rate is judged only then)."""
        values = tuple(float(counters.get(k, 0)) for k in _KEYS)
        samples = self._samples
        samples.append((now, values))
        while len(samples) > 2 and samples[1][0] <= now - self.window:
            samples.popleft()
        echoes = int(values[_KEYS.index("echoes")])
        if echoes and not self._echo_said:
            log.warning("the adapter echoes its transmission (%d frames so far): the driver skips its own "
                        "requests read back (doc/adapters.md, \"Echo\")", echoes)
        self._echo_said = echoes
        t0, first = samples[0]
        span = now - t0
        d = {k: values[i] - first[i] for i, k in enumerate(_KEYS)}
        measured = d["cycles"] / span if span > 0 else 0.0
        wait = d["reply_wait"] / d["dx_timed"] if d["dx_timed"] > 0 else None
        resent = d["retries"] / d["requests"] if d["requests"] > 0 else 0.0
        if not connected:
            self._under_since = None
            self._warned = False
            text = "not in Data_Exchange"
            garbled = self._garbled(resent, d["garbage_bytes"], d["retries"])
            if garbled:
                text += ": " + garbled + " (doc/adapters.md)"
                if not self._garbled_said:
                    self._garbled_said = True
                    log.warning("the controller does not reach Data_Exchange: %s (doc/adapters.md)", garbled)
            self._verdict = LineVerdict(self.asked, measured, self._line_max(), wait, resent, echoes, False,
                                        text, self._adapter_words())
            return
        if span < 0.5 * self.window:
            return
        under = measured < self.ratio * self.asked
        if under:
            if self._under_since is None:
                self._under_since = now
        else:
            if self._warned:
                log.info("the bus is back at %.1f cycles/s (asked %.1f)", measured, self.asked)
            self._under_since = None
            self._warned = False
        slow = under and now - self._under_since >= self.hold
        if slow:
            text = self._warning(measured, wait, resent, d["garbage_bytes"], d["retries"])
            if not self._warned:
                self._warned = True
                self.warnings += 1
                log.warning("%s", text)
        else:
            text = "%.1f cycles/s of %.1f asked" % (measured, self.asked)
            if wait is not None:
                text += ", replies %.1f ms beyond the wire" % (1e3 * wait)
        if echoes:
            text += "; the adapter echoes its transmission (%d frames)" % echoes
        self._verdict = LineVerdict(self.asked, measured, self._line_max(), wait, resent, echoes, slow, text,
                                    self._adapter_words())

    @staticmethod
    def _garbled(resent: float, garbage: float, retries: float) -> str:
        """Resends with garbled replies, in words ("" when there are none)."""
        if not retries or garbage / retries < 1:
            return ""
        return ("%.0f %% of the requests resent, %.0f garbled bytes per resend: replies losing their first "
                "bytes (an adapter slow to turn its receiver on after sending) or noise" % (100 * resent,
                                                                                             garbage / retries))

    def _warning(self, measured: float, wait: Optional[float], resent: float, garbage: float,
                 retries: float) -> str:
        n = len(self.exchanges)
        causes = []
        fixes = []
        line_max = self._line_max()
        if line_max and line_max < self.asked / self.ratio:
            causes.append("the line: at %d bit/s the telegrams of %d station%s take %.0f ms a cycle (at most "
                          "%.1f cycles/s)" % (self.baud, n, "s" if n != 1 else "", 1e3 * self.line_time, line_max))
            fixes.append("cycle_rate %d or less" % max(1, int(0.9 * min(line_max, measured if measured else line_max))))
            if n > 1:
                fixes.append("fewer stations on the line")
            fixes.append("a higher baud rate if every station takes it")
        if wait is not None and wait > ADAPTER_WAIT:
            timer = self.setup.latency_timer_ms if self.setup is not None else None
            causes.append("the USB adapter's latency: each reply reaches the driver %.1f ms (mean) after its time "
                          "on the wire, %s" % (1e3 * wait, "its latency timer is %d ms" % timer if timer is not None
                                               else "the adapter's latency timer (an FTDI's default: 16 ms)"))
            fixes.insert(0, "the adapter's latency timer at 1 ms and low-latency mode (doc/adapters.md)")
        if resent > RESEND_SHARE:
            causes.append(self._garbled(resent, garbage, retries) or "%.0f %% of the requests resent" % (100 * resent))
            fixes.append("the adapter's turnaround and the line's termination (doc/adapters.md)")
        if not causes:
            causes.append("the driver's own time per cycle (%.0f ms of %.0f ms are the wire's)" % (
                1e3 * self.line_time, 1e3 / measured if measured else 0.0))
            fixes.append("a lower cycle_rate")
        return ("the bus runs %.1f cycles/s, under the %.1f asked (cycle_rate): %s. Fix: %s" % (
            measured, self.asked, "; ".join(causes), ", or ".join(fixes)))
