"""The simulated arm of the virtual G2 controller for protocol v2: streamed joint targets with a
look-ahead, blending through a point only into a target already known. ROS-free, no I/O, time
injected (``now``; the fault injections read the arm's clock when no ``now`` is given).

Motion model (doc/controller_program.md §6 and §9):

- **Queue of two**: the target the arm moves to (*active*) and one look-ahead target. :meth:`room`
  says how many more it takes now (none while it stops). ``look_ahead`` (default 1, v2's queue of
  two) sets how many targets beyond the active one the arm holds: the interpreter look-ahead of a
  G2 program (protocol v3's ``interpreter_lookahead``); 0 = the next target comes only after the
  active one ended, so the arm stops at every point whatever the smooth level.
- **Segment**: a synchronous joint move from the previous point (or from rest) to the target: every
  joint starts and ends together, on the straight line in joint space. Its *move time* is
  ``T0 = max_i |dq_i| / (f * vmax_i)`` (``f`` = the target's speed fraction, ``vmax`` the joint
  velocity limits of the kinematics).
- **Speed profile**: a trapezoid in time. The normalised progress ``s`` rises with a linear speed
  ramp of ``r_in`` (from rest: the *stop ramp* ``r = min(f * ramp_time, T0)``: the limiting joint
  accelerates at ``vmax / ramp_time``, so ``ramp_time`` from rest to full speed; default: from the
  kinematics' joint limits, max velocity / acceleration, 0.1 s for the model), cruises at ``1 / T0``
  (the limiting joint at ``f * vmax``) and falls over ``r_out``; the segment lasts
  ``T0 + (r_in + r_out) / 2``. From rest to rest that is ``T0 + r``.
- **Blend** (smooth level ``k > 0`` of the point, the next target known in time): the next segment
  starts ``w`` before the current one ends, with ``w = min(0.05 k, 0.5) * min(T0, T0_next)``, and both
  ramps (``r_out`` of the current, ``r_in`` of the next) are ``w`` long. The arm moves on the sum of
  the two displacement profiles, so in the blend window its joint velocity goes linearly from
  the current segment's to the next one's: no joint is ever faster than in either segment, the
  speed does not drop to zero (unless the path turns back on itself), and the corner is rounded
  (the closest approach is about ``|v1 - v2| w / 8`` from the point). The middle of the blend window
  comes exactly ``T0`` after the middle of the previous one: a blended stream runs on the planned
  time; the ramps only add ``r / 2`` at each stop and start.
- **Decision point**: the trapezoid to a blend and the one to a stop are the same until the cruise
  ends for the earlier of the two, ``max(w_max, r) / 2`` before the cruise of a plain arrival would
  end (``w_max`` the largest window the point's own move time allows). At that moment the arm
  decides: blend if the next target is queued, else stop exactly at the point. A target that comes
  later is queued and run from rest after the point is reached; if none came, the arm stands at the
  point in state WAITING (a gap: it never guesses). Smooth 0 always stops exactly at the point.
- **Point passed**: a blended target counts as done when its blend window begins (outcome
  ``blended``; the next one becomes active and the queue has room again); a stopped-at target when
  the arm reaches it (``executed``).
- **STOP** (:meth:`brake`; also the program's link loss): the arm follows its planned path while
  the rate of progress ramps to zero over ``brake_time`` (:func:`~vr_driver.controller.arm.brake_progress`,
  as SimArm); queued targets not yet started are dropped (``stopped``), a blend already begun goes
  on, no new one begins; the active target ends ``stopped`` unless the ramp carried the arm to it.
- **Faults** (e-stop, drives off, error: :class:`~vr_driver.controller.arm.ArmBase`) stop the arm at once
  at the position of that moment and drop the queue.
- States: MOVING (a segment runs), STOPPING (braking), WAITING (at rest at ``done_seq``'s point after
  a target with smooth > 0 and nothing queued), IDLE (at rest otherwise).
- **The configuration rule** (``configuration``, v3: the program solves each Cartesian target when
  it takes it, nearest :meth:`~vr_driver.controller.arm.ArmBase.configuration_seed`): nearest the
  joints of the previous target still in the ring or the arm (``previous_target``, the default; the
  arm's joints when none is) or nearest the arm's joints at that moment (``current_joints``).

**Assumptions about the real G2** (each a parameter; the defaults are the model described above,
doc/controller_program.md §10.9):

- ``speed_scale`` (default 1.0): MOVEP's speed unit. A target's commanded speed fraction times the
  scale is the speed the arm really runs at (capped at the joint limits, 1.0): a G2 whose "speed
  1000" is 60 % of the joint limits is ``speed_scale`` 0.6. Move times, ramps and blend windows
  follow the real speed.
- ``blend_across_input_read`` (default True): the program reads its inputs between every two
  MOVEs; False is a G2 on which that read ends the blend of the MOVE before it -- an exact stop at
  every point, whatever the smooth level and the look-ahead (the next MOVE then starts from rest
  at once, without a wait for the program).
- ``ramp_shape`` (:class:`RampShape`, default ``linear``): the speed ramp from rest (and to rest,
  and in a blend window) is linear in time (constant acceleration) or S-shaped (``s_curve``: the
  smoothstep ``3x^2 - 2x^3`` of the ramp's share ``x``: no jump in acceleration, the peak 1.5 times
  the linear ramp's). Both cover the same distance in the same time, so the timing above holds for
  either; a controlled stop (:meth:`brake`) keeps its linear ramp.
- ``accelerations`` (default None): per-axis acceleration limits [rad/s^2], the mean acceleration
  of a ramp from rest to full speed (full speed / the ramp's time). Given, the stop ramp of a
  segment lasts ``max_i |dq_i| / (T0 a_i)`` (each joint reaches its cruise speed within its own
  limit; capped at T0) instead of ``f * ramp_time``; for ``a_i = vmax_i / ramp_time`` the two agree.
  None: every joint ramps in ``ramp_time`` (today's model). Not with ``ramp_time`` as well.

``speed_factor`` plays the robot time that many times faster (as SimArm); ``ramp_time`` and
``brake_time`` are robot time. Every target pushed ends in exactly one :class:`StreamLogEntry`,
collected with :meth:`step` / :meth:`collect`.

Thread safety: every public method takes the arm's lock.
"""
from __future__ import annotations

