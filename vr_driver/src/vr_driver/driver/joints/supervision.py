"""Supervision of a planner trajectory on its way: what ``joint_trajectory_action`` decides while a
:class:`~vr_driver.driver.core.TrajectoryRun` executes and when it ends. ROS-free, no I/O, no
clock of its own: the caller steps a :class:`TrajectorySupervisor` with the time and the driver's
status (or just the joints), publishes what each step returns, and sets the :class:`Outcome`.

- Per sample (:meth:`TrajectorySupervisor.step`): the feedback (desired = the plan at the sample's
  time since the start, actual, error) and the path check: the distance to the planned *path*
  (:func:`~vr_driver.driver.motion.trajectories.path_check`, in units of each joint's path tolerance;
  v1 cannot keep the schedule, so the path is checked, not the point of the schedule). Outside it
  (> 1) the run must stop: PATH_TOLERANCE_VIOLATED, naming the joint.
- Also per sample, the deviation from the plan *at the same time* (max over joints of
  |actual - plan(stamp - start)|): not a reason to stop, a figure of how well the schedule was
  kept; its largest value is in the note and in :attr:`Outcome.max_time_deviation`.
- At the end (:meth:`TrajectorySupervisor.finish`): cancelled / preempted / shut down -> canceled;
  the path left or a job failed -> aborted; the final joints outside the goal tolerance, or (a
  streaming protocol) later than ``goal_time_tolerance`` after the end said before it ran (the plan,
  its hold at the start, later points, the bus's cycles; else the planned end) ->
  GOAL_TOLERANCE_VIOLATED; otherwise succeeded. The error_string always ends with the note on how
  the run's time compared with the plan, in the protocol's own terms (its ``name`` and whether it
  ``streams``). v1 stops at each point and moves at the controller's own speed: its time is
  reported, never judged (``goal_time_tolerance`` is not applied, and the note says so).
- On a Cartesian protocol with per-configuration tolerances (the trajectory's ``per_configuration``,
  :class:`~vr_driver.driver.motion.trajectories.ConfigurationTolerances`): each joint is judged against
  what the wire's resolution allows where the arm is, and within the wrist band (joint_5 near 0,
  the plan's or the arm's) joint_4 and joint_6 by their sum -- the path check, the goal check
  and the deviation at the same time alike. The result says so, with the goal's bound: a goal
  on the singularity (joint_5 = 0), whose split of joint_4 / joint_6 a Cartesian controller
  chooses itself, ends SUCCESSFUL within the sum's tolerance, and the words name it.

Units: radians, seconds (the driver's clock), mm for the TCP positions it records.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from typing import Any, List, Optional, Sequence, Tuple

from ...protocol.base import Protocol
from .following import following_floor
from ..motion.stream_points import hold_lead
from ..motion.trajectories import (GOAL_TOLERANCE_VIOLATED, PATH_TOLERANCE_VIOLATED, SUCCESSFUL, ValidTrajectory,
                           path_check)

__all__ = ["SUCCEEDED", "ABORTED", "CANCELED", "SHUTDOWN", "PREEMPTED", "CANCELLED",
           "Sample", "Outcome", "TrajectorySupervisor"]

#: a stream that took this many times its plan, with no target late, says it may have stopped at
#: each point (the interpreter look-ahead of the controller: 1.45 x with look-ahead 0 in the bench)
SLOW_STREAM = 1.25
#: [rad] the result says the plan's floor (how close any arm within the acceleration limits could
#: follow it) from this on
FLOOR_WORDS = math.radians(0.1)
#: the start delays the at-time deviation is fitted over [s], and the step
MAX_START_DELAY = 0.5
DELAY_STEP = 0.005
FINE_DELAY_STEP = 0.00025
#: samples kept for the fit (a 10-minute trajectory at 50 Hz)
MAX_HISTORY = 30000
#: samples x delays the fit judges in one array operation
FIT_CELLS = 20000

# how a goal ends (actionlib's terminal states of an accepted goal)
SUCCEEDED = "succeeded"
ABORTED = "aborted"
CANCELED = "canceled"

# why a run was stopped from outside (the start of the error_string)
SHUTDOWN = "driver shutting down"
PREEMPTED = "preempted by a newer trajectory"
CANCELLED = "cancelled by the client"


@dataclass(frozen=True)
class Sample:
    """One stepped sample: the feedback to publish and what was checked."""

    time: float                                  # seconds since the start (the sample's stamp)
    desired: Tuple[float, ...]                   # the plan at ``time``
    actual: Tuple[float, ...]
    error: Tuple[float, ...]                     # actual - desired
    path_deviation: float                        # distance to the planned path, x the path tolerance
    segment: int                                 # the planned segment nearest the joints
    time_deviation: float                        # rad, max |error| over the joints (the band's rule)
    violated: bool                               # outside the path tolerance: the run must stop
    by_sum: bool = False                         # in the wrist band: joint_4 / joint_6 judged by their sum


@dataclass(frozen=True)
class Outcome:
    """How the goal ends: ``state`` (SUCCEEDED / ABORTED / CANCELED), the control_msgs
    ``error_code`` and ``error_string`` of the result; ``note`` (the time compared with the plan,
    the end of ``error_string``) and the run's figures."""

    state: str
    error_code: int
    error_string: str
    note: str
    elapsed: float                               # seconds from the start to the end
    max_path_deviation: float                    # x the path tolerance (0: no sample)
    max_time_deviation: float                    # rad, vs the plan at the same time (0: no sample)
    samples: int
    start_delay: float = 0.0                     # s: the constant delay that fits the run best
    max_delayed_deviation: float = 0.0           # rad, vs the plan at the same time after that delay


