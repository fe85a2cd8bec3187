"""Joint targets commanded on the fly (the ``joint_command`` topic), on the streaming protocols'
path. ROS-free, no I/O: :class:`JointCommander` validates each command in the caller's thread
and hands it to the stream sequencer as a point of a *live* stream job
(:mod:`vr_driver.driver.motion.streaming`, "A live stream").

A command is what industrial_robot_client's streamer and MoveIt Servo send: joint names (the
controller's joints, in any order: reordered) and one point of positions, optionally with a
``time_from_start``. It is refused -- nothing is sent, :class:`JointCommandRefused` says which rule
and by how much -- when:

- the protocol cannot stream (``wire.streams`` false: v1, one target at a time);
- the names are not the controller's joints (unknown, missing, repeated), or the positions do not
  match them in number;
- a value or ``time_from_start`` is not finite (NaN, inf), or ``time_from_start`` is negative;
- a joint is outside its limits;
- the step from the last accepted command (the arm's joints for the first command of a stream)
  needs a joint faster than its velocity limit: the step must be done within
  ``T = min(dt, joint_command_timeout)``, where ``dt`` is the point's ``time_from_start`` when it
  is > 0, else the time since the last accepted command, and for the first command of a stream
  ``joint_command_timeout``. Refused, never clipped: the message names the joint, its speed and the
  limit. The controller runs the step at the speed that takes ``T`` (0.1 % steps, rounded up);
- the straight joint move of the step leaves the workspace box (sampled as a PTP preview, like
  every stream segment), or collides with the arm itself or the scene (``collision``; the driver's
  collision checks, driver/checks/scene_guard.py);
- a Cartesian stream family (v3, ``stream_prep.CartesianStreams.step_refusal``): the pose the wire carries (FK,
  rounded to its resolution) is solved by the controller as the solution nearest the previous
  target's joints; that must be the commanded joints within the stream's configuration tolerance;
- motion is not possible (link, e-stop, drives, program), or there is no valid joint state;
- a trajectory or move runs, is queued, or a stop is settling: joint_command does not interrupt
  them (stop them with stop_motion first). The other way round, a trajectory or move goal takes
  over from a running joint_command stream (see the streaming module).

A stream starts with the first accepted command, from the arm's joints, and ends when no command
came for ``joint_command_timeout``: the arm is then at rest at the last accepted target (it never
runs past it: each point is one the controller blends through only into a target it already has).
A new command replaces the last one while that one has not been put on the wire; once it has, the
controller may have taken it and it is never recalled. For that replacement the new command is
also validated from the last point on the wire (the sequencer's ``live_anchor``).
"""
from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional, Sequence, Tuple

from ...errors import CollisionError, VrDriverError
from ...kinematics.solver import Kinematics
from ...params import DriverParams
from ...protocol.base import Protocol
from .job_control import JobControl
from ..motion.jobs import MoveJob, StreamPoint
from .path_checks import PathChecks
from ..motion.status import DriverStatus
from .stream_prep import JointStreams

log = logging.getLogger("vr_driver.driver")

__all__ = ["JointCommandRefused", "JointCommander", "REFUSAL_KINDS"]

#: the rules a command can break (JointCommandRefused.kind; the diagnostics count each)
REFUSAL_KINDS = ("message", "protocol", "names", "not_finite", "limits", "speed", "workspace", "configuration",
                 "state", "busy", "collision")


class JointCommandRefused(VrDriverError):
    """A joint command that was refused; nothing was sent. ``kind``: one of REFUSAL_KINDS."""

    def __init__(self, kind: str, reason: str) -> None:
        self.kind = kind
        super().__init__("joint_command refused (%s): %s; nothing was sent" % (kind, reason))


@dataclass(frozen=True)
class CommandCounters:
    """What the topic did so far (for /diagnostics)."""

    accepted: int
    refused: Dict[str, int]
    streams: int                       # live streams started
    last_refusal: str

    @property
    def refused_total(self) -> int:
        return sum(self.refused.values())