import collections
import enum
import json
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence, Tuple

import numpy as np

from panasonic_vr006l_support.joint_limits import model_ramp_time

from .. import validate
from ..errors import MotionError
from ..kinematics.solver import ConfigurationRule, Kinematics
from ..poses import HOME_POSE, ControllerPose, wrap_degrees
from ..protocol.common import BLEND_MAX, BLEND_PER_LEVEL, StreamState, blend_window, joints_to_wire, round_half_away
from ..protocol.v2 import POSITION_UNIT_MM
from .arm import ArmBase, LockedRead, Outcome, brake_progress

__all__ = [
    "DEFAULT_RAMP_TIME",
    "RampShape",
    "BLEND_PER_LEVEL",
    "BLEND_MAX",
    "StreamTarget",
    "StreamLogEntry",
    "SimStreamArm",
    "blend_window",
    "segment_time",
    "wire_pose",
]

Clock = Callable[[], float]

#: robot time [s] from rest to full speed and back at a constant acceleration (the stop ramp of a
#: move at speed fraction f lasts f times this; a shorter move ramps over T0): by default the model's
#: joint limits give it, max over the joints of velocity / acceleration (Kinematics.limits.ramp_time;
#: the accelerations of panasonic_vr006l_support's kinematics_vr006l.yaml, an assumption of velocity /
#: 0.1 s to measure on the real arm): 0.1 s. This one is the model's, for an arm whose kinematics
#: know no accelerations.
DEFAULT_RAMP_TIME = model_ramp_time()

_EPS = 1e-12


class RampShape(enum.Enum):
    """The shape of the arm's speed ramps (an assumption about the real arm, doc/controller_program.md
    §10.9): ``linear`` (constant acceleration, the default) or ``s_curve`` (smoothstep: the speed
    goes as ``3x^2 - 2x^3`` of the ramp's share ``x``, the acceleration rises from 0 and falls back
    to 0; same duration and distance as the linear ramp)."""

    LINEAR = "linear"
    S_CURVE = "s_curve"

    parse = validate.choice_parser(MotionError, "ramp_shape must be {words}, got {value!r}")


