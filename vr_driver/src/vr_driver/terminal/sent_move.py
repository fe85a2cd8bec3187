"""A move the pose terminal has sent, until it ends, ROS-free: the handle a backend returns for it
(:class:`MoveHandle`, its :class:`MoveProgress` and :class:`MoveResult`), its progress on the screen
(:class:`ProgressPrinter`) and its watch (:class:`MoveWatch`): Ctrl-C and a move without a result
in time stop the arm (the goal cancelled, then stop_motion when that is not enough), and how it
ended is said in words.

The dialogue that previews, confirms and sends the move is
:class:`vr_driver.terminal.pose_input.Terminal`.
"""
from __future__ import annotations

import math
import signal
import time
from dataclasses import dataclass
from typing import Callable, Optional, TextIO

from ..poses import ControllerPose
from .pose_text import fmt_pose

__all__ = ["MoveProgress", "MoveResult", "MoveHandle", "ProgressPrinter", "MoveEnd", "MoveWatch", "ctrl_c_raises"]


@dataclass(frozen=True)
class MoveProgress:
    phase: str                                        # validating, preview, sending, moving, stopping
    distance_to_go: float = 0.0                       # mm
    angle_to_go: float = 0.0                          # deg
    current: Optional[ControllerPose] = None


@dataclass(frozen=True)
class MoveResult:
    outcome: str                                      # "succeeded", "cancelled" or "failed"
    reason: str = ""
    reached: Optional[ControllerPose] = None


class MoveHandle:
    """A move on its way (returned by Backend.start_move)."""

    def wait(self, timeout: float) -> bool:
        """Block up to ``timeout`` s; True once the move has ended."""
        raise NotImplementedError

    def progress(self) -> Optional[MoveProgress]:
        raise NotImplementedError

    def cancel(self) -> None:
        """Ask the driver to stop this move (the arm stops)."""
        raise NotImplementedError

    def result(self) -> MoveResult:
        raise NotImplementedError


# ------------------------------------------------------------------------------------ progress

class ProgressPrinter:
    """Shows a move's progress: one line per phase; on a terminal the line is updated in place."""

    def __init__(self, out: TextIO, tty: bool, period: float = 1.0,
                 clock: Callable[[], float] = time.monotonic):
        self.out = out
        self.tty = tty
        self.period = period
        self.clock = clock
        self._phase: Optional[str] = None
        self._width = 0
        self._last_print = -math.inf
        self._open = False
        self._text = ""

    @staticmethod
    def line(p: MoveProgress) -> str:
        if p.phase in ("moving", "stopping", "sending"):
            return "  %-8s distance to go %7.1f mm, angle to go %5.1f deg" % (p.phase, p.distance_to_go,
                                                                              p.angle_to_go)
        return "  %s" % p.phase

    def update(self, p: MoveProgress) -> None:
        text = self.line(p)
        now = self.clock()
        if self.tty:
            if p.phase != self._phase:
                self._newline()
            elif text == self._text:
                return
            pad = max(0, self._width - len(text))
            self.out.write("\r" + text + " " * pad)
            self._width = len(text)
            self._text = text
            self._open = True
        elif p.phase != self._phase or now - self._last_print >= self.period:
            self.out.write(text + "\n")
            self._last_print = now
        self._phase = p.phase
        self.out.flush()

    def _newline(self) -> None:
        if self._open:
            self.out.write("\n")
            self._open = False
            self._width = 0
            self._text = ""

    def finish(self) -> None:
        self._newline()
        self.out.flush()


# ------------------------------------------------------------------------------------ watch

@dataclass(frozen=True)
class MoveEnd:
    """How a watched move ended: ``reached`` its target or not; ``answered``: the driver gave its
    result in time (False: none within the timeout); ``outcome``: the words for the history."""

    reached: bool
    answered: bool
    outcome: str


