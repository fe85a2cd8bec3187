"""The simulated arm of the virtual G2 controller, and its execution log. ROS-free, no I/O.

:class:`SimArm` holds the joints of the arm and plays back trajectories of
:class:`~vr_driver.kinematics.preview.MovePreviewer` (PTP joint-interpolated, LIN straight, CIRC through a via
point) in time divided by ``speed_factor``. Time is injected: :meth:`SimArm.begin` and
:meth:`SimArm.step` take ``now``; the run-time injections (e-stop, drives, error) read the arm's
clock (default ``time.monotonic``, the same clock the program loop uses) so that a stop lands at
the exact position of the moment it was injected.

It reports what a real G2 reports: the TCP pose rounded to whole mm and degrees
(:meth:`SimArm.reported_pose`), angles wrapped into (-180, 180].

Rules (``doc/controller_program.md``):

- A target is planned when it is started; a target outside the reach or the joint limits, or any
  planning failure (joint jump, singularity, degenerate circle), is refused with the planner's
  message and nothing moves.
- Nothing starts while the e-stop is pressed, the drives are off or an error is set; the refusal
  names the first of these.
- The e-stop cuts the drive power, as on a real G2: pressing it switches the drives off, and
  releasing it leaves them off -- they must be switched on again (:meth:`SimArm.set_drives_powered`,
  the node's ``~set_drives_powered`` service); that is refused while the e-stop is pressed.
- E-stop, drives off or an error *during* a motion stops the arm at once, at the position of that
  moment; the motion ends refused (``aborted``) with the reason. :meth:`SimArm.stop` does the same
  for the program (link loss / watchdog).
- A *controlled* stop (:meth:`SimArm.brake`, the master's stop flag) is what a real arm does: it
  keeps following its path while its speed ramps down to zero over ``brake_time`` (robot time,
  divided by ``speed_factor`` like every motion), so it comes to rest ``brake_time / 2`` of path
  time further on; ``moving`` stays true until then. ``brake_time`` 0 halts at once.
- Clearing a fault does not resume an aborted motion: the master must send a new target.
- **The configuration of a PTP target** (``configuration``, :class:`~vr_driver.kinematics.solver.
  ConfigurationRule`; an assumption about the G2, doc/controller_program.md §7): its IK solution
  nearest the joints of the previous target the arm began (``previous_target``, the default; the
  arm's joints before the first) or nearest the arm's joints (``current_joints``). They differ only
  after a motion that stopped short of its target. A LIN / CIRC follows its path from where the arm
  is, whatever the rule.

Thread safety: every public method takes the arm's lock, so injections from a ROS service thread
and the program loop may interleave freely.
"""
from __future__ import annotations

import enum
import json
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .. import validate
from ..errors import KinematicsError, MotionError, PoseError, VrDriverError
from ..kinematics.solver import ConfigurationRule, Kinematics
from ..kinematics.preview import MovePreviewer, MotionSettings, MoveType, Trajectory, at_tcp_speed
from ..protocol.v1 import program_speed
from ..poses import HOME_POSE, ControllerPose, wrap_degrees
from ..protocol.common import INT16_MAX, INT16_MIN, round_half_away

__all__ = [
    "IntPose",
    "round_pose",
    "Outcome",
    "MotionResult",
    "LogEntry",
    "ExecutionLog",
    "brake_progress",
    "ArmBase",
    "SimArm",
]

Clock = Callable[[], float]

#: a pose as the controller reports it: whole mm and degrees
IntPose = Tuple[int, int, int, int, int, int]

_INT16 = (INT16_MIN, INT16_MAX)


def round_pose(pose: Any) -> IntPose:
    """A pose in whole mm / degrees as the G2 reports it: rounded half away from zero (the wire's
    rounding, :func:`vr_driver.protocol.common.round_half_away`), angles wrapped into (-180, 180], every
    value clamped into int16."""
    if not isinstance(pose, ControllerPose):
        pose = ControllerPose.from_sequence(pose)
    out = []
    for i, value in enumerate(pose.as_tuple()):
        v = round_half_away(value)
        if i >= 3:
            v = int(wrap_degrees(float(v)))
        out.append(min(_INT16[1], max(_INT16[0], v)))
    return tuple(out)  # type: ignore[return-value]


