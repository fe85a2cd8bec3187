"""PHY layer: the abstract byte link and two in-process implementations.

A *link* moves raw bytes between two stations; it knows nothing about frames.
Everything above it (FDL deframing, DP services, the master and slave state
machines) talks to a link only through :class:`Link`::

    send(data)                 write all bytes (raises PhyError when the link failed)
    recv(max_bytes, timeout)   up to max_bytes; blocks at most ``timeout`` seconds
                               (``0`` polls, ``None`` waits for ever); ``b""`` on timeout
    flush_input()              discard everything received but not yet read
    close()                    release the link; later calls raise PhyError

Implementations here:

* :class:`MemoryLink` -- one end of an in-memory, thread-safe byte pipe pair
  (``a, b = MemoryLink.pair()``); reads block on a ``threading.Condition``.
* :class:`FaultyLink` -- wraps any link and drops, corrupts or delays bytes with
  given probabilities (seeded ``random.Random``), and can :meth:`FaultyLink.cut`
  / :meth:`FaultyLink.restore` the line; :class:`FaultCounters` says what it did.

The serial and raw-fd links live in :mod:`pyprofibus_vendor.phy_serial`.
"""
from __future__ import annotations

import logging
import random
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, List, Optional, Tuple

from .errors import PhyError

if TYPE_CHECKING:
    from .adapter import AdapterSetup

__all__ = ["Link", "MemoryLink", "FaultyLink", "FaultCounters"]

log = logging.getLogger(__name__)

Clock = Callable[[], float]


