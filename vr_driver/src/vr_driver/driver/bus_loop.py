"""The bus loop (ROS-free): one bus iteration (:meth:`BusLoop.spin_once`) steps the parts -- the
link runs a DP cycle and returns a sample, the arm's joints are read from it, the sequencer decides
what to send -- and publishes an immutable :class:`~vr_driver.driver.motion.status.DriverStatus` snapshot
to the listeners. :meth:`BusLoop.start` runs that iteration at ``cycle_rate`` in the bus thread;
stepped tests call :meth:`spin_once` and :meth:`next_cycle` themselves with a fake clock.

What :meth:`BusLoop.status` returns is never older than ``link_timeout``: a snapshot or a feedback
record older than that reads as a lost link (no pose, no joints, in error).
"""
from __future__ import annotations

import logging
import math
import threading
from dataclasses import replace
from typing import Callable, List, Optional

from ..params import DriverParams
from ..protocol.base import Protocol
from ..protocol.common import StatusBits
from .joints.arm_joints import ArmJoints
from .link.link import ERROR_CONTROLLER, ERROR_LINK, ERROR_NONE, LinkSample, LinkSupervisor
from .own_thread import OwnThread
from .motion.sequencer import SequencerBase
from .link.stations import ControllerIo, IoLine
from .motion.status import DriverStatus

log = logging.getLogger("vr_driver.driver")

__all__ = ["BusLoop", "END_POLL_PERIOD"]

#: s: the bus period while a stream's end is due (StreamSequencer.end_due)
END_POLL_PERIOD = 0.01