class Outcome(enum.Enum):
    EXECUTED = "executed"        # the motion ran to its end
    REJECTED = "rejected"        # refused before it started (nothing moved) or aborted while moving
    VIA_STORED = "via_stored"    # a circular via point, acknowledged without motion
    BLENDED = "blended"          # v2: passed through the point without stopping (a blend began)
    STOPPED = "stopped"          # v2: taken, but a stop / fault / link loss ended it before its point


@dataclass(frozen=True)
class MotionResult:
    """How a motion ended: ``ok`` (reached the target) or not, why, and whether the arm moved."""

    ok: bool
    reason: str = ""
    aborted: bool = False        # it had started moving when it was stopped
    end_time: float = 0.0


@dataclass(frozen=True)
class LogEntry:
    """One target the controller handled (one accepted request of the handshake)."""

    seq: int                     # 1, 2, 3, ... in the order the requests were accepted
    move_type: str               # "PTP", "LIN", "CIRC_END", "CIRC_VIA"
    target: IntPose              # the commanded pose (mm, deg) as received
    outcome: Outcome
    reason: str                  # why it was refused or aborted ("" when executed / stored)
    start_time: float            # clock time the request was accepted
    end_time: float              # clock time of the outcome
    final_pose: IntPose          # the reported pose after the outcome
    aborted: bool = False        # the arm had moved when the motion was stopped
    via: Optional[IntPose] = None  # the via point used by a CIRC_END

    @property
    def duration(self) -> float:
        return self.end_time - self.start_time

    def to_dict(self) -> Dict[str, Any]:
        return {
            "seq": self.seq,
            "time": self.end_time,
            "start_time": self.start_time,
            "duration": self.duration,
            "move_type": self.move_type,
            "target": list(self.target),
            "via": None if self.via is None else list(self.via),
            "outcome": self.outcome.value,
            "reason": self.reason,
            "aborted": self.aborted,
            "final_pose": list(self.final_pose),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)


class ExecutionLog:
    """Thread-safe list of :class:`LogEntry` with listeners and a blocking wait.

    Listeners (``add_listener(fn)``) are called with each new entry in the thread that appended it,
    outside the log's lock; an exception in one is recorded in :attr:`listener_errors` and does not
    stop the others (the program loop must not die of a broken log file).
    """

    def __init__(self) -> None:
        self._entries: List[LogEntry] = []
        self._cond = threading.Condition()
        self._listeners: List[Callable[[LogEntry], None]] = []
        self.listener_errors: List[BaseException] = []

    def add_listener(self, listener: Callable[[LogEntry], None]) -> None:
        with self._cond:
            self._listeners.append(listener)

    def remove_listener(self, listener: Callable[[LogEntry], None]) -> None:
        with self._cond:
            if listener in self._listeners:
                self._listeners.remove(listener)

    def append(self, entry: LogEntry) -> None:
        with self._cond:
            self._entries.append(entry)
            listeners = list(self._listeners)
            self._cond.notify_all()
        for listener in listeners:
            try:
                listener(entry)
            except Exception as exc:  # noqa: BLE001 - a listener must not break the program loop
                self.listener_errors.append(exc)

    def entries(self) -> List[LogEntry]:
        """A copy of the entries so far."""
        with self._cond:
            return list(self._entries)

    def __len__(self) -> int:
        with self._cond:
            return len(self._entries)

    def __getitem__(self, index: int) -> LogEntry:
        with self._cond:
            return self._entries[index]

    def wait_for(self, count: int, timeout: Optional[float] = None) -> bool:
        """Block until the log has at least ``count`` entries (True) or ``timeout`` passed (False)."""
        with self._cond:
            return self._cond.wait_for(lambda: len(self._entries) >= count, timeout)

    def clear(self) -> None:
        with self._cond:
            self._entries.clear()