class JointCommander:
    """The joint_command state of one driver (module docstring): ``status(now)`` is the driver's
    status, ``jobs`` its job control (the queue the live stream joins), ``checks`` and ``streams``
    its path checks and stream preparation (None: a protocol that does not stream).
    :meth:`command` may be called from any thread; commands are validated one at a time."""

    def __init__(self, params: DriverParams, kinematics: Kinematics, wire: Protocol, clock: Callable[[], float],
                 status: Callable[[float], DriverStatus], jobs: JobControl, checks: PathChecks,
                 streams: Optional[JointStreams]) -> None:
        self.params = params
        self.kin = kinematics
        self.wire = wire
        self.clock = clock
        self.status = status
        self.jobs = jobs
        self.checks = checks
        self.streams = streams
        self._lock = threading.Lock()
        self._job: Optional[MoveJob] = None          # the live stream (None: none yet)
        self._last: Tuple[float, ...] = ()           # its last accepted command (controller order)
        self._stamp = 0.0                            # when it was accepted (clock)
        self._created = 0.0                          # when the live stream's first command was
        self._accepted = 0
        self._streams = 0
        self._refused = {kind: 0 for kind in REFUSAL_KINDS}
        self._last_refusal = ""

    def counters(self) -> CommandCounters:
        with self._lock:
            return CommandCounters(self._accepted, dict(self._refused), self._streams, self._last_refusal)

    def refuse(self, kind: str, reason: str) -> JointCommandRefused:
        """Count a refusal made before :meth:`command` (e.g. a message that is not one point) and
        return its exception to raise."""
        exc = JointCommandRefused(kind, reason)
        with self._lock:
            self._refused[kind] += 1
            self._last_refusal = str(exc)
        return exc

    def trajectory(self, names: Sequence[str], points: Sequence[Any]) -> MoveJob:
        """A trajectory_msgs/JointTrajectory-like command (``points``: objects with ``positions``
        and ``time_from_start``, a duration with ``to_sec()`` or seconds): exactly one point, as
        industrial_robot_client's streamer and MoveIt Servo send; velocities, accelerations and
        efforts are not used (the speed comes from the step and its time)."""
        if len(points) != 1:
            raise self.refuse("message", "a joint command has exactly one point, this one has %d (a "
                              "whole path goes to joint_path_command or joint_trajectory_action)"
                              % len(points))
        point = points[0]
        tfs = getattr(point, "time_from_start", 0.0)
        tfs = tfs.to_sec() if hasattr(tfs, "to_sec") else tfs
        return self.command(names, getattr(point, "positions", ()), tfs)

    def command(self, names: Sequence[str], positions: Sequence[Any], time_from_start: float = 0.0
                ) -> MoveJob:
        """Validate one command and stream it (module docstring). Returns the live job it joined;
        raises :class:`JointCommandRefused` (nothing sent)."""
        with self._lock:
            try:
                job = self._command(names, positions, time_from_start)
            except JointCommandRefused as exc:
                self._refused[exc.kind] += 1
                self._last_refusal = str(exc)
                raise
            self._accepted += 1
            return job

    # ------------------------------------------------------------------ the rules
    def _command(self, names: Sequence[str], positions: Sequence[Any], time_from_start: Any) -> MoveJob:
        wire = self.wire
        if not wire.streams:
            raise JointCommandRefused(
                "protocol", "protocol %s cannot stream joint targets (one target at a time, the arm "
                "stops at each); use joint_path_command or joint_trajectory_action, or a streaming "
                "protocol (v2, v3)" % wire.name)
        q = self._reordered(names, positions)
        try:
            dt_given = float(time_from_start)
        except (TypeError, ValueError):
            raise JointCommandRefused("not_finite", "time_from_start %r is not a number"
                                      % (time_from_start,)) from None
        if not math.isfinite(dt_given) or dt_given < 0.0:
            raise JointCommandRefused("not_finite", "time_from_start %r must be finite and >= 0"
                                      % (time_from_start,))
        try:
            q = self.kin.check_limits(q)
        except VrDriverError as exc:
            raise JointCommandRefused("limits", str(exc)) from None
        now = self.clock()
        status = self.status(now)
        if not status.motion_possible:
            raise JointCommandRefused("state", "motion is not possible: %s" % status.why_no_motion())
        timeout = self.params.joint_command_timeout
        view = self.jobs.view
        job = self._job
        other = self.jobs.last_posted                    # a move or trajectory posted meanwhile
        if other is not None and other is not job and not other.done:
            raise JointCommandRefused("busy", "a trajectory or move (job %d) is %s; joint_command "
                                      "starts only when nothing else runs (stop it with stop_motion "
                                      "first)" % (other.id, other.phase.value))
        alive = (job is not None and not job.done and not job.closed
                 and now - self._stamp <= timeout)
        if alive and view.settling:
            raise JointCommandRefused("busy", "the stream was stopped and the arm is coming to rest; "
                                      "the next command starts a new stream from there")
        if alive:
            assert job is not None
            prev = self._last
            dt = dt_given if dt_given > 0.0 else now - self._stamp
            anchor = view.live_anchor if view.job is job and view.live_anchor is not None else job.start
        else:
            if view.job is not None or view.queue_length or view.settling:
                running = view.job.id if view.job is not None else None
                raise JointCommandRefused(
                    "busy", "a trajectory or move is %s%s; joint_command starts only when nothing "
                    "else runs (stop it with stop_motion first)"
                    % ("stopping" if view.settling else "running" if view.job is not None else "queued",
                       " (job %d)" % running if running is not None else ""))
            if status.joints is None or not status.joints_valid:
                raise JointCommandRefused("state", "no valid joint state of the arm to start from")
            prev = tuple(status.joints)
            dt = dt_given if dt_given > 0.0 else timeout
            anchor = prev
        step_time = max(min(dt, timeout), 1e-6)
        origin = "the last accepted command" if alive else "the arm's joints"
        speed = self._speed(prev, q, step_time, origin)
        anchored_speed = self._speed(anchor, q, step_time, "")
        pose = self._check_path(prev, q, origin)
        if anchor != prev:
            self._check_path(anchor, q, "the last target on the wire")
        smooth = self.params.stream_smooth
        if alive:
            assert job is not None
            t = now - self._created + step_time          # its planned arrival from the stream's start
            point = StreamPoint(q, speed, smooth, t, len(job.points), pose=pose)
            anchored = StreamPoint(q, anchored_speed, smooth, t, len(job.points), pose=pose)
            self.jobs.extend_live(job, point, anchored, anchor, now)
        else:
            point = StreamPoint(q, speed, smooth, step_time, 1, pose=pose)
            job = MoveJob(None, None, points=(point,), start=prev, live=True, stamp=now)
            self.jobs.post_job(job)
            self._job, self._created = job, now
            self._streams += 1
            log.info("joint_command: stream started (job %d) from [%s] deg", job.id,
                     " ".join("%.2f" % math.degrees(v) for v in prev))
        self._last, self._stamp = q, now
        self.jobs.wake()
        return job

    def _reordered(self, names: Sequence[str], positions: Sequence[Any]) -> Tuple[float, ...]:
        """The positions in the controller's joint order; refused for wrong names or counts and
        for values that are not finite numbers."""
        expected = list(self.params.controller_joint_names)
        try:
            names = [str(n) for n in names]
            values = list(positions)
        except TypeError:
            raise JointCommandRefused("names", "expected a list of joint names and a list of "
                                      "positions") from None
        unknown = [n for n in names if n not in expected]
        missing = [n for n in expected if n not in names]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if unknown or missing or repeated:
            parts = []
            if unknown:
                parts.append("unknown %s" % unknown)
            if missing:
                parts.append("missing %s" % missing)
            if repeated:
                parts.append("repeated %s" % repeated)
            raise JointCommandRefused("names", "joint names %s: %s (the controller's joints: %s)"
                                      % (names, ", ".join(parts), ", ".join(expected)))
        if len(values) != len(names):
            raise JointCommandRefused("names", "%d positions for %d joint names"
                                      % (len(values), len(names)))
        q = [0.0] * len(expected)
        for name, value in zip(names, values):
            try:
                v = float(value)
            except (TypeError, ValueError):
                v = float("nan")
            if not math.isfinite(v):
                raise JointCommandRefused("not_finite", "%s = %r is not a finite number" % (name, value))
            q[expected.index(name)] = v
        return tuple(q)

    def _speed(self, prev: Sequence[float], q: Sequence[float], step_time: float, origin: str) -> int:
        """The wire speed (0.1 % of the joint speed limits, 1..1000) that moves ``prev`` -> ``q`` in
        ``step_time``. With ``origin`` (what ``prev`` is, for the message) a step that needs more
        than a joint's limit is refused, naming the joint; without, it gets full speed (the arm just
        takes longer)."""
        refuse = bool(origin)
        vmax = self.kin.limits.velocity
        ratios = [abs(b - a) / (step_time * v) for a, b, v in zip(prev, q, vmax)]
        worst = max(range(len(ratios)), key=ratios.__getitem__)
        if refuse and ratios[worst] > 1.0 + 1e-9:
            names = self.params.controller_joint_names
            raise JointCommandRefused(
                "speed", "%s would move %.4f rad in %.4g s: %.3f rad/s, %.0f %% of its %.3g rad/s "
                "limit (%.3g rad/s too fast; the step from %s)"
                % (names[worst], abs(q[worst] - prev[worst]), step_time,
                   ratios[worst] * vmax[worst], 100.0 * ratios[worst], vmax[worst],
                   (ratios[worst] - 1.0) * vmax[worst], origin))
        return min(1000, max(1, int(math.ceil(1000.0 * ratios[worst] - 1e-9))))

    def _check_path(self, prev: Tuple[float, ...], q: Tuple[float, ...], origin: str) -> Any:
        """The straight joint move ``prev`` -> ``q`` inside the workspace box; for a Cartesian
        protocol the pose the wire carries, solved as the controller will from ``prev``, must be
        ``q``. Returns that pose (None for a joint protocol)."""
        try:
            self.checks.check_joint_move(prev, q)
        except VrDriverError as exc:
            raise JointCommandRefused("workspace", "the step from %s: %s" % (origin, exc)) from None
        try:         # one chord: a few checks of ~10 us each (scene_guard)
            self.checks.check_collision_path((prev, q), "the step from %s" % origin)
        except CollisionError as exc:
            raise JointCommandRefused("collision", str(exc)) from None
        try:        # (a Cartesian stream: the coordinate search only, near joint_5 = 0 a few dozen IK solutions)
            pose, error = self.streams.step_refusal(prev, q)      # type: ignore[union-attr]  (it streams)
        except VrDriverError as exc:
            raise JointCommandRefused("configuration", "from %s: the controller cannot solve its pose: %s"
                                      % (origin, exc)) from None
        if error:
            raise JointCommandRefused("configuration", "from %s: %s; use a protocol with joint targets"
                                      % (origin, error))
        return pose
