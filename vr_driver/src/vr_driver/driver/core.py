"""The driver core behind the ROS node `interface` (ROS-free, testable with plain pytest).

:class:`DriverCore` composes two parts stepped by a clock:

- :class:`~vr_driver.driver.link.LinkSupervisor` (port, DP master, session, freshness, counters),
- :class:`~vr_driver.driver.sequencer.MotionSequencer` (queue, handshake, stops, outcomes),

and one bus iteration (:meth:`DriverCore.spin_once`) only steps them: the link runs a DP cycle and
returns a sample, the joints of the reported pose are solved, the sequencer decides what to send,
and an immutable :class:`DriverStatus` snapshot is published. :meth:`DriverCore.start` runs that
iteration at ``cycle_rate`` in the bus thread; tests call :meth:`spin_once` themselves with a fake
clock, in one thread.

Requests from other threads (:meth:`submit`, :meth:`submit_joint_path`, :meth:`cancel`,
:meth:`stop_motion`) validate and plan in the caller's thread -- never on the bus thread, and
under no lock the bus needs -- and then post the job to the sequencer. A job that must be planned
again (the arm is not where it was planned from) is planned on the core's planning thread
(:meth:`run_planning` in stepped tests).

Safety rules enforced here and in the parts (README "Reliability"):
- nothing reaches the bus that was not validated first: finite values, int16, the workspace box on
  the rounded values that are sent *and on every sample of the previewed path*, the joint limits
  on every sample, reachability, and a controller that says motion is possible;
- each target is requested exactly once; a job whose link is lost, that times out or is stopped
  is ended with its reason and never re-sent; a stopped job ends when the arm is at rest, with the
  rest pose;
- what :meth:`status` returns is never older than ``link_timeout``: a snapshot or a feedback
  record older than that reads as a lost link (no pose, no joints, in error).
"""
from __future__ import annotations

import collections
import logging
import math
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable, Deque, Dict, List, Optional, Sequence, Tuple

from pyprofibus_vendor.phy import Link

from ..bus.health import BusHealthSummary
from ..errors import CollisionError, VrDriverError
from ..kinematics.solver import Kinematics
from ..kinematics.preview import MotionPlanner, check_envelope
from ..params import DriverParams
from ..poses import ControllerPose, MoveType
from ..protocol.v1 import Feedback, StatusBits, commands_for
from .joint_command import JointCommander
from .scene_guard import SceneGuard
from .jobs import MoveJob, MoveRequest, Preview, StreamPoint, SubmitMode
from .link import (ERROR_CONTROLLER, ERROR_LINK, ERROR_NONE, LinkCounters, LinkSample, LinkState,
                   LinkSupervisor, open_serial_link)
from .sequencer import MotionSequencer, why_no_motion
from .stations import ControllerIo, IoLine
from .streaming import (MAX_CARTESIAN_TOLERANCE, MAX_STREAM_TOLERANCE, MIN_SEGMENT_CYCLES, StreamSequencer,
                        stream_points, stream_speeds)
from .tracking import JointTracker
from .trajectories import ValidTrajectory, thin

log = logging.getLogger("vr_driver.driver")
#: s: the bus period while a stream's end is due (StreamSequencer.end_due)
END_POLL_PERIOD = 0.01
#: rad: a Cartesian stream's target, solved as the controller will (the IK solution nearest the
#: previous target's joints), must land this near the planned point (every joint); farther, the
#: controller would run another configuration than the one planned and checked
CONFIGURATION_TOLERANCE = math.radians(1.0)
#: [rad] the widest joint step between two points of a Cartesian stream (streaming.split_long): the
#: controller takes the solution nearest the previous target, the planned one only while a joint
#: turns by well under half a turn between them
CARTESIAN_MAX_STEP = math.radians(90.0)

Clock = Callable[[], float]

__all__ = ["DriverCore", "DriverError", "DriverStatus", "ModelCheck", "TrajectoryRun"]


class DriverError(VrDriverError):
    """A request the driver refuses (not connected, e-stop, bad input...). The message says why."""


@dataclass(frozen=True)
class ModelCheck:
    """Our model against the controller's, at a connection (protocols that report both the joints
    and the pose: v2): how far the reported pose lies from our FK of the reported joints."""

    session: int                       # the link session it was made in
    position_mm: float                 # the largest of |dX|, |dY|, |dZ|
    angle_deg: float                   # the largest of |dRx|, |dRy|, |dRz| (wrapped)
    ok: bool                           # within model_check_position / model_check_angle
    joints: Tuple[float, ...]          # the reported joints it was made at [rad]

    def describe(self) -> str:
        text = "the controller's pose is %.3f mm / %.3f deg from our model's FK of its joints" % (
            self.position_mm, self.angle_deg)
        if not self.ok:
            text += (": the model's dimensions (panasonic_vr006l_support/config/kinematics_vr006l.yaml) "
                     "are not the robot's -- Cartesian targets, the workspace box and the RViz preview "
                     "are off by about that much; calibrate the model (README, The robot model)")
        return text