def ctrl_c_raises() -> None:
    """Ctrl-C raises KeyboardInterrupt in this process (call it from the main thread), whatever the
    process inherited: one started with SIGINT ignored (a script's background job, ``nohup``, a CI
    runner) keeps it ignored, Python then installs no handler -- and a terminal's promise "Ctrl-C
    stops the arm" (:class:`MoveWatch`) would silently fail: a fresh-clone test run saw three moves
    in a row run to their end through the test's Ctrl-Cs."""
    signal.signal(signal.SIGINT, signal.default_int_handler)


@dataclass
class MoveWatch:
    """One sent move seen to its end: its progress on ``printer`` every ``poll_period`` s; on Ctrl-C
    or when it has no result after ``timeout`` s, the goal cancelled and, when the move has not
    ended after half of ``stop_wait`` (or on a second Ctrl-C), ``call_stop`` (stop_motion) as well;
    how it ended said with ``say``."""

    handle: MoveHandle
    printer: ProgressPrinter
    say: Callable[[str], None]
    call_stop: Callable[[], None]
    clock: Callable[[], float] = time.monotonic
    poll_period: float = 0.1
    stop_wait: float = 10.0

    def follow(self, target: Optional[ControllerPose], started: float, timeout: float) -> MoveEnd:
        """Until the move ends (or ``timeout`` s after ``started``, the clock's time it was sent);
        ``target``: where it goes (the distance to it is said when it is reached)."""
        handle, printer = self.handle, self.printer
        timed_out = False
        try:
            while not handle.wait(self.poll_period):
                progress = handle.progress()
                if progress is not None:
                    printer.update(progress)
                if self.clock() - started > timeout:
                    timed_out = True
                    break
            progress = handle.progress()          # the last word: how far it got
            if progress is not None:
                printer.update(progress)
        except KeyboardInterrupt:
            printer.finish()
            self.say("Ctrl-C: stopping the arm ...")
            self.stop()
        printer.finish()
        if timed_out:
            self.say("No result from the driver within %.0f s: stopping the move." % timeout)
            ended = self.stop()
            result = handle.result() if ended else None
            where = fmt_pose(result.reached) if result is not None and result.reached is not None else "unknown"
            self.say("The move %s; the arm is at %s." % ("was stopped" if ended else "did not end", where))
            return MoveEnd(reached=False, answered=False, outcome="no result in time")
        result = handle.result()
        elapsed = self.clock() - started
        where = fmt_pose(result.reached) if result.reached is not None else "unknown"
        if result.outcome == "succeeded":
            off = ""
            if result.reached is not None and target is not None:
                dp, da = result.reached.distance_to(target)
                off = " (%.1f mm, %.1f deg from the target)" % (dp, da)
            self.say("Reached %s%s in %.1f s." % (where, off, elapsed))
            return MoveEnd(reached=True, answered=True, outcome="reached")
        if result.outcome == "cancelled":
            self.say("Stopped at %s: %s" % (where, result.reason or "cancelled"))
            return MoveEnd(False, True, "stopped at %s (at rest): %s" % (where, result.reason or "cancelled"))
        self.say("Failed: %s; the arm is at %s" % (result.reason or "no reason given", where))
        return MoveEnd(False, True, "failed at %s: %s" % (where, result.reason or "no reason given"))

    def stop(self) -> bool:
        """Cancel the goal; when the driver has not ended it after half of ``stop_wait`` (or on a
        second Ctrl-C), call stop_motion as well. True once the move has ended."""
        handle = self.handle
        handle.cancel()
        now = self.clock()
        escalate, end = now + self.stop_wait / 2.0, now + self.stop_wait
        stop_sent = False
        while True:
            try:
                if handle.wait(self.poll_period):
                    return True
            except KeyboardInterrupt:
                if not stop_sent:
                    self.say("Ctrl-C again: calling stop_motion ...")
                    self.call_stop()
                    stop_sent = True
                continue
            now = self.clock()
            if not stop_sent and now >= escalate:
                self.say("The move has not ended yet: calling stop_motion ...")
                self.call_stop()
                stop_sent = True
            if now >= end:
                return False
