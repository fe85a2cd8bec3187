"""Shared test helpers: a fake clock, a scripted link, the robot's constants."""
from __future__ import annotations

from typing import Callable, List, Optional

from pyprofibus_vendor.fdl import Frame, RespondingLink

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


class ScriptedLink(RespondingLink):
    """A thread-free link whose far end is a Python function.

    Every complete frame sent is recorded in ``sent`` and passed to
    ``respond(frame)``; the returned bytes (if any) become readable.
    """

    def __init__(self, respond: Callable[[Frame], Optional[bytes]]) -> None:
        super().__init__("scripted link")
        self._respond = respond
        self.sent: List[Frame] = []

    def respond(self, frame: Frame) -> Optional[bytes]:
        self.sent.append(frame)
        return self._respond(frame)