@dataclass(frozen=True)
class DriverStatus:
    """A consistent snapshot of everything the node publishes."""

    time: float
    link: LinkState
    link_reason: str
    feedback: Optional[Feedback]              # None unless the link is CONNECTED
    pose: Optional[ControllerPose]
    joints: Optional[Tuple[float, ...]]
    joints_valid: bool
    job: Optional[MoveJob]
    queue_length: int
    cycle_rate: float                          # measured DP cycles per second
    counters: LinkCounters
    master_counters: Dict[str, int]
    slave_state: str
    last_diag: str
    error_code: int
    error_reason: str
    feedback_time: Optional[float] = None     # clock time the feedback record arrived (None: none)
    record_time: Optional[float] = None       # clock time the controller's record was taken: the
    #                                           reply that brought it began then (arrival less its
    #                                           time on the wire); a new value = a new sample
    settling: bool = False                    # a stopped move is waiting for the arm to be at rest
    model_check: Optional[ModelCheck] = None  # the model against the controller (v2), latest connection
    bus_health: Optional[BusHealthSummary] = None   # the gaps between the card's replies, last minute

    @property
    def connected(self) -> bool:
        return self.link is LinkState.CONNECTED

    @property
    def motion_possible(self) -> bool:
        fb = self.feedback
        if fb is None or not self.connected:
            return False
        return not why_no_motion(fb)

    def why_no_motion(self) -> str:
        """Why motion is not possible now ("" when it is)."""
        if not self.connected or self.feedback is None:
            return "no link to the controller (%s: %s)" % (self.link.value, self.link_reason)
        return why_no_motion(self.feedback)

    def stale(self, now: float, limit: float) -> "DriverStatus":
        """This snapshot as it must be read at ``now``: unchanged while it and its feedback are at
        most ``limit`` seconds old; otherwise a lost link -- no feedback, no pose, no joints, in
        error -- never a repeat of old good news."""
        age = now - self.time
        fb_age = None if self.feedback_time is None else now - self.feedback_time
        if age <= limit and (fb_age is None or fb_age <= limit):
            return self
        if age > limit:
            reason = "the driver's status is %.2f s old (the bus loop stalled)" % age
        else:
            reason = "the controller's last record is %.2f s old" % fb_age
        return replace(self, link=LinkState.STALE, link_reason=reason, feedback=None, pose=None,
                       joints_valid=False, error_code=ERROR_LINK, error_reason=reason,
                       feedback_time=None, record_time=None)


class TrajectoryRun:
    """A planner trajectory on its way (v1: a joint path of its thinned points). ``jobs[i]``
    goes to ``traj.positions[kept[i + 1]]``."""

    def __init__(self, traj: ValidTrajectory, kept: List[int], jobs: List[MoveJob], started: float) -> None:
        self.traj = traj
        self.kept = kept
        self.jobs = jobs
        self.started = started

    @property
    def done(self) -> bool:
        return all(job.done for job in self.jobs)

    @property
    def success(self) -> bool:
        return self.done and all(job.result is not None and job.result.success for job in self.jobs)

    def failure(self) -> Optional[MoveJob]:
        """The first job that ended without success (None: none so far)."""
        for job in self.jobs:
            if job.done and job.result is not None and not job.result.success:
                return job
        return None

    def points_done(self) -> int:
        """How many planned points have been reached (kept points passed, dropped ones between)."""
        if len(self.jobs) == 1 and self.jobs[0].points:          # a v2 stream
            job = self.jobs[0]
            return job.points[job.points_done - 1].index if job.points_done else 0
        n = 0
        for job, index in zip(self.jobs, self.kept[1:]):
            if job.done and job.result is not None and job.result.success:
                n = index
        return n


def _fmt_pose(pose: ControllerPose) -> str:
    return "(%.1f, %.1f, %.1f mm, %.2f, %.2f, %.2f deg)" % pose.as_tuple()


def driver_kinematics(params: DriverParams) -> Kinematics:
    """The driver's model: the package's (``model`` empty) or the robot of the ``model`` file
    (Kinematics.from_true_model: e.g. what ``calibrate fit --write`` produced), with ``prefix`` and
    ``tcp_offset`` applied. Raises ParamError naming ``model`` when the file cannot be made into one."""
    from ..errors import ModelError
    from ..params import ParamError
    try:
        kin = Kinematics.from_true_model(params.model or None, prefix=params.prefix)
    except ModelError as exc:
        if not params.model:
            raise
        raise ParamError("model", params.model, str(exc)) from None
    if any(params.tcp_offset):
        kin.conventions = kin.conventions.with_tcp(params.tcp_offset)
    return kin


def _load_cell(path: str):
    """The Scene of the cell file ``path`` (None for ""); ParamError naming ``scene`` with the
    SceneError's words (the file, the entry and the key) when it is bad."""
    if not path:
        return None
    from ..errors import SceneError
    from ..kinematics.scene import load_scene
    from ..params import ParamError
    try:
        return load_scene(path)
    except SceneError as exc:
        raise ParamError("scene", path, str(exc)) from None