def _s_area(x: float) -> float:
    """Distance covered over the share ``x`` (0..1) of an S-shaped ramp from rest to speed 1 lasting
    1: the integral of the smoothstep 3x^2 - 2x^3 (1/2 at x = 1, as the linear ramp's x^2 / 2)."""
    return x * x * x - 0.5 * x * x * x * x


def check_accelerations(value: Any, joints: int = 6) -> Optional[Tuple[float, ...]]:
    """Per-axis acceleration limits [rad/s^2] from a sequence of ``joints`` finite numbers > 0 (None:
    none given); MotionError naming the bad one otherwise."""
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != joints:
        raise MotionError("accelerations must be %d numbers > 0 (rad/s^2, joint_1 .. joint_%d), got %r"
                          % (joints, joints, value))
    out = []
    for i, a in enumerate(value):
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not math.isfinite(a) or a <= 0.0:
            raise MotionError("accelerations: joint_%d must be a finite number > 0 (rad/s^2), got %r"
                              % (i + 1, a))
        out.append(float(a))
    return tuple(out)


def segment_time(move_time: float, ramp_in: float, ramp_out: float) -> float:
    """How long a segment of move time T0 lasts with those ramps: T0 + (r_in + r_out) / 2."""
    return move_time + 0.5 * (ramp_in + ramp_out)


def wire_pose(pose: ControllerPose) -> Tuple[int, ...]:
    """The v2 feedback pose: X, Y, Z in 0.01 mm, Rx, Ry, Rz in 0.001 degree (wrapped into
    (-180, 180] degrees), rounded half away from zero."""
    values = pose.as_tuple()
    out = [round_half_away(v / POSITION_UNIT_MM) for v in values[:3]]
    for v in values[3:]:
        w = round_half_away(wrap_degrees(v) * 1000.0)
        out.append(w - 360000 if w > 180000 else w)
    return tuple(out)


@dataclass(frozen=True)
class StreamTarget:
    """One joint target taken from the wire."""

    seq: int
    wire_joints: Tuple[int, ...]        # as received: 0.001 degree
    speed: int                          # 0.1 % of the joint speed limits (1..1000)
    smooth: int
    taken_time: float

    @property
    def joints(self) -> Tuple[float, ...]:
        return tuple(math.radians(v * 0.001) for v in self.wire_joints)

    @property
    def speed_fraction(self) -> float:
        return self.speed / 1000.0

    @property
    def log_target(self) -> Tuple[int, ...]:
        """The target as its log entry shows it (the wire's values; v2: the joints in 0.001 deg)."""
        return self.wire_joints

    @property
    def move_type(self) -> str:
        """The move its log entry names."""
        return "JOINT"


@dataclass(frozen=True)
class StreamLogEntry:
    """One v2 target the controller handled: taken and then executed / blended / stopped, or refused
    (``rejected`` with the wire's reject code)."""

    seq: int
    target: Tuple[int, ...]             # as received: v2 the joints in 0.001 degree, v3 the pose (0.1 mm, 0.01 deg)
    speed: int                          # 0.1 %
    smooth: int
    outcome: Outcome
    reason: str
    taken_time: float                   # clock time it was taken (or refused)
    start_time: Optional[float]         # clock time its segment began (None: it never moved)
    end_time: float                     # clock time of the outcome
    final_joints: Tuple[int, ...]       # the arm's joints at the outcome, 0.001 degree
    reject_code: int = 0
    move_type: str = "JOINT"

    @property
    def duration(self) -> float:
        """From the start of its segment (or from being taken) to the outcome."""
        return self.end_time - (self.start_time if self.start_time is not None else self.taken_time)

    def to_dict(self) -> Dict[str, Any]:
        return {
            "seq": self.seq, "move_type": self.move_type, "target": list(self.target),
            "speed": self.speed, "smooth": self.smooth, "outcome": self.outcome.value,
            "reason": self.reason, "reject_code": self.reject_code, "taken_time": self.taken_time,
            "start_time": self.start_time, "time": self.end_time, "duration": self.duration,
            "final_joints": list(self.final_joints),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)