class BusLoop(OwnThread):
    """The bus thread of one driver and what it publishes (module docstring). ``stop``: the
    driver's stop event (shared with the planning thread)."""

    thread_name = "vr_driver-bus"

    def __init__(self, params: DriverParams, clock: Callable[[], float], cycle_rate_hz: float,
                 link: LinkSupervisor, sequencer: SequencerBase, wire: Protocol, arm: ArmJoints,
                 io: Optional[IoLine], controller_io: Optional[ControllerIo], stop: threading.Event) -> None:
        self.params = params
        self.clock = clock
        self.cycle_rate_hz = cycle_rate_hz
        self.link = link
        self.sequencer = sequencer
        self.wire = wire
        self.arm = arm
        self.io = io
        self.controller_io = controller_io
        self._stop = stop
        # set by requests (their inbox's): run a bus cycle now, not at the next tick; a bus process's
        # master waits for it too (LinkSupervisor's wake)
        self._wake = sequencer.inbox.wake
        self._last_record = b""
        self._repeat_now = False          # run the next bus cycle at once (a changed record, send_changes_at_once)
        self._repeated = False            # this cycle was such a repeat
        self._listeners: List[Callable[[DriverStatus], None]] = []
        self._status = self._set_status(self._snapshot(self.clock(), None))
        self._fresh = threading.Condition()      # notified with each new snapshot (status_after)

    # ------------------------------------------------------------------------ the thread (OwnThread)
    def request_stop(self) -> None:
        """Ask the bus thread to end, without waiting or taking a lock (safe from a signal handler):
        its wake-up ends its wait, for the next period or for a bus process's next report alike."""
        self._stop.set()
        self._wake.set()

    def wake(self) -> None:
        """Run a bus cycle now (a request was posted), not at the next tick (the inbox's wake:
        a bus process's master waits for it as well)."""
        self._wake.set()

    def add_listener(self, callback: Callable[[DriverStatus], None]) -> None:
        """``callback(status)`` after every bus iteration (bus thread)."""
        self._listeners.append(callback)

    def status(self, now: float) -> DriverStatus:
        """The latest snapshot, read at ``now``: one older than ``link_timeout``, or with feedback
        older than that, reads as a lost link."""
        return self._status.stale(now, self.params.link_timeout)

    def _run(self) -> None:
        period = 1.0 / self.cycle_rate_hz
        next_start = self.clock()
        while not self._stop.is_set():
            try:
                self.spin_once()
            except Exception:  # never let the bus thread die: log, drop the link, reopen
                log.exception("bus thread: unexpected error; reopening the link")
                self.link.fail("internal error (see log)")
                self._publish(self.clock(), None)
            if self.link.paced:
                # the bus process keeps the time: step() waits for its next cycle (or a wake),
                # never a period here; an early cycle (a changed record sent at once, a stream's end due) is
                # asked of it
                now = self.clock()
                soon = self.next_cycle(now, math.inf)
                if soon < math.inf:
                    self.link.cycle_at(soon)
                continue
            next_start += period
            now = self.clock()
            if next_start < now:
                next_start = now
            next_start = self.next_cycle(now, next_start)
            if next_start <= now:
                continue
            if self._wake.wait(next_start - now):
                self._wake.clear()
                next_start = self.clock()     # an extra cycle now; the rate resumes from here

    # ------------------------------------------------------------------------ one iteration
    def next_cycle(self, now: float, scheduled: float) -> float:
        """When the bus cycle after the one that just ran starts (``scheduled``: at the cycle rate).
        A protocol that sends changes at once (``send_changes_at_once``, v2): a changed record (a new
        target, STOP) goes out at once, not a period later -- the controller acts on it at the first
        telegram that brings it (its CRC-16); and while a
        stream's end is due (:meth:`StreamSequencer.end_due`) the bus cycles every
        END_POLL_PERIOD, so the goal's result does not wait up to a period for the arrival."""
        if self._repeat_now:
            self._repeat_now = False
            self._repeated = True             # never two in a row: a record that changed at every
            return now                        # cycle must not make the bus loop spin
        if self.sequencer.end_due(now):
            return min(scheduled, now + END_POLL_PERIOD)
        return scheduled

    def spin_once(self) -> DriverStatus:
        """One bus iteration: link step (one DP cycle), joints, sequencer step, snapshot."""
        sample = self.link.step(self.clock())
        now = sample.time
        if self.controller_io is not None:
            self.controller_io.refresh(sample.connected, sample.feedback, sample.feedback_time, now)
        if self.io is not None:
            self.io.update(now)          # judge the I/O stations after the cycle (io.snapshot())
        joints = self.arm.update(sample, self.sequencer.view.job)
        command = self.sequencer.step(now, sample, joints)
        record = self.wire.encode(command, self.params.byte_order)
        if self.wire.send_changes_at_once and record != self._last_record and sample.connected \
                and not self._repeated:
            self._repeat_now = True
        self._repeated = False
        self._last_record = record
        # the snapshot before the outputs go out (to a bus process: a socket write, which lets
        # other threads run): a job that ended in this step is never seen beside an older status
        status = self._set_status(self._snapshot(now, sample))
        self.link.set_outputs(record)
        self._notify(status)
        return status

    def status_after(self, t: float, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) for a snapshot taken at ``t`` or later; True when there is one.
        A job's end is set inside the sequencer's step, before that step's snapshot: a thread woken
        by it that reads the status at once reads the one before -- the arm's joints a record before
        its end (a goal check failed at 0.45 deg off a pose the arm had reached). Not for a stepped
        core (one thread: nothing else would take the snapshot)."""
        with self._fresh:
            return self._fresh.wait_for(lambda: self._status.time >= t, timeout)

    # ------------------------------------------------------------------------ snapshots
    def _snapshot(self, now: float, sample: Optional[LinkSample]) -> DriverStatus:
        view = self.sequencer.view
        counters = replace(self.link.counters, targets_sent=view.targets_sent,
                           targets_done=view.targets_done, targets_rejected=view.targets_rejected,
                           targets_aborted=view.targets_aborted)
        fb = sample.feedback if sample is not None else None
        if sample is None:
            link, reason = self.link.state, "not started"
            error_code, error_reason = ERROR_LINK, reason
        else:
            link, reason = sample.state, sample.reason
            error_code, error_reason = sample.error_code, sample.error_reason
        if fb is not None:
            if fb.status & StatusBits.ERROR:
                error_code, error_reason = ERROR_CONTROLLER, "the controller reports an error"
            else:
                error_code, error_reason = ERROR_NONE, ""
        return DriverStatus(
            time=now, link=link, link_reason=reason, feedback=fb,
            pose=fb.pose if fb is not None else None,
            joints=self.arm.joints, joints_valid=self.arm.valid and fb is not None,
            job=view.job, queue_length=view.queue_length, cycle_rate=self.link.cycle_rate,
            counters=counters, master_counters=self.link.master_counters(),
            slave_state=self.link.slave_state, last_diag=self.link.last_diag,
            error_code=error_code, error_reason=error_reason,
            model_check=self.arm.model_check,
            feedback_time=sample.feedback_time if sample is not None and fb is not None else None,
            record_time=sample.record_time if sample is not None and fb is not None else None,
            settling=view.settling, bus_health=self.link.health_summary(now), line=self.link.line_verdict())

    def _set_status(self, status: DriverStatus) -> DriverStatus:
        """The iteration's snapshot made the latest, and what requests read of it published to
        their inbox (:class:`~vr_driver.driver.motion.inbox.MotionSnapshot`)."""
        self._status = status
        self.sequencer.inbox.publish(status.for_requests(self.params.link_timeout))
        return status

    def _publish(self, now: float, sample: Optional[LinkSample]) -> DriverStatus:
        status = self._set_status(self._snapshot(now, sample))
        self._notify(status)
        return status

    def _notify(self, status: DriverStatus) -> None:
        with self._fresh:
            self._fresh.notify_all()
        for callback in self._listeners:
            try:
                callback(status)
            except Exception:
                log.exception("status listener failed")