class DriverCore:
    """See the module docstring. ``open_link(device, baud)`` makes the link (tests may pass a
    factory for an in-memory or fault-injecting link)."""

    def __init__(self, params: DriverParams, kinematics: Optional[Kinematics] = None,
                 planner: Optional[MotionPlanner] = None, clock: Clock = time.monotonic,
                 open_link: Callable[[str, int], Link] = open_serial_link) -> None:
        self.params = params
        self.bus = params.bus()
        self.slave_config = self.bus.slaves[0]
        if kinematics is None:
            kinematics = driver_kinematics(params)     # the package's model or ``model``'s
        self.kin = kinematics
        self.planner = planner or MotionPlanner(self.kin)
        self.clock = clock
        # the I/O stations beside the controller (io_signals), cycled by the link's master
        signals = params.signal_map(self.bus)
        self.io: Optional[IoLine] = IoLine(signals, params.link_timeout) if signals is not None else None
        self.link = LinkSupervisor(params, self.bus, clock, open_link, stations=self.io)
        self.protocol = params.wire
        self.streaming = self.protocol.streams
        self.sequencer = (StreamSequencer if self.streaming else MotionSequencer)(
            params, clock, self._schedule_replan)
        # the controller's own I/O (v2) as a station of the signal map at the controller's address
        self.controller_io: Optional[ControllerIo] = None
        if self.io is not None and self.protocol.controller_io and \
                any(st.address == self.slave_config.address for st in self.io.map.stations):
            self.controller_io = ControllerIo(self.slave_config.address, self._set_controller_outputs)
            self.io.add_local(self.controller_io)
        self._stop = threading.Event()
        self._wake = threading.Event()      # set by requests: run a bus cycle now, not at the next tick
        self._thread: Optional[threading.Thread] = None
        self._planning: Deque[Callable[[], None]] = collections.deque()
        # one planner at a time: requests plan in their callers' threads (an action server runs one
        # per goal); twenty goals planning at once starved the bus thread of the interpreter lock
        # for over 0.3 s (every blocking call of a DP cycle waits its turn behind each of them) and
        # the card's watchdog expired. Waiting here costs no CPU and no interpreter lock.
        self._planning_gate = threading.Lock()
        self._planning_cond = threading.Condition()
        self._planning_thread: Optional[threading.Thread] = None
        self._last_posted: Optional[MoveJob] = None
        self._last_record = b""
        self._repeat_now = False          # run the next bus cycle at once (a new v2 record)
        self._repeated = False            # this cycle was such a repeat
        self._joints: Optional[Tuple[float, ...]] = None
        self._joints_valid = False
        # the joints of the reported pose (v1, v3): the commanded branch, the configuration held
        self.tracker = JointTracker(self.kin, self.protocol.pose_resolution)
        self._model_check: Optional[ModelCheck] = None
        self._listeners: List[Callable[[DriverStatus], None]] = []
        self._status = self._snapshot(self.clock(), None)
        self.joint_commander = JointCommander(self)
        # the cell and the collision checks (scene_guard; MissingDependency: a scene but no libraries)
        self.scene_guard = SceneGuard(self.kin, self._planning_gate, _load_cell(params.scene),
                                      params.collision_padding, params.collision_check, params.prefix,
                                      model=params.model)

    @property
    def handshake(self):
        """The master side of the target handshake (read-only use: ``handshake.ready``)."""
        return self.sequencer.handshake

    # ------------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._planning_thread = threading.Thread(target=self._plan_loop, name="vr_driver-planning",
                                                 daemon=True)
        self._planning_thread.start()
        self._thread = threading.Thread(target=self._run, name="vr_driver-bus", daemon=True)
        self._thread.start()

    def request_stop(self) -> None:
        """Ask the bus thread to end, without waiting (safe from a signal handler or a ROS shutdown
        hook, which may interrupt a thread that holds a lock :meth:`stop` needs)."""
        self._stop.set()
        self._wake.set()
        self.link.poke()

    def stop(self, timeout: float = 3.0) -> None:
        self._stop.set()
        self._wake.set()
        self.link.poke()
        with self._planning_cond:
            self._planning_cond.notify_all()
        for attr in ("_thread", "_planning_thread"):
            thread = getattr(self, attr)
            if thread is not None:
                thread.join(timeout)
                setattr(self, attr, None)
        self.sequencer.shutdown("driver shut down")
        self.link.close()

    def add_listener(self, callback: Callable[[DriverStatus], None]) -> None:
        """``callback(status)`` after every bus iteration (bus thread)."""
        self._listeners.append(callback)

    # ------------------------------------------------------------------------ queries
    def status(self, now: Optional[float] = None) -> DriverStatus:
        """The latest snapshot, read at ``now`` (default: the clock): one older than
        ``link_timeout``, or with feedback older than that, reads as a lost link."""
        return self._status.stale(self.clock() if now is None else now, self.params.link_timeout)

    @property
    def joint_names(self) -> Tuple[str, ...]:
        return self.params.controller_joint_names

    # ------------------------------------------------------------------------ requests
    def preview(self, request: MoveRequest, start_joints: Optional[Sequence[float]] = None) -> Preview:
        """Validate and plan ``request`` from the current joints (or ``start_joints``); sends
        nothing. The whole previewed path must stay inside the joint limits and the workspace box.
        Raises VrDriverError (PoseError, KinematicsError, MotionError, EnvelopeError,
        ProtocolError, DriverError) with the reason."""
        if start_joints is None:
            start_joints = self._current_joints()
        commands = tuple(commands_for(request.move_type, request.target, request.via,
                                      self.params.workspace))
        # plan to exactly what will be sent (whole mm / deg)
        target = commands[-1].pose
        via = commands[0].pose if len(commands) == 2 else None
        with self._planning_gate:
            trajectory = self.planner.plan(request.move_type, start_joints, target, via)
        check_envelope(trajectory, self.params.workspace)
        self.check_collision_path(trajectory.positions, "%s path" % request.move_type.name, trajectory.times)
        return Preview(request, commands, trajectory, tuple(trajectory.goal))

    def claim_ticket(self) -> int:
        """A ticket in arrival order for a goal that preempts (take it as the goal arrives, pass it
        to :meth:`submit`): of two goals, the one that arrived later wins, whichever is planned
        first; an older one submitted after a newer ticket was claimed is superseded."""
        return self.sequencer.claim_ticket()

    def submit(self, request: MoveRequest, on_update: Optional[Callable[[MoveJob], None]] = None,
               mode: SubmitMode = SubmitMode.APPEND, ticket: Optional[int] = None) -> MoveJob:
        """Validate, preview and queue a move. Raises (and queues nothing) when it is invalid,
        unreachable, leaves the envelope, or the controller cannot move now. ``mode``: APPEND
        (behind the queue) or PREEMPT (stop the running move, drop the queue; ``ticket`` from
        :meth:`claim_ticket` keeps arrival order)."""
        self._require_motion_possible()
        preview = self.preview(request, self._planning_start(mode))
        if self.streaming:
            job = MoveJob(preview, on_update, ticket=ticket, points=self._preview_stream(preview))
        else:
            job = MoveJob(preview, on_update, ticket=ticket)
        self._last_posted = job
        self.sequencer.add([job], mode)
        self.wake()
        log.info("job %d queued (%s): %s %s", job.id, mode.value, request.move_type.name,
                 " then ".join(c.describe() for c in job.preview.commands))
        return job

    def submit_joint_path(self, names: Sequence[str], points: Sequence[Sequence[float]],
                          on_update: Optional[Callable[[MoveJob], None]] = None) -> List[MoveJob]:
        """Each joint point -> FK -> a PTP target, streamed in order. All points are validated
        and previewed first (in the caller's thread; the bus keeps cycling); if any is bad,
        nothing is queued and DriverError names the point. The new path replaces every queued
        target of an earlier one; the target in flight completes and the new path runs from its
        end. An empty ``points`` stops the motion."""
        if not points:
            self.stop_motion("empty joint path: stop requested")
            return []
        if self.streaming:
            raise DriverError("protocol v2 runs a joint path with its timing: give each point a "
                              "time_from_start (see submit_trajectory); nothing was sent")
        order = self._joint_order(names)
        self._require_motion_possible()
        start = self._planning_start(SubmitMode.REPLACE)
        previews = []
        for index, point in enumerate(points):
            try:
                if len(point) != len(order):
                    raise DriverError("has %d positions for %d joint names" % (len(point), len(order)))
                q = [0.0] * 6
                for src, dst in enumerate(order):
                    q[dst] = float(point[src])
                q = self.kin.check_limits(self.kin.joint_vector(q))
                pose = self.kin.fk_pose(q)
                request = MoveRequest(MoveType.PTP, pose, label="joint path point %d" % index)
                preview = self.preview(request, start)
            except (VrDriverError, TypeError, ValueError) as exc:
                raise DriverError("joint path point %d: %s; nothing was sent" % (index, exc)) from None
            previews.append(preview)
            start = preview.joint_target
            time.sleep(0)   # hand the GIL over: the bus thread must not wait on a long validation
        jobs = [MoveJob(p, on_update) for p in previews]
        for job in jobs[1:]:
            job.group = jobs[0].group
        self._last_posted = jobs[-1]
        self.sequencer.add(jobs, SubmitMode.REPLACE)
        self.wake()
        log.info("joint path: %d PTP targets queued (jobs %d..%d)", len(jobs), jobs[0].id, jobs[-1].id)
        return jobs

    def submit_trajectory(self, traj: ValidTrajectory,
                          on_update: Optional[Callable[[MoveJob], None]] = None,
                          mode: SubmitMode = SubmitMode.REPLACE) -> "TrajectoryRun":
        """Run a validated planner trajectory.

        Protocol v2: one streamed job (:func:`streaming.stream_points`: thinned with its timing to
        ``stream_path_tolerance``, each segment's speed from its planned duration, blended through
        with ``stream_smooth``); every segment between the stream's points is checked against the
        joint limits and the workspace box before anything is queued. ``mode`` as :meth:`submit`
        (REPLACE, the default: the points the controller already took complete, then this one).

        Protocol v1: thinned to the fewest stop points
        that keep the path within its path tolerance (:func:`trajectories.thin`), each kept point
        a PTP target of a joint path (it replaces the queued targets of an earlier path). The v1
        program stops at every point and moves at its own speed: the result says how much slower
        than planned it ran. Raises DriverError (nothing queued) as :meth:`submit_joint_path`, and
        CollisionError when a sample or a chord between two collides."""
        try:
            self.check_collision_path(traj.positions, "trajectory", traj.times)
        except CollisionError as exc:
            raise CollisionError("%s; nothing was sent" % exc, exc.contacts, exc.sample, exc.time) from None
        if self.streaming:
            return self._submit_stream(traj, on_update, mode)
        kept = thin(traj)
        points = [traj.positions[k] for k in kept[1:]]
        if not points:                      # only the start, where the arm is: nothing to move
            return TrajectoryRun(traj, kept, [], self.clock())
        jobs = self.submit_joint_path(self.joint_names, points, on_update)
        log.info("trajectory: %d points planned over %.2f s, %d stop points after thinning",
                 len(traj.positions) - 1, traj.duration, len(points))
        return TrajectoryRun(traj, kept, jobs, self.clock())

    # ------------------------------------------------------------------------ protocol v2
    def _set_controller_outputs(self, value: int) -> None:
        self.sequencer.outputs = value      # type: ignore[attr-defined]  (StreamSequencer)
        self.wake()

    def _min_segment(self) -> float:
        """The shortest segment the bus feeds without a gap: MIN_SEGMENT_CYCLES of the configured
        cycle, or of the measured one when the wire is slower (a 72-byte record at 19.2 kbit/s)."""
        rate = self.bus.cycle_rate_hz
        measured = self.link.cycle_rate
        if measured > 0.0:
            rate = min(rate, measured)
        return MIN_SEGMENT_CYCLES / rate

    def _stream(self, times: Sequence[float], positions: Sequence[Sequence[float]], tolerance: float,
                max_tolerance: float) -> Tuple[StreamPoint, ...]:
        points = stream_points(times, positions, self.kin.limits.velocity, self.params.stream_smooth,
                               tolerance, self._min_segment(), max_tolerance,
                               corner_tolerance=math.radians(self.params.stream_path_tolerance),
                               max_step=None if self.protocol.joint_targets else CARTESIAN_MAX_STEP)
        if self.protocol.joint_targets or not points:
            return points
        return self.cartesian_points(positions[0], points)

    def cartesian_points(self, start: Sequence[float], points: Sequence[StreamPoint],
                         first: int = 0) -> Tuple[StreamPoint, ...]:
        """A stream for a Cartesian protocol: each point gets its pose (FK of the planned joints, as
        the wire carries it) and is solved as the controller will solve it -- the IK solution
        nearest the previous target's joints (the arm's, ``start``, for the first): it must be the
        planned point within CONFIGURATION_TOLERANCE, or the controller would run another
        configuration than the one planned and checked (doc/controller_program.md section 7).
        Raises DriverError naming the point (nothing is sent)."""
        out = []
        prev = tuple(start)
        for i, point in enumerate(points):
            pose = self.protocol.wire_pose(self.kin.fk_pose(point.joints))
            try:
                with self._planning_gate:
                    solved = self.kin.ik_pose(pose, seed=prev)
            except VrDriverError as exc:
                raise DriverError("point %d of %d (planned point %d): the controller cannot solve its "
                                  "pose %s: %s; nothing was sent" % (first + i + 1, first + len(points),
                                                                    point.index, _fmt_pose(pose), exc)) from None
            off = [abs(a - b) for a, b in zip(solved, point.joints)]
            worst = max(range(len(off)), key=off.__getitem__)
            if off[worst] > CONFIGURATION_TOLERANCE:
                raise DriverError(
                    "point %d of %d (planned point %d): the controller would reach its pose %s in "
                    "another configuration than planned (joint_%d %.1f deg instead of %.1f deg: the "
                    "solution nearest the previous target's joints); plan a path that stays in one "
                    "configuration, or use a protocol with joint targets; nothing was sent"
                    % (first + i + 1, first + len(points), point.index, _fmt_pose(pose), worst + 1,
                       math.degrees(solved[worst]), math.degrees(point.joints[worst])))
            out.append(replace(point, pose=pose))
            prev = point.joints
            time.sleep(0)   # hand the GIL over: the bus thread must not wait on a long validation
        return tuple(out)

    def _preview_stream(self, preview: Preview) -> Tuple[StreamPoint, ...]:
        """A validated move as a stream: its planned samples (a PTP's joint line with its speed
        ramps, a LIN / CIRC's Cartesian path) thinned to 0.01 deg at their planned times; the last
        point is exactly the previewed target."""
        traj = preview.trajectory
        positions = [tuple(float(v) for v in q) for q in traj.positions]
        positions[-1] = tuple(preview.joint_target)
        points = self._stream([float(t) for t in traj.times], positions, math.radians(0.01),
                              MAX_CARTESIAN_TOLERANCE)
        if not points:      # already there: one target at the goal
            points = (StreamPoint(tuple(preview.joint_target), 1000, 0, 0.0, len(positions) - 1),)
            if not self.protocol.joint_targets:
                points = self.cartesian_points(positions[0], points)
        return points

    def check_segments(self, start: Sequence[float], points: Sequence[StreamPoint]) -> None:
        """Every straight joint move of the stream (from ``start``) inside the joint limits and the
        workspace box, sampled as a PTP preview; raises (EnvelopeError, KinematicsError...) naming
        the segment; CollisionError naming the point where a chord collides."""
        self.check_collision_path([tuple(start)] + [p.joints for p in points],
                                  "the stream's straight joint moves", [0.0] + [p.time for p in points])
        prev = tuple(start)
        for i, point in enumerate(points):
            try:
                with self._planning_gate:
                    check_envelope(self.planner.ptp_joints(prev, point.joints), self.params.workspace)
            except VrDriverError as exc:
                raise type(exc)("segment %d of %d (to planned point %d): %s"
                                % (i + 1, len(points), point.index, exc)) from None
            prev = point.joints
            time.sleep(0)   # hand the GIL over: the bus thread must not wait on a long validation

    def _submit_stream(self, traj: ValidTrajectory, on_update: Optional[Callable[[MoveJob], None]],
                       mode: SubmitMode) -> "TrajectoryRun":
        self._require_motion_possible()
        tol = math.radians(self.params.stream_path_tolerance)
        points = self._stream(traj.times, traj.positions, tol, max(tol, MAX_STREAM_TOLERANCE))
        if not points:
            return TrajectoryRun(traj, [0], [], self.clock())
        try:
            self.check_segments(traj.positions[0], points)
        except VrDriverError as exc:
            raise DriverError("%s; nothing was sent" % exc) from None
        job = MoveJob(None, on_update, points=points, start=tuple(traj.positions[0]))
        self._last_posted = job
        self.sequencer.add([job], mode)
        self.wake()
        log.info("trajectory: %d points planned over %.2f s streamed as %d targets (job %d)",
                 len(traj.positions) - 1, traj.duration, len(points), job.id)
        return TrajectoryRun(traj, [0] + [p.index for p in points], [job], self.clock())

    def _restream(self, job: MoveJob, joints: Tuple[float, ...]) -> Tuple[Tuple[StreamPoint, ...], Tuple[float, ...]]:
        """A stream job's points from ``joints`` (the arm is not where the stream was planned to
        start): the first segment is checked again and its speed set for its planned arrival (no
        faster than the limits)."""
        points = job.points
        self.check_segments(joints, points[:1])
        if not self.protocol.joint_targets:
            self.cartesian_points(joints, points[:1])
        first = points[0]
        # (a pause at the start, first.release > 0: the move begins when it ends)
        speed = stream_speeds(joints, [tuple(joints), first.joints], [first.release, first.time],
                              self.kin.limits.velocity)[1]
        return (replace(first, speed=speed),) + tuple(points[1:]), tuple(joints)

    def joint_command(self, names: Sequence[str], positions: Sequence[float],
                      time_from_start: float = 0.0) -> MoveJob:
        """One streamed joint target (the ``joint_command`` topic; :mod:`.joint_command` has the
        rules): validated here, in the caller's thread, then a point of the live stream job it
        returns. Raises JointCommandRefused (nothing sent) with the rule and the reason."""
        return self.joint_commander.command(names, positions, time_from_start)

    def cancel(self, job: MoveJob, reason: str = "cancelled") -> None:
        """Cancel one job: a queued one is dropped; the one in flight is stopped and ends when
        the arm is at rest."""
        self.sequencer.cancel(job, reason)
        self.wake()

    def stop_motion(self, reason: str = "stop requested") -> int:
        """Drop the queue and stop the target in flight; returns the number of jobs it ends."""
        view = self.sequencer.view
        n = view.queue_length + (1 if view.job is not None and not view.settling else 0)
        self.sequencer.stop_all(reason)
        self.wake()
        log.info("stop motion: %s (%d job(s) to end)", reason, n)
        return n

    # ------------------------------------------------------------------------ collision checking
    @property
    def collision(self):
        """The CollisionChecker of the current scene (kinematics.collision), or None when nothing is
        checked (collision_check false, or pinocchio / coal missing with no scene). Replaced as a
        whole on every scene change; not thread-safe: use it under :attr:`planning_gate`, or
        ``copy()`` it (a planner of its own)."""
        return self.scene_guard.checker

    def scene(self):
        """A copy of the scene (kinematics.scene.Scene)."""
        return self.scene_guard.scene()

    def add_scene_object(self, obj, replace: bool = False) -> str:
        """Add ``obj`` (a SceneObject in base_link); ``replace``: in place of the object of its name
        (added when there is none). SceneError (nothing changes) for a taken name without
        ``replace``; an object the arm stands in now is added with a warning (scene_guard), which
        is returned ("" when none)."""
        return self.scene_guard.add(obj, replace, self._joints_now())

    def remove_scene_object(self, name: str):
        """Remove the object ``name`` and return it; SceneError naming the objects when absent."""
        return self.scene_guard.remove(name)

    def clear_scene(self) -> None:
        self.scene_guard.clear()

    def load_scene(self, path: str):
        """Replace the scene by the cell file ``path``; SceneError (nothing changes) when it is bad."""
        return self.scene_guard.load(path, self._joints_now())

    def check_collision_path(self, samples: Sequence[Sequence[float]], what: str,
                             times: Optional[Sequence[float]] = None) -> None:
        """Raise CollisionError when ``samples`` (joint vectors, controller order) or a straight
        chord between two of them would collide (scene_guard: the chords checked at most the
        planner's max_sweep of arm motion apart); ``what`` names the path in the message."""
        self.scene_guard.check_path(samples, what, times)

    def _joints_now(self) -> Optional[Tuple[float, ...]]:
        status = self.status()
        return status.joints if status.joints is not None and status.joints_valid else None

    # ------------------------------------------------------------------------ request helpers
    @property
    def planning_gate(self) -> threading.Lock:
        """Held while planning or checking a path (one at a time, off the bus thread)."""
        return self._planning_gate

    @property
    def last_posted(self) -> Optional[MoveJob]:
        """The job posted last (a move, a trajectory, a joint_command stream), or None."""
        return self._last_posted

    def post_job(self, job: MoveJob) -> None:
        """Queue ``job`` (validated already) behind the others and run a bus cycle now."""
        self._last_posted = job
        self.sequencer.add([job], SubmitMode.APPEND)
        self.wake()

    def wake(self) -> None:
        """Run a bus cycle now (a request was posted), not at the next tick."""
        self._wake.set()
        self.link.poke()

    def configuration_error(self, prev: Sequence[float], joints: Sequence[float]) -> str:
        """A Cartesian protocol: why the controller would not reach ``joints`` when sent their pose
        (FK, rounded as the wire carries it) after a target at ``prev`` -- it solves the pose as the
        IK solution nearest the previous target's joints -- or "" when it reaches them within
        CONFIGURATION_TOLERANCE."""
        pose = self.protocol.wire_pose(self.kin.fk_pose(joints))
        try:
            with self._planning_gate:
                solved = self.kin.ik_pose(pose, seed=tuple(prev))
        except VrDriverError as exc:
            return "the controller cannot solve its pose %s: %s" % (_fmt_pose(pose), exc)
        off = [abs(a - b) for a, b in zip(solved, joints)]
        worst = max(range(len(off)), key=off.__getitem__)
        if off[worst] <= CONFIGURATION_TOLERANCE:
            return ""
        return ("the controller would reach its pose %s in another configuration (joint_%d %.1f deg "
                "instead of %.1f deg: the solution nearest the previous target's joints); use a "
                "protocol with joint targets" % (_fmt_pose(pose), worst + 1, math.degrees(solved[worst]),
                                                 math.degrees(joints[worst])))

    def _require_motion_possible(self) -> None:
        status = self.status()
        if not status.motion_possible:
            raise DriverError("motion is not possible: %s" % status.why_no_motion())

    def _current_joints(self) -> Tuple[float, ...]:
        status = self.status()
        if status.joints is None or not status.joints_valid:
            raise DriverError("no valid current joint state to plan from (%s)"
                              % (status.link_reason or status.link.value))
        return status.joints

    def _planning_start(self, mode: SubmitMode) -> Tuple[float, ...]:
        """Where a new job will start: for APPEND the last queued job's target, for REPLACE the
        target in flight, else (and for PREEMPT) the arm's joints now. A guess when the arm moves
        meanwhile: the sequencer plans the job again if the arm is elsewhere when it is sent."""
        if mode is SubmitMode.APPEND:
            last = self._last_posted
            if last is not None and not last.done:
                return last.joint_target
            tail = self.sequencer.view.tail_joints
            if tail is not None:
                return tail
        elif mode is SubmitMode.REPLACE:
            inflight = self.sequencer.view.inflight_joints
            if inflight is not None:
                return inflight
        return self._current_joints()

    def _joint_order(self, names: Sequence[str]) -> List[int]:
        expected = list(self.params.controller_joint_names)
        names = list(names)
        if sorted(names) != sorted(expected) or len(names) != len(set(names)):
            raise DriverError("joint names %s do not match the controller's joints %s"
                              % (names, expected))
        return [expected.index(n) for n in names]

    # ------------------------------------------------------------------------ planning thread
    def _schedule_replan(self, job: MoveJob, joints: Tuple[float, ...]) -> None:
        """Called by the sequencer (bus thread): plan ``job`` again from ``joints``, off the bus."""
        def task() -> None:
            try:
                if job.points:
                    preview = self._restream(job, joints)
                else:
                    preview = self.preview(job.preview.request, joints)
            except VrDriverError as exc:
                self.sequencer.replanned(job, None, str(exc))
            else:
                self.sequencer.replanned(job, preview)
            self.wake()
        with self._planning_cond:
            self._planning.append(task)
            self._planning_cond.notify_all()

    def run_planning(self) -> int:
        """Run the planning tasks waiting now, in the caller's thread (stepped tests); returns
        how many ran."""
        n = 0
        while True:
            with self._planning_cond:
                if not self._planning:
                    return n
                task = self._planning.popleft()
            task()
            n += 1

    def _plan_loop(self) -> None:
        while not self._stop.is_set():
            with self._planning_cond:
                self._planning_cond.wait_for(lambda: self._planning or self._stop.is_set())
                if self._stop.is_set():
                    return
                task = self._planning.popleft()
            try:
                task()
            except Exception:  # the planning thread must survive a planner bug
                log.exception("planning thread: unexpected error")

    # ------------------------------------------------------------------------ bus loop
    def _run(self) -> None:
        period = 1.0 / self.bus.cycle_rate_hz
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
                # never a period here; an early cycle (v2's changed record, a stream's end due) is
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

    def next_cycle(self, now: float, scheduled: float) -> float:
        """When the bus cycle after the one that just ran starts (``scheduled``: at the cycle rate).
        v2: a changed record (a new target, STOP) goes out at once, not a period later -- the
        controller acts on it at the first telegram that brings it (its CRC-16); and while a
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
        joints = self._update_joints(sample)
        self._check_model(sample, joints)
        command = self.sequencer.step(now, sample, joints)
        record = self.protocol.encode(command, self.params.byte_order)
        if self.protocol.send_changes_at_once and record != self._last_record and sample.connected \
                and not self._repeated:
            self._repeat_now = True
        self._repeated = False
        self._last_record = record
        # the snapshot before the outputs go out (to a bus process: a socket write, which lets
        # other threads run): a job that ended in this step is never seen beside an older status
        status = self._status = self._snapshot(now, sample)
        self.link.set_outputs(record)
        self._notify(status)
        return status

    def _update_joints(self, sample: LinkSample) -> Optional[Tuple[float, ...]]:
        """The joints of the controller's latest record; None while the link is down. v2 reports
        them; v1 and v3 report only a pose, which :class:`~vr_driver.driver.tracking.JointTracker`
        reads against what was sent (the branch the controller is on, the commanded configuration
        where the pose leaves it open, no step the arm cannot make). A few milliseconds at most
        (the solver's time budget)."""
        fb = sample.feedback
        if fb is None:
            self._joints_valid = False       # (the tracker keeps the last joints as its reference)
            return None
        reported = self.protocol.feedback_joints(fb)
        if reported is not None:            # v2 reports the joints themselves (0.001 deg)
            self._joints, self._joints_valid = reported, True
            return self._joints
        self.tracker.follow(self.sequencer.view.job)
        joints = self.tracker.update(fb.pose, sample.record_time if sample.record_time is not None
                                     else sample.time)
        self._joints, self._joints_valid = self.tracker.joints, joints is not None
        return joints

    def _check_model(self, sample: LinkSample, joints: Optional[Tuple[float, ...]]) -> None:
        """Once per connection (the first record of a link session) where the protocol reports the
        joints and the pose: the reported pose against our FK of the reported joints. One FK on the
        bus thread per connection. A mismatch is a warning in the log (and /diagnostics)."""
        fb = sample.fresh
        if fb is None or joints is None or not self.protocol.reports_joints:
            return
        if self._model_check is not None and self._model_check.session == sample.session:
            return
        ours = self.kin.fk_pose(joints).as_tuple()
        theirs = fb.pose.as_tuple()
        d_pos = max(abs(a - b) for a, b in zip(ours[:3], theirs[:3]))
        d_ang = max(abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(ours[3:], theirs[3:]))
        check = ModelCheck(sample.session, d_pos, d_ang, d_pos <= self.params.model_check_position
                           and d_ang <= self.params.model_check_angle, tuple(joints))
        self._model_check = check
        if check.ok:
            log.info("model check: %s", check.describe())
        else:
            log.warning("model check: %s", check.describe())

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
            joints=self._joints, joints_valid=self._joints_valid and fb is not None,
            job=view.job, queue_length=view.queue_length, cycle_rate=self.link.cycle_rate,
            counters=counters, master_counters=self.link.master_counters(),
            slave_state=self.link.slave_state, last_diag=self.link.last_diag,
            error_code=error_code, error_reason=error_reason,
            model_check=self._model_check,
            feedback_time=sample.feedback_time if sample is not None and fb is not None else None,
            record_time=sample.record_time if sample is not None and fb is not None else None,
            settling=view.settling, bus_health=self.link.health_summary(now))

    def _publish(self, now: float, sample: Optional[LinkSample]) -> DriverStatus:
        status = self._status = self._snapshot(now, sample)
        self._notify(status)
        return status

    def _notify(self, status: DriverStatus) -> None:
        for callback in self._listeners:
            try:
                callback(status)
            except Exception:
                log.exception("status listener failed")
