"""Shared test helpers: a fake clock, a scripted link, the robot's constants."""
from __future__ import annotations

from typing import Callable, List, Optional

from pyprofibus_vendor.fdl import Deframer, Frame
from pyprofibus_vendor.phy import Link
from pyprofibus_vendor.errors import PhyError

ROBOT_IDENT = 0x06C6
ROBOT_CFG = bytes.fromhex("13 13 13 11 23 23 23 21")   # 4In x3, 2In, 4Out x3, 2Out
ROBOT_BYTES = 14
MASTER = 2
SLAVE = 4


class FakeClock:
    """An injectable monotonic clock that only moves when told to."""

    def __init__(self, start: float = 1000.0) -> None:
        self.t = start

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> float:
        self.t += dt
        return self.t


def transform(outputs: bytes) -> bytes:
    """What the echo slave of the tests returns as inputs for given outputs."""
    return bytes((b ^ 0xA5) for b in outputs)


class ScriptedLink(Link):
    """A thread-free link whose far end is a Python function.

    Every complete frame sent is recorded in ``sent`` and passed to
    ``respond(frame)``; the returned bytes (if any) become readable.
    """

    def __init__(self, respond: Callable[[Frame], Optional[bytes]]) -> None:
        self.respond = respond
        self.sent: List[Frame] = []
        self.deframer = Deframer()
        self._rx = bytearray()
        self._closed = False

    def send(self, data: bytes) -> None:
        if self._closed:
            raise PhyError("closed")
        for frame in self.deframer.feed(data):
            self.sent.append(frame)
            reply = self.respond(frame)
            if reply:
                self._rx += reply

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        if self._closed:
            raise PhyError("closed")
        out = bytes(self._rx[:max_bytes])
        del self._rx[:max_bytes]
        return out

    def flush_input(self) -> None:
        self._rx.clear()

    def close(self) -> None:
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed
