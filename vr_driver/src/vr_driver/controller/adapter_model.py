"""The USB-RS-485 adapter between the PC and the line, as the virtual line models it. ROS-free.

These are behaviours of the adapter, not of the G2 or of PROFIBUS; the virtual line
(:class:`~vr_driver.controller.line.LineHub`, its ``adapter`` option) puts an
:class:`AdapterModel` on the master's side of the line so that tests and benches can run through
them (vr_driver/doc/adapters.md says what real adapters do):

- **latency timer** (``latency_ms``): bytes from the line to the PC are held in the adapter and
  handed over in a burst when its timer expires (a free-running timer of that period, as an FTDI
  chip's that restarts with each USB packet) or when a USB packet is full (``packet`` bytes: 62 of
  an FT232R's 64, two being status). 0: every byte at once.
- **echo** (``echo``): the adapter's receiver stays on while it transmits, so the PC reads its own
  transmission back, each byte once it is on the line, before the reply.
- **slow turnaround** (``turnaround_ms``): after the master's transmission the adapter's receiver
  (an auto-direction adapter switching its driver off) is deaf this long: every byte a station
  puts on the line before then is lost -- the first bytes of a prompt reply.

:class:`AdapterModel` is clocked by its caller (the hub), so it is stepped deterministically in
tests: :meth:`~AdapterModel.sent` (the master's transmission ends on the line at ``end``),
:meth:`~AdapterModel.heard` (a station's bytes begin on the line at ``start``: what the receiver
keeps), :meth:`~AdapterModel.hold` (bytes for the PC), :meth:`~AdapterModel.due` (what the adapter
hands to the PC now) and :meth:`~AdapterModel.next_due`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

__all__ = ["AdapterBehaviour", "AdapterCounters", "AdapterModel"]


@dataclass(frozen=True)
class AdapterBehaviour:
    """See the module docstring. Raises ValueError for a value out of range."""

    latency_ms: float = 0.0
    echo: bool = False
    turnaround_ms: float = 0.0
    packet: int = 62

    def __post_init__(self) -> None:
        if not 0.0 <= self.latency_ms <= 255.0:
            raise ValueError("adapter latency_ms %r outside 0..255 (an FTDI timer's range)" % (self.latency_ms,))
        if not 0.0 <= self.turnaround_ms <= 100.0:
            raise ValueError("adapter turnaround_ms %r outside 0..100" % (self.turnaround_ms,))
        if not 1 <= self.packet <= 4096:
            raise ValueError("adapter packet %r outside 1..4096" % (self.packet,))

    @property
    def active(self) -> bool:
        """The adapter changes anything (else the line needs no model)."""
        return self.latency_ms > 0 or self.echo or self.turnaround_ms > 0

    def describe(self) -> str:
        parts = ["latency timer %g ms" % self.latency_ms if self.latency_ms else "no latency timer"]
        parts.append("echo" if self.echo else "no echo")
        if self.turnaround_ms:
            parts.append("receiver deaf %g ms after sending" % self.turnaround_ms)
        return ", ".join(parts)


@dataclass
class AdapterCounters:
    echoed: int = 0          # bytes of the master's transmission read back to it
    lost: int = 0            # station bytes lost in the turnaround
    bursts: int = 0          # hand-overs to the PC
    held: int = 0            # bytes that went through the latency timer


class AdapterModel:
    """See the module docstring; times are the caller's clock [s]."""

    def __init__(self, behaviour: AdapterBehaviour) -> None:
        self.behaviour = behaviour
        self.counters = AdapterCounters()
        self._period = behaviour.latency_ms / 1000.0
        self._deaf_until = -math.inf
        self._buf = bytearray()
        self._flush_at: Optional[float] = None

    def sent(self, data: bytes, end: float) -> Optional[bytes]:
        """The master's ``data`` is on the line until ``end``: the receiver is deaf until ``end``
        plus the turnaround. Returns the echo (for the PC at ``end``) or None."""
        self._deaf_until = end + self.behaviour.turnaround_ms / 1000.0
        if self.behaviour.echo and data:
            self.counters.echoed += len(data)
            return bytes(data)
        return None

    def heard(self, data: bytes, start: float, char_time: float) -> bytes:
        """A station's ``data`` begins on the line at ``start``, a character every ``char_time``:
        the bytes the receiver keeps (those begun before it listens again are lost)."""
        if start >= self._deaf_until or not data:
            return data
        lost = len(data) if char_time <= 0 else min(len(data), int(math.ceil((self._deaf_until - start) / char_time)))
        self.counters.lost += lost
        return data[lost:]

    def hold(self, data: bytes, now: float) -> bytes:
        """Bytes for the PC arrive in the adapter at ``now``; returns what it hands over at once
        (no timer, or full USB packets)."""
        self.counters.held += len(data)
        if self._period <= 0:
            self.counters.bursts += 1
            return bytes(data)
        self._buf += data
        if self._flush_at is None:
            self._flush_at = math.floor(now / self._period) * self._period + self._period
        packet = self.behaviour.packet
        if len(self._buf) >= packet:
            n = len(self._buf) - len(self._buf) % packet
            out, self._buf[:] = bytes(self._buf[:n]), self._buf[n:]
            self.counters.bursts += 1
            if not self._buf:
                self._flush_at = None
            return out
        return b""

    def due(self, now: float) -> bytes:
        """What the adapter hands to the PC at ``now`` (its timer expired)."""
        if self._flush_at is None or now < self._flush_at or not self._buf:
            return b""
        out = bytes(self._buf)
        self._buf.clear()
        self._flush_at = None
        self.counters.bursts += 1
        return out

    def next_due(self) -> Optional[float]:
        """When the held bytes go to the PC (None: nothing held)."""
        return self._flush_at if self._buf else None