class _Segment:
    """One segment on the path-time axis (see the module docstring for the profile)."""

    def __init__(self, target: StreamTarget, start: np.ndarray, t0: float, ramp_in: float,
                 vmax: np.ndarray, ramp_time: float, wall_start: float, *, fraction: Optional[float] = None,
                 accelerations: Optional[np.ndarray] = None, shape: RampShape = RampShape.LINEAR) -> None:
        f = target.speed_fraction if fraction is None else fraction
        self.target = target
        self.start = start
        self.end = np.array(target.joints)
        self.delta = self.end - start
        self.move_time = float(np.max(np.abs(self.delta) / (f * vmax)))
        self.t0 = t0
        self.ramp_in = min(ramp_in, self.move_time)
        if accelerations is None:
            ramp = ramp_time * f
        elif self.move_time > _EPS:            # each joint reaches its cruise speed within its limit
            ramp = float(np.max(np.abs(self.delta) / (self.move_time * accelerations)))
        else:
            ramp = 0.0
        self.stop_ramp = min(ramp, self.move_time)
        self.ramp_out: Optional[float] = None         # decided at the decision point
        self.blend = 0.0                              # > 0: blends into the next over this window
        self.wall_start = wall_start
        self.s_curve = shape is RampShape.S_CURVE

    @property
    def zero(self) -> bool:
        return self.move_time <= _EPS

    def decision_time(self) -> float:
        w_max = blend_window(self.target.smooth, self.move_time, self.move_time)
        return self.t0 + self.move_time + 0.5 * self.ramp_in - 0.5 * max(w_max, self.stop_ramp)

    def end_time(self) -> float:
        assert self.ramp_out is not None
        return self.t0 + segment_time(self.move_time, self.ramp_in, self.ramp_out)

    def progress(self, t: float) -> float:
        """Normalised progress s at path time t (the cruise goes on while ramp_out is undecided)."""
        if self.zero:
            return 1.0
        u = t - self.t0
        if u <= 0.0:
            return 0.0
        v = 1.0 / self.move_time
        r_in = self.ramp_in
        if u < r_in:
            if self.s_curve:
                return v * r_in * _s_area(u / r_in)
            return v * u * u / (2.0 * r_in)
        if self.ramp_out is not None:
            total = self.end_time()
            if u >= total - self.t0:
                return 1.0
            left = total - t
            if left < self.ramp_out:
                if self.s_curve:
                    return 1.0 - v * self.ramp_out * _s_area(left / self.ramp_out)
                return 1.0 - v * left * left / (2.0 * self.ramp_out)
        return v * (u - 0.5 * r_in)

    def position(self, t: float) -> np.ndarray:
        return self.delta * self.progress(t)