class Link(ABC):
    """An abstract, bidirectional byte link (one end of a serial line)."""

    #: the USB adapter under the port, where the link knows it (SerialLink; pyprofibus_vendor.adapter)
    adapter: Optional["AdapterSetup"] = None

    @abstractmethod
    def send(self, data: bytes) -> None:
        """Transmit all of ``data``. Raises :class:`PhyError` if the link failed."""

    @abstractmethod
    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        """Return up to ``max_bytes`` received bytes.

        Blocks (without spinning) until at least one byte is there or ``timeout``
        seconds passed; returns ``b""`` on timeout. ``timeout=None`` waits for ever.
        """

    def flush_input(self) -> None:
        """Discard all received, unread bytes."""
        while self.recv(4096, 0.0):
            pass

    @abstractmethod
    def close(self) -> None:
        """Close the link. Idempotent."""

    @property
    @abstractmethod
    def closed(self) -> bool:
        """True once :meth:`close` was called (or the link failed for good)."""

    def __enter__(self) -> "Link":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Pipe:
    """One direction of a memory link: a byte buffer with a condition."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.buf = bytearray()
        self.writer_closed = False


class MemoryLink(Link):
    """One end of an in-memory byte link pair. Thread-safe.

    ``send`` on one end appends to the other end's receive buffer and wakes a
    reader blocked in ``recv``. Closing either end makes the other end's
    ``send`` fail and its ``recv`` fail once the remaining bytes are read
    (like a pty whose peer went away).
    """

    def __init__(self, rx: _Pipe, tx: _Pipe, name: str = "mem") -> None:
        self._rx = rx
        self._tx = tx
        self._closed = False
        self.name = name

    @classmethod
    def pair(cls) -> Tuple["MemoryLink", "MemoryLink"]:
        """Return two connected ends ``(a, b)``: what ``a`` sends, ``b`` receives."""
        ab, ba = _Pipe(), _Pipe()
        return cls(rx=ba, tx=ab, name="mem-a"), cls(rx=ab, tx=ba, name="mem-b")

    def send(self, data: bytes) -> None:
        if self._closed:
            raise PhyError(f"{self.name}: send on a closed link")
        with self._tx.cond:
            if self._rx.writer_closed:  # the peer closed its end
                raise PhyError(f"{self.name}: peer closed the link")
            self._tx.buf += data
            self._tx.cond.notify_all()

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        if self._closed:
            raise PhyError(f"{self.name}: recv on a closed link")
        deadline = None if timeout is None else time.monotonic() + max(0.0, timeout)
        with self._rx.cond:
            while not self._rx.buf:
                if self._rx.writer_closed:
                    raise PhyError(f"{self.name}: peer closed the link")
                if self._closed:
                    raise PhyError(f"{self.name}: link closed while reading")
                if deadline is None:
                    self._rx.cond.wait()
                else:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        return b""
                    self._rx.cond.wait(left)
            out = bytes(self._rx.buf[:max_bytes])
            del self._rx.buf[:max_bytes]
            return out

    def flush_input(self) -> None:
        if self._closed:
            raise PhyError(f"{self.name}: flush on a closed link")
        with self._rx.cond:
            self._rx.buf.clear()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for pipe in (self._tx, self._rx):
            with pipe.cond:
                if pipe is self._tx:
                    pipe.writer_closed = True
                pipe.cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed


@dataclass
class FaultCounters:
    """What a :class:`FaultyLink` did so far (bytes, in both directions)."""

    bytes_sent: int = 0        # bytes handed to send() by the user
    bytes_received: int = 0    # bytes returned by recv() to the user
    dropped: int = 0
    corrupted: int = 0
    parity_drops: int = 0      # corrupted characters discarded by the emulated parity check
    delayed: int = 0
    cut_discarded: int = 0     # bytes swallowed while the link was cut
    cuts: int = 0


class FaultyLink(Link):
    """Fault-injecting wrapper around any :class:`Link`.

    Every byte passing through (both directions) is independently

    * dropped with probability ``drop``,
    * corrupted with probability ``corrupt``: XOR with a random non-zero mask,
      or, with ``bit_errors=k``, flip exactly k distinct bits (line noise),
    * delayed with probability ``delay`` by ``delay_s`` seconds (receive
      direction only: the byte and everything after it are held back, so the
      order is kept and no thread is needed).

    ``parity=True`` emulates the receiving UART of an 8E1 line with parity
    checking (what :class:`~.phy_serial.SerialLink` enables on real ports): a
    corrupted character whose error pattern flips an odd number of bits fails
    the parity check and is discarded (``parity_drops``); even-weight errors
    pass and must be caught by the FDL checks. Without it (a pty, a socket)
    only the 8-bit FCS protects the data, which misses about 1 in 256
    multi-byte corruptions.

    ``directions`` selects where drop/corrupt apply: ``"both"``, ``"tx"`` or ``"rx"``.
    While :meth:`cut` is in effect nothing passes in either direction: sent
    bytes vanish and received bytes are read from the inner link and discarded.
    The random generator is ``random.Random(seed)`` unless ``rng`` is given; the
    clock (for delays) is injectable.
    """

    def __init__(
        self,
        inner: Link,
        drop: float = 0.0,
        corrupt: float = 0.0,
        delay: float = 0.0,
        delay_s: float = 0.05,
        seed: int = 0,
        rng: Optional[random.Random] = None,
        directions: str = "both",
        clock: Clock = time.monotonic,
        bit_errors: Optional[int] = None,
        parity: bool = False,
    ) -> None:
        for name, p in (("drop", drop), ("corrupt", corrupt), ("delay", delay)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} probability {p} not in [0, 1]")
        if bit_errors is not None and not 1 <= bit_errors <= 8:
            raise ValueError(f"bit_errors {bit_errors} not in 1..8")
        if directions not in ("both", "tx", "rx"):
            raise ValueError(f"directions must be 'both', 'tx' or 'rx', not {directions!r}")
        self.inner = inner
        self.drop = drop
        self.corrupt = corrupt
        self.delay = delay
        self.delay_s = delay_s
        self.directions = directions
        self.bit_errors = bit_errors
        self.parity = parity
        self.rng = rng if rng is not None else random.Random(seed)
        self.clock = clock
        self.counters = FaultCounters()
        self._cut = False
        self._lock = threading.Lock()
        self._held: List[Tuple[float, int]] = []  # (due time, byte) in arrival order

    # -- control ---------------------------------------------------------------
    def cut(self) -> None:
        """Interrupt the line: nothing passes either way until :meth:`restore`."""
        with self._lock:
            if not self._cut:
                self._cut = True
                self.counters.cuts += 1
                self._held.clear()
        log.info("fault link: line cut")

    def restore(self) -> None:
        """Reconnect the line after :meth:`cut`."""
        with self._lock:
            self._cut = False
        log.info("fault link: line restored")

    @property
    def is_cut(self) -> bool:
        return self._cut

    # -- byte mangling -----------------------------------------------------------
    def _mangle(self, data: bytes) -> bytes:
        out = bytearray()
        for byte in data:
            if self.drop and self.rng.random() < self.drop:
                self.counters.dropped += 1
                continue
            if self.corrupt and self.rng.random() < self.corrupt:
                if self.bit_errors is None:
                    mask = self.rng.randrange(1, 256)
                else:
                    mask = sum(1 << b for b in self.rng.sample(range(8), self.bit_errors))
                self.counters.corrupted += 1
                if self.parity and bin(mask).count("1") % 2:
                    self.counters.parity_drops += 1
                    continue
                byte ^= mask
            out.append(byte)
        return bytes(out)

    # -- Link API ------------------------------------------------------------------
    def send(self, data: bytes) -> None:
        with self._lock:
            self.counters.bytes_sent += len(data)
            if self._cut:
                self.counters.cut_discarded += len(data)
                return
            if self.directions in ("both", "tx"):
                data = self._mangle(data)
        if data:
            self.inner.send(data)

    def _take_due(self, max_bytes: int, now: float) -> bytes:
        out = bytearray()
        while self._held and len(out) < max_bytes and self._held[0][0] <= now:
            out.append(self._held.pop(0)[1])
        return bytes(out)

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        """As :meth:`Link.recv`; may return ``b""`` early when every byte that
        arrived was dropped, cut away or is still held back by a delay."""
        now = self.clock()
        with self._lock:
            due = self._take_due(max_bytes, now)
            next_due = self._held[0][0] if self._held else None
        if due:
            self.counters.bytes_received += len(due)
            return due
        wait = timeout
        if next_due is not None:
            until = max(0.0, next_due - now)
            wait = until if wait is None else min(wait, until)
        raw = self.inner.recv(max_bytes, wait)
        with self._lock:
            if raw:
                if self._cut:
                    self.counters.cut_discarded += len(raw)
                    raw = b""
                elif self.directions in ("both", "rx"):
                    raw = self._mangle(raw)
                if raw:
                    self._hold(raw, self.clock())
            due = self._take_due(max_bytes, self.clock())
            self.counters.bytes_received += len(due)
        return due

    def _hold(self, raw: bytes, now: float) -> None:
        """Queue received bytes; each may be delayed (keeping the order)."""
        floor = self._held[-1][0] if self._held else now
        for byte in raw:
            due = max(now, floor)
            if self.delay and self.rng.random() < self.delay:
                due += self.delay_s
                self.counters.delayed += 1
            floor = due
            self._held.append((due, byte))

    def flush_input(self) -> None:
        with self._lock:
            self._held.clear()
        self.inner.flush_input()

    def close(self) -> None:
        self.inner.close()

    @property
    def closed(self) -> bool:
        return self.inner.closed