def brake_progress(elapsed: float, brake_time: float) -> float:
    """Path time [s] a controlled stop still covers ``elapsed`` robot seconds after it began: the
    rate of progress along the path ramps linearly from 1 to 0 over ``brake_time``, so the arm comes
    to rest ``brake_time / 2`` of path time after the stop began."""
    tau = min(max(elapsed, 0.0), brake_time)
    return tau - tau * tau / (2.0 * brake_time) if brake_time > 0.0 else 0.0


class LockedRead:
    """A read-only attribute of an arm that the program thread steps while others read it: the value
    of ``attribute``, read under the arm's ``_lock``. In the class body: ``joints =
    LockedRead("_joints", "The exact joints [rad] at the last step.")``. Setting it raises
    AttributeError, as a property without a setter does."""

    def __init__(self, attribute: str, doc: Optional[str] = None) -> None:
        self.attribute = attribute
        self.name = attribute
        self.__doc__ = doc

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, arm: Any, owner: Optional[type] = None) -> Any:
        if arm is None:
            return self
        with arm._lock:
            return getattr(arm, self.attribute)

    def __set__(self, arm: Any, value: Any) -> None:
        raise AttributeError("%s is read-only" % self.name)


class ArmBase:
    """What both simulated arms (SimArm, the v2 SimStreamArm) share: the start (validated options,
    the initial joints: ``initial_joints`` wins over ``initial_pose``, which is solved by IK seeded
    from the SRDF's ``home`` state), the read-outs, and e-stop, drives and error as on a real G2:
    the e-stop cuts the drive power, and releasing it leaves the drives off until they are switched
    on again (refused while the e-stop is pressed); setting any fault stops a motion at once
    (``self._abort(reason, now)``, the arm's). ``configuration``: the controller's rule for the
    joint solution of a Cartesian target (:meth:`configuration_seed`)."""

    def _init_arm(self, kinematics: Optional[Kinematics], speed_factor: float, brake_time: float,
                  initial_pose: Any, initial_joints: Optional[Sequence[float]], clock: Clock,
                  configuration: Any = ConfigurationRule.PREVIOUS_TARGET) -> None:
        try:
            self.configuration = ConfigurationRule.parse(configuration)
        except PoseError as exc:
            raise MotionError("configuration: %s" % exc) from None
        speed_factor = validate.number(speed_factor, lambda _: MotionError(
            "speed_factor must be a finite number > 0, got %r" % (speed_factor,)), 0.0, lo_open=True, text=False)
        self.brake_time = validate.number(brake_time, lambda _: MotionError(
            "brake_time must be a finite number >= 0, got %r" % (brake_time,)), 0.0, text=False)
        self.kin = kinematics if kinematics is not None else Kinematics.default()
        self.speed_factor = float(speed_factor)
        self.clock = clock
        self._lock = threading.RLock()
        if initial_joints is not None:
            joints = self.kin.check_limits(initial_joints)
        else:
            pose = initial_pose if isinstance(initial_pose, ControllerPose) else \
                ControllerPose.from_sequence(initial_pose)
            joints = self.kin.ik_pose(pose, seed=self.kin.named_states.get("home"))
        self._joints: Tuple[float, ...] = tuple(float(v) for v in joints)
        self._pose = self.kin.fk_pose(self._joints)
        self._estop = False
        self._drives = True
        self._error: Optional[str] = None
        self._last_step = -math.inf                       # clock time of the last position update

    def _abort(self, reason: str, now: Optional[float]) -> bool:
        raise NotImplementedError

    def configuration_seed(self, previous: Optional[Sequence[float]]) -> Tuple[float, ...]:
        """The joints the controller takes a Cartesian target's IK solution nearest to, by its
        ``configuration`` rule: ``previous`` (the joints of the previous target it took; None when
        there is none) under ``previous_target``, the arm's joints now under ``current_joints``."""
        with self._lock:
            return self.configuration.seed(previous, self._joints)

    def snapshot(self) -> Tuple[bool, ControllerPose, Tuple[float, ...]]:
        """(moving, the exact pose, the joints) read together under the arm's lock. Read one by
        one from another thread they may straddle a program loop: a motion that begins between
        them (at speed_factor 100 a joint turns tens of degrees in one 10 ms loop) pairs the rest
        pose with the joints of the next move."""
        with self._lock:
            return self.moving, self._pose, self._joints

    def stepped_joints(self) -> Tuple[Tuple[float, ...], float]:
        """(the exact joints, the clock time of the step that brought them up to date: -inf before
        any) read together under the arm's lock: a reader that stamps a sample with its own time
        dates it late by the time since the step, tens of ms on a busy machine (a 0.2 s speed window
        read 13 % fast)."""
        with self._lock:
            return self._joints, self._last_step

    @property
    def moving(self) -> bool:
        raise NotImplementedError

    joints = LockedRead("_joints", "The exact joints [rad] at the last step.")
    pose = LockedRead("_pose", "The exact TCP pose (float mm / deg) at the last step.")

    def reported_pose(self) -> IntPose:
        """The pose as the v1 controller reports it (whole mm / degrees)."""
        with self._lock:
            return round_pose(self._pose)

    last_step_time = LockedRead("_last_step", "Clock time the position was last brought up to date (-inf before any).")
    estop = LockedRead("_estop", "True while the e-stop is pressed.")

    @property
    def drives_powered(self) -> bool:
        """True when the drives carry power: the drives switch is on and the e-stop is released."""
        with self._lock:
            return self._drives and not self._estop

    error = LockedRead("_error", "The injected error text, or None.")

    def blocked_reason(self) -> Optional[str]:
        """Why no motion may start now (e-stop, drives off, error), or None."""
        with self._lock:
            if self._estop:
                return "e-stop pressed"
            if not self._drives:
                return "drives not powered"
            if self._error is not None:
                return "controller error: %s" % self._error
            return None

    def set_estop(self, pressed: bool, now: Optional[float] = None) -> None:
        """Press (True) or release (False) the e-stop. Pressing stops a motion at once and
        switches the drives off; releasing leaves them off (switch them on again)."""
        with self._lock:
            self._estop = bool(pressed)
            if self._estop:
                self._drives = False
                self._abort("e-stop pressed during the motion", now)

    def set_drives_powered(self, powered: bool, now: Optional[float] = None) -> bool:
        """Switch the drives on or off; returns whether they are in the state asked for.
        Switching off stops a motion at once; switching on is refused while the e-stop is
        pressed (False)."""
        with self._lock:
            if powered and self._estop:
                return False
            self._drives = bool(powered)
            if not self._drives:
                self._abort("drives switched off during the motion", now)
            return True

    def set_error(self, error: Any, now: Optional[float] = None) -> None:
        """Set (a truthy value; a string is kept as the error text) or clear (False / None) the
        controller error. Setting it stops a motion at once."""
        with self._lock:
            if not error:
                self._error = None
                return
            self._error = error if isinstance(error, str) else "injected error"
            self._abort("controller error during the motion: %s" % self._error, now)