def first_sent(run: object) -> Optional[float]:
    """When the run's first target left (its ``first_sent``; None: not yet, or a test's run without it)."""
    return getattr(run, "first_sent", None)


def lateness(now: float, said: float, sent: Optional[float], started: float, planned: float) -> Tuple[float, str]:
    """(how late a run ended at ``now`` [s], the end it is late against, in words): against the end
    said before it ran (``said`` [s] after its first target left at ``sent``: the time the protocol
    adds to the plan -- a hold at the start, later points, the bus's cycles -- was said, so it is not
    lateness; a goal_time_tolerance of 0.1 s would otherwise refuse every v3 run as said), else
    against the ``planned`` end from ``started``."""
    if said > 0.0 and sent is not None:
        return now - sent - said, "the end said before it ran (%.2f s after its first target)" % said
    return now - started - planned, "the planned end"


class TrajectorySupervisor:
    """Watches one run of ``traj`` (``run``: what :meth:`DriverCore.submit_trajectory` returned,
    started at ``started`` on the driver's clock) for the protocol ``wire``
    (:class:`vr_driver.protocol.base.Protocol`). ``joint_names``: the controller's joint names, for
    the texts (default joint_1..joint_n).

    The caller's loop: ``while sup.running:`` read the status, :meth:`step_status` (or
    :meth:`step`), publish the returned sample; :meth:`cancel` / :meth:`shutdown` on a request
    from outside. After the loop: if :attr:`stops_arm`, stop the arm (reason :attr:`stop_reason`)
    and wait for the run's jobs; then :meth:`finish` (or :meth:`finish_status`).

    ``accelerations`` [rad/s^2] (the arm's joint acceleration limits; None: not said): the result
    also says how close any arm within them could follow the plan, where that is FLOOR_WORDS or more
    (:func:`vr_driver.driver.joints.following.following_floor`: a plan's points joined by straight lines
    change speed at once)."""

    def __init__(self, traj: ValidTrajectory, run: Any, started: float, wire: Protocol,
                 joint_names: Optional[Sequence[str]] = None,
                 accelerations: Optional[Sequence[float]] = None, said: float = 0.0) -> None:
        self.traj = traj
        #: [s] the run's duration said before it ran, from its first target (announced.Announced.duration:
        #: the plan, its hold at the start, later points, the bus's cycles to the arm and back); 0: not said
        self.said = float(said)
        self.accelerations = None if accelerations is None else tuple(float(a) for a in accelerations)
        self.run = run
        self.started = started
        self.wire = wire
        n = len(traj.positions[0])
        self.names = list(joint_names) if joint_names is not None else ["joint_%d" % (i + 1) for i in range(n)]
        self.executed: List[Tuple[float, float, float]] = []   # TCP positions seen [mm]
        self.samples = 0
        self._history: List[Tuple[float, Tuple[float, ...]]] = []     # (t, actual), for the delay fit
        self.max_path_deviation = 0.0
        self.max_time_deviation = 0.0
        self.worst_time: Optional[Tuple[int, float]] = None      # (joint index, seconds since start)
        self.samples_by_sum = 0                   # samples judged with joint_4 / joint_6 by their sum
        self._stop_reason = ""
        self._preempted = False
        self._violated = False

    # ------------------------------------------------------------------ during the run
    @property
    def stop_reason(self) -> str:
        """Why the run was stopped before its end ("" while it was not)."""
        return self._stop_reason

    @property
    def preempted(self) -> bool:
        return self._preempted

    @property
    def stops_arm(self) -> bool:
        """The caller must stop the arm: cancelled, out of the path tolerance, shut down. Not when
        preempted: the newer trajectory already replaced the queued points and starts from the one
        in flight."""
        return bool(self._stop_reason) and not self._preempted

    @property
    def running(self) -> bool:
        """Keep stepping: the run has not ended, failed, or been stopped."""
        return not self._stop_reason and not self.run.done and self.run.failure() is None

    def cancel(self, preempted: bool = False) -> None:
        """The client cancelled the goal (``preempted``: a newer goal replaced it)."""
        if not self._stop_reason:
            self._preempted = preempted
            self._stop_reason = PREEMPTED if preempted else CANCELLED

    def shutdown(self) -> None:
        """The driver shuts down: the run is stopped."""
        if not self._stop_reason:
            self._stop_reason = SHUTDOWN

    def step(self, now: float, joints_valid: bool, joints: Optional[Sequence[float]],
             stamp: Optional[float] = None, pose: Any = None) -> Optional[Sample]:
        """One sample of the arm: ``joints`` measured at ``stamp`` (default ``now``), ``pose``
        (a ControllerPose or None) recorded for the executed TCP path. None when there are no
        valid joints (nothing to publish, nothing checked)."""
        if not joints_valid or joints is None:
            return None
        t = (now if stamp is None else stamp) - self.started
        actual = tuple(float(v) for v in joints)
        desired = tuple(self.traj.sample(t))
        error = tuple(a - d for a, d in zip(actual, desired))
        judged = self._judged(np.array([actual]), np.array([desired]))[0]
        worst = int(np.argmax(judged))
        off = float(judged[worst])
        self.samples += 1
        if off > self.max_time_deviation or self.worst_time is None:
            self.max_time_deviation, self.worst_time = off, (worst, t)
        if len(self._history) < MAX_HISTORY:
            self._history.append((t, actual))
        if pose is not None:
            self.executed.append(tuple(pose.as_tuple()[:3]))
        check = path_check(self.traj, actual)
        deviation, segment = check.deviation, check.segment
        self.max_path_deviation = max(self.max_path_deviation, deviation)
        self.samples_by_sum += check.by_sum
        violated = deviation > 1.0
        if violated and not self._stop_reason:
            self._violated = True
            self._stop_reason = ("the arm left the path tolerance near segment %d (%.1f x the "
                                 "tolerance, %s)" % (segment, deviation, self._joint_words(check.joint, check.by_sum)))
        return Sample(t, desired, actual, error, deviation, segment, off, violated, check.by_sum)

    def _joint_words(self, joint: int, by_sum: bool) -> str:
        """A joint's name, or within the wrist band the sum's with the rule."""
        tolerances = self.traj.per_configuration
        if by_sum and tolerances is not None and joint == tolerances.wrist[0]:
            return "%s: %s" % (tolerances.sum_name(self.names), tolerances.band_words(self.names))
        return self.names[joint]

    def _judged(self, actual: np.ndarray, desired: np.ndarray) -> np.ndarray:
        """|actual - desired| per sample and joint (rows), except where the wrist band's rule
        applies (a per-configuration trajectory, joint_5 within the band in either): there
        joint_4's column holds |the error of joint_4 + sign * joint_6| and joint_6's 0."""
        err = np.abs(actual - desired)
        tolerances = self.traj.per_configuration
        if tolerances is None or not len(err):
            return err
        i4, i5, i6 = tolerances.wrist
        band = (np.abs(actual[:, i5]) < tolerances.band) | (np.abs(desired[:, i5]) < tolerances.band)
        if band.any():
            diff = actual - desired
            err[band, i4] = np.abs(diff[band, i4] + tolerances.sign * diff[band, i6])
            err[band, i6] = 0.0
        return err

    def _label(self, joint: int, t: float, delay: float = 0.0) -> str:
        """The name of the worst joint of the deviation at the same time, the sample ``t`` s after
        the start against the plan ``delay`` s earlier (joint_4's index in the band: the sum)."""
        tolerances = self.traj.per_configuration
        if tolerances is not None and joint == tolerances.wrist[0]:
            q = [v for tt, v in self._history if tt == t]
            desired = self.traj.sample(t - delay)
            if (q and tolerances.in_band(q[0])) or tolerances.in_band(desired):
                return tolerances.sum_name(self.names)
        return self.names[joint]

    def step_status(self, now: float, status: Any) -> Optional[Sample]:
        """:meth:`step` with a :class:`~vr_driver.driver.core.DriverStatus` (stamp: the time the
        controller took its record, else the time the record arrived, else the snapshot's time)."""
        stamp = next((t for t in (getattr(status, "record_time", None), status.feedback_time)
                      if t is not None), status.time)
        return self.step(now, status.joints_valid, status.joints, stamp, status.pose)

    # ------------------------------------------------------------------ the end
    def note(self, elapsed: float, cycle_rate: float = 0.0,
             fit: Optional[Tuple[float, float, Optional[int], float]] = None) -> str:
        """How the run's time compared with the plan, in the protocol's terms, and how far it was
        from the plan at the same time (``fit``: :meth:`fit_delay`'s result when the caller has it)."""
        traj, run, wire = self.traj, self.run, self.wire
        slower = elapsed / traj.duration if traj.duration > 0 else 1.0
        text = self.start_words()
        if wire.streams:
            points = run.jobs[0].points if run.jobs else ()
            smooth = max((p.smooth for p in points), default=0)
            how = "smooth levels up to %d" % smooth if smooth else "an exact stop at each"
            # the stream's own timing: the plan after its hold at the start (stream_points.fed_schedule),
            # later only where the bus fed a target later than the plan passed it
            hold = hold_lead(points)
            if hold > 0.005:
                how += ", the first a %.2f s hold at the start while the bus brought the first targets" % hold
            fed = points[-1].fed if points and points[-1].fed is not None else traj.duration
            slower_fed = elapsed / fed if fed > 0 else slower
            text += "ran %.2f x the planned %.2f s (protocol %s: %d of %d points streamed, %s)" % (
                slower, traj.duration, wire.name, len(points), len(traj.positions) - 1, how)
            gaps = run.jobs[0].gaps if run.jobs else 0
            if gaps:
                text += ("; the arm stopped %d time(s) on the way waiting for its next target: the bus "
                         "(%.1f cycles/s) did not bring it in time -- a faster line (baud) or a larger "
                         "stream_path_tolerance gives fewer, longer segments" % (gaps, cycle_rate))
            elif smooth and slower_fed > SLOW_STREAM and len(points) >= 2:
                text += ("; %.0f %% longer than planned%s although no target came late: a controller that "
                         "stops at each point (its interpreter does not read the next MOVE ahead, "
                         "doc/controller_program.md section 10.9) runs this way"
                         % (100.0 * (slower_fed - 1.0), " with its hold" if hold > 0.005 else ""))
        else:
            text += "ran %.2f x the planned %.2f s (protocol %s stops at each of %d points)" % (
                slower, traj.duration, wire.name, len(run.jobs))
            if traj.goal_time_tolerance > 0.0:
                text += ("; its time is reported, not judged: goal_time_tolerance (%.2f s) applies to a "
                         "streaming protocol" % traj.goal_time_tolerance)
        delay, off, joint, at = fit if fit is not None else self.fit_delay()
        if joint is not None:
            text += ("; at most %.3f deg from the plan at the same time after a start delay of %.3f s "
                     "(%s, %.2f s after the start; %.3f deg without the delay)" % (
                         math.degrees(off), delay, self._label(joint, at, delay), at, math.degrees(self.max_time_deviation)))
        tolerances = traj.per_configuration
        if tolerances is not None and self.samples_by_sum:
            text += "; %s (%d of %d samples)" % (tolerances.band_words(self.names), self.samples_by_sum, self.samples)
        floor, where = self.floor()
        if floor >= FLOOR_WORDS:
            text += ("; no arm within the joint acceleration limits follows this plan closer than %.3f deg (%s)"
                     % (math.degrees(floor), where))
        return text

    def start_words(self) -> str:
        """How the run began, counted from its start (:attr:`started`: the goal's arrival): "prepared
        in P s; first target left F s after the goal arrived; " (P: arrival to queued -- the checks,
        the stream's preparation; F: arrival to the record that carried the first target handed to
        the bus, which sends it with its next cycle). "" for a run that does not say (a test's)."""
        prepared = getattr(self.run, "prepared", None)
        if prepared is None:
            return ""
        since = "the goal arrived" if self.traj.delay <= 0.0 else "its start time (the goal's header stamp)"
        text = "prepared in %.3f s" % max(0.0, prepared - self.started)
        sent = first_sent(self.run)
        if sent is not None:
            text += "; first target left %.3f s after %s" % (sent - self.started, since)
        return text + "; "

    def floor(self) -> Tuple[float, str]:
        """(floor [rad], where): the least deviation from the plan at the same time any arm within
        :attr:`accelerations` could reach (judged as this supervisor judges, joint_4 / joint_6 by
        their sum in the wrist band); (0.0, "") without accelerations."""
        if self.accelerations is None or len(self.accelerations) != len(self.traj.positions[0]):
            return 0.0, ""
        tolerances = self.traj.per_configuration
        return following_floor(self.traj.times, self.traj.positions, self.accelerations,
                               band=None if tolerances is None else tolerances.band,
                               sign=1.0 if tolerances is None else tolerances.sign, names=self.names)

    def fit_delay(self) -> Tuple[float, float, Optional[int], float]:
        """The constant start delay in [0, MAX_START_DELAY] that makes the samples deviate least
        from the plan at the same time (the arm starts a bus cycle or two after the goal: the
        stream must reach the controller; a schedule kept after that is what the figure judges):
        (delay, the largest deviation then [rad], its joint index, its time since the start).
        (0, 0, None, 0) without samples."""
        if not self._history:
            return 0.0, 0.0, None, 0.0
        ts = np.array([t for t, _ in self._history])
        actual = np.array([q for _, q in self._history])
        times = np.asarray(self.traj.times, dtype=float)
        plan = np.asarray(self.traj.positions, dtype=float)
        n, dof = actual.shape
        best = None
        # many delays at once (the result waits for this fit: one delay at a time took ~20 ms, more
        # than a bus cycle on a loaded machine); in chunks that keep the arrays small
        chunk = max(1, FIT_CELLS // max(1, n))

        def judge(delays: np.ndarray) -> None:
            nonlocal best
            for k in range(0, len(delays), chunk):
                part = delays[k:k + chunk]
                at = (ts[None, :] - part[:, None]).ravel()
                desired = np.column_stack([np.interp(at, times, plan[:, j]) for j in range(dof)])
                err = self._judged(np.tile(actual, (len(part), 1)), desired).reshape(len(part), n, dof)
                worst = err.max(axis=(1, 2))
                for d in range(len(part)):        # the first delay of the smallest (as one at a time)
                    if best is None or worst[d] < best[1] - 1e-12:
                        i, j = np.unravel_index(int(err[d].argmax()), (n, dof))
                        best = (float(part[d]), float(worst[d]), int(j), float(ts[i]))
        judge(np.arange(0.0, MAX_START_DELAY + 1e-9, DELAY_STEP))
        coarse = best[0]                      # then finer around it: at 150 deg/s, 2.5 ms is 0.4 deg
        fine = np.arange(coarse - DELAY_STEP, coarse + DELAY_STEP + 1e-9, FINE_DELAY_STEP)
        judge(fine[(fine >= 0.0) & (fine <= MAX_START_DELAY)])
        return best

    def finish(self, now: float, joints_valid: bool, joints: Optional[Sequence[float]],
               cycle_rate: float = 0.0) -> Outcome:
        """The outcome, with the arm's final joints at ``now`` (the run's jobs ended, or the
        caller gave up waiting for them); ``cycle_rate``: the measured DP cycles per second (for
        the note on a streaming protocol's gaps)."""
        traj, run = self.traj, self.run
        elapsed = now - self.started
        fit = self.fit_delay()
        note = self.note(elapsed, cycle_rate, fit)

        delay, delayed, _joint, _at = fit

        def outcome(state: str, code: int, text: str) -> Outcome:
            return Outcome(state, code, text, note, elapsed, self.max_path_deviation,
                           self.max_time_deviation, self.samples, delay, delayed)

        if self._stop_reason and not self._violated:
            return outcome(CANCELED, SUCCESSFUL, "%s; %s" % (self._stop_reason, note))
        failed = run.failure()
        if self._violated or failed is not None:
            reason = self._stop_reason or (failed.result.reason if failed.result else "failed")
            return outcome(ABORTED, PATH_TOLERANCE_VIOLATED, "%s; %s" % (reason, note))
        if joints is None or not joints_valid:
            return outcome(ABORTED, GOAL_TOLERANCE_VIOLATED, "no joint state at the end; " + note)
        checks, in_band = self.goal_checks(joints)
        bad = [(name, err, tol) for name, err, tol in checks if err > tol]
        if bad:
            name, err, tol = bad[0]
            return outcome(ABORTED, GOAL_TOLERANCE_VIOLATED, "%s ended %.4f rad from the goal (tolerance "
                           "%.4f%s); %s" % (name, err, tol, self._band_note(joints) if in_band else "", note))
        late, end = lateness(now, self.said, first_sent(run), self.started, traj.duration)
        if self.wire.streams and traj.goal_time_tolerance > 0.0 and late > traj.goal_time_tolerance:
            return outcome(ABORTED, GOAL_TOLERANCE_VIOLATED, "reached %.2f s after %s (goal_time_tolerance "
                           "%.2f s); %s" % (late, end, traj.goal_time_tolerance, note))
        if traj.per_configuration is not None:
            return outcome(SUCCEEDED, SUCCESSFUL, "%s; %s" % (note, self._goal_words(joints, checks, in_band)))
        return outcome(SUCCEEDED, SUCCESSFUL, note)

    def goal_checks(self, joints: Sequence[float]) -> Tuple[List[Tuple[str, float, float]], bool]:
        """What the goal check compares: (name, |final - goal| [rad], tolerance [rad]) per joint --
        within the wrist band (a per-configuration trajectory whose goal or final joint_5 is within
        it) joint_4 and joint_6 as their sum, against the sum's goal tolerance -- and whether the
        band's rule applied."""
        traj = self.traj
        final = traj.positions[-1]
        tolerances = traj.per_configuration
        off = [abs(a - b) for a, b in zip(joints, final)]
        checks = [(self.names[i], off[i], t) for i, t in enumerate(traj.goal_tolerance)]
        if tolerances is None or not (tolerances.in_band(final) or tolerances.in_band(joints)):
            return checks, False
        i4, _i5, i6 = tolerances.wrist
        checks = [c for i, c in enumerate(checks) if i not in (i4, i6)]
        checks.insert(i4, (tolerances.sum_name(self.names), abs(tolerances.sum_of(joints) - tolerances.sum_of(final)),
                           tolerances.goal_sum))
        return checks, True

    def _band_note(self, joints: Sequence[float]) -> str:
        tolerances = self.traj.per_configuration
        i5 = tolerances.wrist[1]
        return "; %s ends at %.2f deg (the goal's %.2f deg): %s" % (
            self.names[i5], math.degrees(joints[i5]), math.degrees(self.traj.positions[-1][i5]),
            tolerances.band_words(self.names))

    def _goal_words(self, joints: Sequence[float], checks: List[Tuple[str, float, float]], in_band: bool) -> str:
        """The goal's bound in words: the joint nearest its tolerance, and within the wrist band the
        sum's rule and how far the controller's own split of joint_4 / joint_6 is from the plan's."""
        finite = [c for c in checks if math.isfinite(c[2]) and c[2] > 0.0]
        text = "the goal within the tolerances the wire's resolution allows there"
        if finite:
            name, err, tol = max(finite, key=lambda c: c[1] / c[2])
            text += " (closest: %s %.3f deg of %.3f deg)" % (name, math.degrees(err), math.degrees(tol))
        if in_band:
            tolerances = self.traj.per_configuration
            i4, _i5, i6 = tolerances.wrist
            final = self.traj.positions[-1]
            text += ("%s; their split is the controller's: %s %.2f deg, %s %.2f deg from the plan's"
                     % (self._band_note(joints), self.names[i4], math.degrees(joints[i4] - final[i4]),
                        self.names[i6], math.degrees(joints[i6] - final[i6])))
        return text

    def finish_status(self, now: float, status: Any) -> Outcome:
        """:meth:`finish` with a :class:`~vr_driver.driver.core.DriverStatus`."""
        return self.finish(now, status.joints_valid, status.joints, status.cycle_rate)
