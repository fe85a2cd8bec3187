"""The pose terminal's watch of a sent move (vr_driver.terminal.sent_move.MoveWatch), stepped with a
fake clock in one thread: each wait of the handle advances the clock by its timeout."""
from __future__ import annotations

import io
import os
import signal
import subprocess
import sys

from vr_driver.poses import ControllerPose
from vr_driver.terminal.sent_move import (MoveEnd, MoveHandle, MoveProgress, MoveResult, MoveWatch,
                                          ProgressPrinter)

TARGET = ControllerPose(1000, 0, 800, 0, 45, 0)


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class Handle(MoveHandle):
    """Ends after ``waits`` waits (None: never; ``ends_on_stop``: once stop_motion was called) with
    ``result``; each wait advances ``clock`` by its timeout."""

    def __init__(self, clock, waits=None, result=None, ends_on_stop=False):
        self.clock, self.waits, self.ends_on_stop = clock, waits, ends_on_stop
        self.result_ = result or MoveResult("succeeded", "", TARGET)
        self.n = 0
        self.cancelled_at = None
        self.stopped = False

    def wait(self, timeout):
        self.n += 1
        self.clock.now += timeout
        return (self.waits is not None and self.n >= self.waits) or (self.ends_on_stop and self.stopped)

    def progress(self):
        return MoveProgress("moving", 10.0, 0.0)

    def cancel(self):
        self.cancelled_at = self.clock.now

    def result(self):
        return self.result_


def watch(handle, clock, stop_wait=2.0):
    said, stops = [], []

    def call_stop():
        stops.append(clock.now)
        handle.stopped = True
    w = MoveWatch(handle, ProgressPrinter(io.StringIO(), tty=False, clock=clock), said.append, call_stop,
                  clock=clock, poll_period=0.1, stop_wait=stop_wait)
    return w, said, stops


def test_a_reached_move_says_how_far_from_the_target_and_how_long():
    clock = Clock()
    handle = Handle(clock, waits=5, result=MoveResult("succeeded", "", ControllerPose(1001, 0, 800, 0, 45, 0)))
    w, said, stops = watch(handle, clock)
    assert w.follow(TARGET, 0.0, timeout=10.0) == MoveEnd(reached=True, answered=True, outcome="reached")
    assert said == ["Reached X 1001  Y 0  Z 800  Rx 0  Ry 45  Rz 0 (1.0 mm, 0.0 deg from the target) in 0.5 s."]
    assert handle.cancelled_at is None and stops == []


def test_a_failed_move_is_answered_but_not_reached():
    clock = Clock()
    handle = Handle(clock, waits=2, result=MoveResult("failed", "the controller rejected the target", None))
    w, said, _ = watch(handle, clock)
    end = w.follow(TARGET, 0.0, timeout=10.0)
    assert end == MoveEnd(False, True, "failed at unknown: the controller rejected the target")
    assert said == ["Failed: the controller rejected the target; the arm is at unknown"]


def test_no_result_in_time_cancels_then_calls_stop_motion_at_half_the_stop_wait():
    clock = Clock()
    handle = Handle(clock, ends_on_stop=True,
                    result=MoveResult("cancelled", "stopped", ControllerPose(1050, 0, 750, 0, 45, 0)))
    w, said, stops = watch(handle, clock, stop_wait=2.0)
    end = w.follow(TARGET, 0.0, timeout=1.0)
    assert end == MoveEnd(reached=False, answered=False, outcome="no result in time")
    assert 1.0 < handle.cancelled_at < 1.0 + 0.2          # at the first poll past the timeout
    assert len(stops) == 1 and handle.cancelled_at + 1.0 <= stops[0] < handle.cancelled_at + 1.0 + 0.2
    assert said[0] == "No result from the driver within 1 s: stopping the move."
    assert said[-1] == "The move was stopped; the arm is at X 1050  Y 0  Z 750  Rx 0  Ry 45  Rz 0."


def test_a_move_that_does_not_end_even_after_stop_motion_is_said_so():
    clock = Clock()
    handle = Handle(clock)                                 # never ends
    w, said, stops = watch(handle, clock, stop_wait=2.0)
    assert w.follow(TARGET, 0.0, timeout=1.0).answered is False
    assert len(stops) == 1
    assert handle.cancelled_at + 2.0 <= clock.now < handle.cancelled_at + 2.0 + 0.2   # gave up at stop_wait
    assert said[-1] == "The move did not end; the arm is at unknown."


# ------------------------------------------------------------------ Ctrl-C, whatever was inherited

_SIGINT_PROBE = """
import os, signal, sys
from vr_driver.terminal.sent_move import ctrl_c_raises
print("inherited", "ignored" if signal.getsignal(signal.SIGINT) == signal.SIG_IGN else "other")
if sys.argv[1] == "fix":
    ctrl_c_raises()
try:
    os.kill(os.getpid(), signal.SIGINT)
    for _ in range(100000):          # a handler runs between two bytecodes: long before this ends
        pass
    print("Ctrl-C did nothing")
except KeyboardInterrupt:
    print("Ctrl-C raised")
"""


def _ignoring_sigint():
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def test_ctrl_c_raises_in_a_process_started_with_sigint_ignored():
    """A process started with SIGINT ignored (a script's background job, a CI runner) keeps it
    ignored: without ctrl_c_raises() the terminal's Ctrl-C would do nothing during a move (a
    fresh-clone run saw three moves run to their end through the test's Ctrl-Cs)."""
    out = {}
    for mode in ("fix", "without"):
        res = subprocess.run([sys.executable, "-c", _SIGINT_PROBE, mode], capture_output=True, text=True,
                             timeout=60, preexec_fn=_ignoring_sigint, env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
        assert res.returncode == 0, res.stderr
        out[mode] = res.stdout.split("\n")
    assert out["fix"][:2] == ["inherited ignored", "Ctrl-C raised"], out
    assert out["without"][:2] == ["inherited ignored", "Ctrl-C did nothing"], out       # the probe can fail


def test_the_pose_terminal_takes_ctrl_c_when_started_with_sigint_ignored():
    """The node itself: started with SIGINT ignored and no ROS master, it waits for one; a Ctrl-C
    (SIGINT) then ends the wait with the shell's 130, long before its --wait runs out."""
    node = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "nodes", "pose_terminal")
    proc = subprocess.Popen([sys.executable, node, "--pose", "1000", "0", "800", "0", "45", "0", "--wait", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, preexec_fn=_ignoring_sigint,
                            env=dict(os.environ, ROS_MASTER_URI="http://localhost:9",
                                     PYTHONPATH=os.pathsep.join(sys.path)))
    try:
        first = proc.stdout.readline()                      # said once it waits (the event awaited)
        assert "Waiting for the ROS master" in first, first
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, first + rest
    assert "Interrupted while waiting for the driver" in rest
