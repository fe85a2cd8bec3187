"""The stepped world on a paced line: every telegram takes its time on the wire at the bus's bit rate
(11 bits a character, one direction at a time, as controller.line's hub paces the virtual line), and
each bus cycle also carries the I/O island's exchange -- the thesis' USB-RS-485 line at 19.2 kbit/s
with the island beside the controller, as ``bench/trajectory.py``'s "paced" configurations run it,
but on the fake clock, in one thread.

While a telegram is on the wire the controller's program keeps looping (:meth:`PacedWorld.advance`
runs the loops that fall due), so the program takes a target within a loop of the end of the
request that carried it and the reply carries the record its last loop wrote -- as on the real line,
where the card answers at once with what the program last wrote.
"""
from __future__ import annotations

from typing import Any, Optional

from _world import SteppedLink, World

#: bits per character on the line (start, 8 data, parity, stop)
BITS_PER_CHAR = 11
#: characters of the I/O island's Data_Exchange each cycle, request and reply (2 bytes of outputs
#: out, 2 of inputs back, each framed: SD2 LE LEr SD2 DA SA FC ... FCS ED)
ISLAND_CHARS = (9 + 2) + (9 + 2)


class PacedLink(SteppedLink):
    """A :class:`SteppedLink` whose telegrams take their wire time at ``baud``; ``island_chars``
    more characters per exchange (the island's, on the same line). ``world.advance(t)`` moves the
    clock, running the controller's program loops that fall due."""

    def __init__(self, slave: Any, world: "PacedWorld", baud: int, island_chars: int = ISLAND_CHARS) -> None:
        super().__init__(slave, world.clock)
        self.world = world
        self.char_time = BITS_PER_CHAR / float(baud)
        self.island_time = island_chars * self.char_time
        self._ready_at = 0.0              # the reply's last character arrives then

    def send(self, data: bytes) -> None:
        if self._ready_at:                # the island's turn on the line since the last reply
            self.world.advance(max(self.clock.t, self._ready_at + self.island_time))
        self.world.advance(self.clock.t + len(data) * self.char_time)
        before = len(self._rx)
        super().send(data)
        reply = len(self._rx) - before
        self._ready_at = self.clock.t + reply * self.char_time

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        if self._rx and self.clock.t < self._ready_at:
            self.world.advance(self._ready_at)
        return super().recv(max_bytes, timeout)


class PacedWorld(World):
    """:class:`World` on a :class:`PacedLink` at the driver's ``baud`` (WORLD_PARAMS: 19 200)."""

    def __init__(self, kin, params=None, *, island_chars: int = ISLAND_CHARS, **kw) -> None:
        super().__init__(kin, params, **kw)
        self.link = PacedLink(self.slave, self, self.params.baud, island_chars)

    def advance(self, until: float) -> None:
        """Move the clock to ``until``, running the program loops due on the way."""
        while self.next_loop <= until:
            if self.next_loop > self.clock.t:
                self.clock.t = self.next_loop
            self.program.step(self.clock.t)
            self.next_loop += self.loop_period
        if until > self.clock.t:
            self.clock.t = until