class SimStreamArm(ArmBase):
    """A simulated VR-006L running streamed joint targets (see the module docstring)."""

    def __init__(self, kinematics: Optional[Kinematics] = None, *, speed_factor: float = 1.0,
                 initial_pose: Any = HOME_POSE, initial_joints: Optional[Sequence[float]] = None,
                 clock: Clock = time.monotonic, brake_time: float = 0.0,
                 ramp_time: Optional[float] = None, look_ahead: int = 1,
                 configuration: Any = ConfigurationRule.PREVIOUS_TARGET, speed_scale: float = 1.0,
                 blend_across_input_read: bool = True, ramp_shape: Any = RampShape.LINEAR,
                 accelerations: Optional[Sequence[float]] = None) -> None:
        if ramp_time is not None and not (isinstance(ramp_time, (int, float)) and not isinstance(ramp_time, bool)
                                          and math.isfinite(ramp_time) and ramp_time >= 0.0):
            raise MotionError("ramp_time must be a finite number >= 0, got %r" % (ramp_time,))
        if isinstance(look_ahead, bool) or not isinstance(look_ahead, int) or look_ahead < 0:
            raise MotionError("look_ahead must be an integer >= 0, got %r" % (look_ahead,))
        if isinstance(speed_scale, bool) or not isinstance(speed_scale, (int, float)) \
                or not math.isfinite(speed_scale) or speed_scale <= 0.0:
            raise MotionError("speed_scale must be a finite number > 0, got %r" % (speed_scale,))
        if not isinstance(blend_across_input_read, bool):
            raise MotionError("blend_across_input_read must be True or False, got %r" % (blend_across_input_read,))
        self.look_ahead = look_ahead
        #: assumptions about the real G2 (module docstring)
        self.speed_scale = float(speed_scale)
        self.blend_across_input_read = blend_across_input_read
        self.ramp_shape = RampShape.parse(ramp_shape)
        self._init_arm(kinematics, speed_factor, brake_time, initial_pose, initial_joints, clock, configuration)
        self.accelerations = check_accelerations(accelerations, len(self.kin.limits.velocity))
        if self.accelerations is not None and ramp_time is not None:
            raise MotionError("give ramp_time (every joint ramps in that time) or accelerations (per axis), "
                              "not both")
        self._acc = None if self.accelerations is None else np.array(self.accelerations, dtype=float)
        if ramp_time is None:      # the model's joint limits: max velocity / acceleration (0.1 s)
            ramp_time = self.kin.limits.ramp_time
        self.ramp_time = float(DEFAULT_RAMP_TIME if ramp_time is None else ramp_time)
        self.vmax = np.array(self.kin.limits.velocity, dtype=float)
        self._rest = np.array(self._joints, dtype=float)
        self._queue: Deque[StreamTarget] = collections.deque()
        self._active: Optional[_Segment] = None
        self._tail: Optional[_Segment] = None       # a blended segment still finishing its window
        self._waiting = False
        self._done_seq = 0
        self._results: List[StreamLogEntry] = []
        self._tau = 0.0                             # path time at the last step
        self._offset: Optional[float] = None        # path time = robot time - offset (not braking)
        self._brake: Optional[Tuple[float, float, str]] = None   # robot time, path time, reason

    # ------------------------------------------------------------------------------- read-outs
    @property
    def moving(self) -> bool:
        with self._lock:
            return self._active is not None or self._tail is not None

    @property
    def braking(self) -> bool:
        with self._lock:
            return self._brake is not None

    @property
    def state(self) -> StreamState:
        with self._lock:
            if self._brake is not None:
                return StreamState.STOPPING
            if self.moving:
                return StreamState.MOVING
            return StreamState.WAITING if self._waiting else StreamState.IDLE

    done_seq = LockedRead("_done_seq", "The sequence number of the target last reached or blended through (0: none yet).")

    @property
    def active_seq(self) -> int:
        with self._lock:
            return self._active.target.seq if self._active is not None else 0

    @property
    def queued(self) -> Tuple[int, ...]:
        """Sequence numbers taken and not yet passed: the active one, then the look-ahead."""
        with self._lock:
            seqs = [self._active.target.seq] if self._active is not None else []
            return tuple(seqs + [t.seq for t in self._queue])

    def room(self) -> int:
        """How many targets the arm takes now (the active one and ``look_ahead`` more: a queue of
        two by default; none while it stops)."""
        with self._lock:
            if self._brake is not None:
                return 0
            return max(0, 1 + self.look_ahead - len(self._queue) - (self._active is not None))

    def limit_violation(self, joints: Sequence[float]) -> Optional[str]:
        """Why these joints cannot be a target (outside the joint limits), or None."""
        bad = self.kin.limit_violations(joints)
        return "joints outside their limits: " + "; ".join(bad) if bad else None

    def collect(self) -> List[StreamLogEntry]:
        """The entries of the targets that ended since the last call (once)."""
        with self._lock:
            out, self._results = self._results, []
            return out

    # ------------------------------------------------------------------------------- commands
    def push(self, target: StreamTarget, now: Optional[float] = None) -> None:
        """Queue a target (the caller checked :meth:`room`, the faults and the limits). From rest
        it starts at once."""
        with self._lock:
            now = self.clock() if now is None else now
            if self.room() <= 0:
                raise MotionError("target %d: the queue is full" % target.seq)
            self._advance(now)
            self._queue.append(target)
            if self._active is None and self._tail is None:
                self._start_next(self._tau, now, from_rest=True)
            self._update_joints()

    def step(self, now: Optional[float] = None) -> List[StreamLogEntry]:
        """Advance the arm to ``now``; returns the entries of targets that ended (:meth:`collect`)."""
        with self._lock:
            self._advance(self.clock() if now is None else now)
            self._update_joints()
            return self.collect()

    def brake(self, reason: str, now: Optional[float] = None) -> bool:
        """A controlled stop (STOP, link loss): see the module docstring. True if the arm was
        moving and not braking already; the queue is dropped either way."""
        with self._lock:
            now = self.clock() if now is None else now
            self._advance(now)
            # a blend already decided is part of the path: its target stays (the arm brakes on it)
            committed = self._active is not None and self._active.blend > 0.0
            self._drop_queue(reason, now, keep=1 if committed else 0)
            self._waiting = False
            if not self.moving or self._brake is not None:
                self._update_joints()
                return False
            if self._active is not None and self._active.ramp_out is None:
                self._active.ramp_out = self._active.stop_ramp        # no new blend
            if self.brake_time <= 0.0:
                self._halt(reason, now)
            else:
                self._brake = (self._robot_time(now), self._tau, reason)
                self._advance(now)          # a zero-length remainder ends here
            self._update_joints()
            return True

    def stop(self, reason: str, now: Optional[float] = None) -> bool:
        """Stop at once at the position of ``now`` and drop the queue. True if the arm moved."""
        with self._lock:
            return self._abort(reason, now)

    # ------------------------------------------------------------------------------- helpers
    def _abort(self, reason: str, now: Optional[float]) -> bool:
        now = self.clock() if now is None else now
        self._advance(now)
        self._drop_queue(reason, now)
        self._waiting = False
        moved = self.moving
        self._halt(reason, now)
        self._update_joints()
        return moved

    def _robot_time(self, now: float) -> float:
        return now * self.speed_factor

    def _wall(self, robot_time: float) -> float:
        return robot_time / self.speed_factor

    def _path_time(self, rt: float) -> float:
        if self._brake is not None:
            rt_b, tau_b, _ = self._brake
            return tau_b + brake_progress(rt - rt_b, self.brake_time)
        assert self._offset is not None
        return rt - self._offset

    def _wall_of_path(self, tau: float) -> float:
        """Clock time the path reaches path time ``tau`` (inverse of :meth:`_path_time`)."""
        if self._brake is not None:
            rt_b, tau_b, _ = self._brake
            frac = max(0.0, 1.0 - 2.0 * (tau - tau_b) / self.brake_time)
            return self._wall(rt_b + self.brake_time * (1.0 - math.sqrt(frac)))
        assert self._offset is not None
        return self._wall(tau + self._offset)

    def _position(self, tau: float) -> np.ndarray:
        segs = [s for s in (self._tail, self._active) if s is not None]
        if not segs:
            return self._rest
        q = segs[0].start.copy()
        for s in segs:
            q = q + s.position(tau)
        return q

    def _update_joints(self) -> None:
        q = self._position(self._tau)
        joints = tuple(float(v) for v in q)
        if joints != self._joints:
            self._joints = joints
            self._pose = self.kin.fk_pose(joints)

    def _advance(self, now: float) -> None:
        """Run the events (decisions, blend starts, segment ends, the end of a brake) up to ``now``."""
        now = max(now, self._last_step)
        self._last_step = now
        rt = self._robot_time(now)
        if self._offset is None:
            self._offset = rt - self._tau
        while True:
            target = self._path_time(rt)
            when, event = self._next_event()
            if event is not None and when <= target + _EPS:
                self._tau = max(self._tau, when)
                event()
                continue
            self._tau = max(self._tau, target)
            if self._brake is not None and rt - self._brake[0] >= self.brake_time:
                self._halt(self._brake[2], self._wall(self._brake[0] + self.brake_time))
                continue
            break

    def _next_event(self) -> Tuple[float, Optional[Callable[[], None]]]:
        events: List[Tuple[float, Callable[[], None]]] = []
        tail, active = self._tail, self._active
        if tail is not None:
            events.append((tail.end_time(), self._tail_ends))
        if active is not None:
            if active.ramp_out is None:
                events.append((active.decision_time(), self._decide))
            elif active.blend > 0.0:
                events.append((active.end_time() - active.blend, self._blend_starts))
            else:
                events.append((active.end_time(), self._arrive))
        if not events:
            return math.inf, None
        return min(events, key=lambda e: e[0])

    def _decide(self) -> None:
        seg = self._active
        assert seg is not None and seg.ramp_out is None
        if self._queue and self._brake is None and seg.target.smooth > 0 and self.blend_across_input_read:
            nxt = self._queue[0]
            nxt_time = float(np.max(np.abs(np.array(nxt.joints) - seg.end) / (self._fraction(nxt) * self.vmax)))
            w = blend_window(seg.target.smooth, seg.move_time, nxt_time)
            if w > _EPS:
                seg.ramp_out = seg.blend = w
                return
        seg.ramp_out = seg.stop_ramp

    def _blend_starts(self) -> None:
        seg = self._active
        assert seg is not None
        now = self._wall_of_path(self._tau)
        self._tail = seg
        self._active = None
        self._done_seq = seg.target.seq
        self._finish(seg, Outcome.BLENDED, "", now, self._position(self._tau))
        self._start_next(self._tau, now, from_rest=False, ramp_in=seg.blend, start=seg.end)

    def _tail_ends(self) -> None:
        tail = self._tail
        assert tail is not None
        self._tail = None
        if self._active is None:
            self._rest = tail.end.copy()

    def _arrive(self) -> None:
        seg = self._active
        assert seg is not None
        now = self._wall_of_path(self._tau)
        self._active = None
        self._rest = seg.end.copy()
        self._done_seq = seg.target.seq
        self._finish(seg, Outcome.EXECUTED, "", now, seg.end)
        if self._brake is not None:
            self._brake = None                     # the ramp carried it to the point: at rest
            self._offset = self._robot_time(now) - self._tau
            return
        if self._queue:
            self._start_next(self._tau, now, from_rest=True)
        else:
            self._waiting = seg.target.smooth > 0

    def _start_next(self, tau: float, now: float, *, from_rest: bool, ramp_in: float = 0.0,
                    start: Optional[np.ndarray] = None) -> None:
        target = self._queue.popleft()
        begin = self._position(tau) if start is None else start
        seg = _Segment(target, np.array(begin, dtype=float), tau, 0.0, self.vmax, self.ramp_time, now,
                       fraction=self._fraction(target), accelerations=self._acc, shape=self.ramp_shape)
        seg.ramp_in = seg.stop_ramp if from_rest else min(ramp_in, seg.move_time)
        if target.smooth <= 0:
            seg.ramp_out = seg.stop_ramp
        self._waiting = False
        self._active = seg
        if from_rest:
            self._rest = np.array(begin, dtype=float)

    def _fraction(self, target: StreamTarget) -> float:
        """The share of the joint speed limits the arm really runs a target at: its commanded
        fraction times ``speed_scale``, at most 1 (exactly the commanded one at scale 1)."""
        if self.speed_scale == 1.0:
            return target.speed_fraction
        return min(1.0, target.speed_fraction * self.speed_scale)

    def _halt(self, reason: str, now: float) -> None:
        """Freeze the arm where it is now; the active target ends stopped."""
        q = self._position(self._tau)
        seg = self._active
        self._active = self._tail = None
        self._brake = None
        self._offset = self._robot_time(now) - self._tau     # path time follows the clock again
        self._rest = q
        if seg is not None:
            self._finish(seg, Outcome.STOPPED, reason, now, q)

    def _drop_queue(self, reason: str, now: float, keep: int = 0) -> None:
        q = self._position(self._tau)
        dropped = []
        while len(self._queue) > keep:
            dropped.append(self._queue.pop())
        for target in reversed(dropped):
            self._results.append(StreamLogEntry(
                target.seq, target.log_target, target.speed, target.smooth, Outcome.STOPPED,
                "dropped before it started: %s" % reason, target.taken_time, None, now,
                joints_to_wire(q), move_type=target.move_type))

    def _finish(self, seg: _Segment, outcome: Outcome, reason: str, now: float, q: np.ndarray) -> None:
        t = seg.target
        self._results.append(StreamLogEntry(
            t.seq, t.log_target, t.speed, t.smooth, outcome, reason, t.taken_time, seg.wall_start, now,
            joints_to_wire(q), move_type=t.move_type))