@dataclass
class _Motion:
    trajectory: Trajectory
    start_time: float
    move_type: MoveType
    brake_start: Optional[float] = None      # wall time a controlled stop began
    brake_from: float = 0.0                  # path time [s] at that moment
    brake_reason: str = ""


class SimArm(ArmBase):
    """A simulated VR-006L: joints, planned motions played back ``speed_factor`` times faster, faults.

    ``initial_joints`` wins over ``initial_pose``; the initial pose is solved by IK seeded from the
    SRDF's ``home`` state (PoseError / a KinematicsError if it is not reachable). ``configuration``:
    the rule for a PTP target's joint solution (module docstring). ``program_speeds``: (MOVEP,
    MOVEL / MOVEC) [m/min], the program's constant move speeds (the v1 program: every move is the
    previewed one slowed down evenly until its TCP never exceeds that speed,
    :func:`~vr_driver.kinematics.preview.at_tcp_speed`); None: the arm's own full-speed profile.
    """

    def __init__(self, kinematics: Optional[Kinematics] = None, planner: Optional[MovePreviewer] = None, *,
                 speed_factor: float = 1.0, initial_pose: Any = HOME_POSE,
                 initial_joints: Optional[Sequence[float]] = None,
                 settings: Optional[MotionSettings] = None, clock: Clock = time.monotonic,
                 brake_time: float = 0.0, configuration: Any = ConfigurationRule.PREVIOUS_TARGET,
                 program_speeds: Optional[Tuple[float, float]] = None) -> None:
        self._init_arm(kinematics, speed_factor, brake_time, initial_pose, initial_joints, clock, configuration)
        self.planner = planner if planner is not None else MovePreviewer(self.kin, settings)
        self.program_speeds = None if program_speeds is None else (float(program_speeds[0]), float(program_speeds[1]))
        self._motion: Optional[_Motion] = None
        self._result: Optional[MotionResult] = None      # finished motion not yet collected by step()
        self._target: Optional[Tuple[float, ...]] = None  # the joints of the last target begun

    # ------------------------------------------------------------------------------- read-outs
    @property
    def moving(self) -> bool:
        with self._lock:
            return self._motion is not None

    def motion_remaining(self, now: Optional[float] = None) -> float:
        """Wall time [s] until the current motion ends (0 when idle)."""
        with self._lock:
            if self._motion is None:
                return 0.0
            now = self.clock() if now is None else now
            m = self._motion
            if m.brake_start is not None:
                return max(0.0, self.brake_time / self.speed_factor - (now - m.brake_start))
            return max(0.0, m.trajectory.duration / self.speed_factor - (now - m.start_time))

    # ---------------------------------------------------------------------------- injections
    def stop(self, reason: str, now: Optional[float] = None) -> bool:
        """Stop a motion at once (program-side stop, e.g. the master went silent). True if one ran."""
        with self._lock:
            return self._abort(reason, now)

    @property
    def braking(self) -> bool:
        with self._lock:
            return self._motion is not None and self._motion.brake_start is not None

    def brake(self, reason: str, now: Optional[float] = None) -> bool:
        """Begin a controlled stop: the arm decelerates along its path and comes to rest
        ``brake_time / 2`` of path time later (at once with ``brake_time`` 0); the motion then
        ends refused with ``reason`` (or done, if the ramp carried it to the target). True if a
        motion was running and was not braking already."""
        with self._lock:
            m = self._motion
            if m is None or m.brake_start is not None:
                return False
            now = self.clock() if now is None else now
            now = max(now, self._last_step)
            if self.brake_time <= 0.0:
                return self._abort(reason, now)
            m.brake_from = (now - m.start_time) * self.speed_factor
            m.brake_start = now
            m.brake_reason = reason
            self._last_step = now
            return True

    # ------------------------------------------------------------------------------- motions
    def plan(self, move_type: Any, target: Any, via: Any = None) -> Trajectory:
        """The trajectory a motion to ``target`` would follow from the current joints (raises the
        planner's VrDriverError when it cannot)."""
        with self._lock:
            return self._plan(MoveType.parse(move_type), target, via)

    def _plan(self, kind: MoveType, target: Any, via: Any) -> Trajectory:
        """The motion from the current joints, at the program's speed (``program_speeds``); a PTP to
        the target's solution by the rule."""
        speed = None if self.program_speeds is None else program_speed(kind, *self.program_speeds)
        seed = self.configuration_seed(self._target)
        if kind is not MoveType.PTP or seed == self._joints:
            return at_tcp_speed(self.planner.plan(kind, self._joints, target, via), speed)
        pose = target if isinstance(target, ControllerPose) else ControllerPose.from_sequence(target)
        try:
            goal = self.kin.ik_pose(pose, seed=seed)
        except KinematicsError as exc:
            raise type(exc)("PTP target %s: %s" % (pose, exc)) from exc
        return at_tcp_speed(self.planner.ptp_joints(self._joints, goal), speed)

    def begin(self, move_type: Any, target: Any, via: Any = None, now: Optional[float] = None
              ) -> Tuple[bool, str]:
        """Start a motion: ``(True, "")``, or ``(False, reason)`` when it is refused (a fault, a
        motion already running, no via for CIRC, unreachable, planning failed); nothing moves then."""
        with self._lock:
            now = self.clock() if now is None else now
            blocked = self.blocked_reason()
            if blocked is not None:
                return False, blocked
            if self._motion is not None:
                return False, "a motion is already running"
            try:
                kind = MoveType.parse(move_type)
                if kind is MoveType.CIRC and via is None:
                    return False, "circular end point without a stored via point"
                traj = self._plan(kind, target, via)
            except VrDriverError as exc:
                return False, "%s: %s" % (type(exc).__name__, exc)
            self._result = None
            self._target = traj.goal
            self._last_step = max(self._last_step, now)
            self._motion = _Motion(traj, now, kind)
            if traj.duration <= 0.0:      # already there
                self._finish(now)
            return True, ""

    def step(self, now: Optional[float] = None) -> Optional[MotionResult]:
        """Advance the arm to ``now``. Returns the result of a motion that ended since the last
        call (once), else None."""
        with self._lock:
            now = self.clock() if now is None else now
            self._last_step = max(self._last_step, now)
            if self._motion is not None:
                m = self._motion
                elapsed = self._elapsed(m, now)
                if elapsed >= m.trajectory.duration:
                    self._finish(now)
                elif m.brake_start is not None and \
                        (now - m.brake_start) * self.speed_factor >= self.brake_time:
                    self._move_to(self._sample(m.trajectory, max(0.0, elapsed)))
                    self._motion = None
                    self._result = MotionResult(False, m.brake_reason, True, now)
                else:
                    self._move_to(self._sample(m.trajectory, max(0.0, elapsed)))
            result, self._result = self._result, None
            return result

    # ------------------------------------------------------------------------------- helpers
    def _elapsed(self, m: _Motion, now: float) -> float:
        """Path time [s] reached at wall time ``now`` (a controlled stop ramps the rate to 0)."""
        if m.brake_start is None:
            return (now - m.start_time) * self.speed_factor
        return m.brake_from + brake_progress((now - m.brake_start) * self.speed_factor, self.brake_time)

    def _finish(self, now: float) -> None:
        m = self._motion
        assert m is not None
        self._move_to(m.trajectory.goal)
        self._motion = None
        self._result = MotionResult(True, "", False, now)

    def _abort(self, reason: str, now: Optional[float]) -> bool:
        m = self._motion
        if m is None:
            return False
        now = self.clock() if now is None else now
        now = max(now, self._last_step)                  # never back along the path
        self._last_step = now
        elapsed = self._elapsed(m, now)
        if elapsed >= m.trajectory.duration:
            # it had already arrived before the stop: the motion was complete
            self._finish(now if m.brake_start is not None else
                         min(now, m.start_time + m.trajectory.duration / self.speed_factor))
            return False
        self._move_to(self._sample(m.trajectory, max(0.0, elapsed)))
        self._motion = None
        self._result = MotionResult(False, reason, True, now)
        return True

    def _move_to(self, joints: Sequence[float]) -> None:
        self._joints = tuple(float(v) for v in joints)
        self._pose = self.kin.fk_pose(self._joints)

    @staticmethod
    def _sample(traj: Trajectory, t: float) -> Tuple[float, ...]:
        """Joints at time ``t`` (linear in joint space between samples, as the planner assumes)."""
        times = traj.times
        i = int(np.searchsorted(times, t, side="right")) - 1
        i = max(0, min(i, len(times) - 2))
        t0, t1 = float(times[i]), float(times[i + 1])
        f = 0.0 if t1 <= t0 else min(1.0, max(0.0, (t - t0) / (t1 - t0)))
        q = traj.positions[i] + f * (traj.positions[i + 1] - traj.positions[i])
        return tuple(float(v) for v in q)
