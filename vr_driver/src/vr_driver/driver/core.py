"""The driver core behind the ROS node `interface` (ROS-free, testable with plain pytest).

:class:`DriverCore` owns and wires the parts, each with one job, and is the one object the node
and the tests talk to:

- :class:`~vr_driver.driver.link.link.LinkSupervisor` (port, DP master, session, freshness, counters),
- the sequencer (:class:`~vr_driver.driver.motion.handshake.HandshakeSequencer`, v1's handshake, or
  :class:`~vr_driver.driver.motion.streaming.StreamSequencer`: queue, stops, outcomes),
- :class:`~vr_driver.driver.bus_loop.BusLoop` (the bus thread: one iteration steps the link, the
  joints and the sequencer and publishes a :class:`~vr_driver.driver.motion.status.DriverStatus`),
- :class:`~vr_driver.driver.joints.arm_joints.ArmJoints` (the joints of each record, the model check),
- :class:`~vr_driver.driver.checks.job_control.JobControl` (submit, cancel, stop; the planning thread),
- :class:`~vr_driver.driver.checks.path_checks.PathChecks` (previews, the workspace box, the cell) and,
  for a streaming protocol, the stream preparation of its family
  (:mod:`vr_driver.driver.checks.stream_prep`),
- :class:`~vr_driver.driver.checks.joint_command.JointCommander` (the ``joint_command`` topic).

:meth:`DriverCore.start` runs the bus thread and the planning thread; tests call
:meth:`spin_once`, :meth:`next_cycle` and :meth:`run_planning` themselves with a fake clock, in
one thread. Requests from other threads validate and plan in the caller's thread -- never on the
bus thread, and under no lock the bus needs -- and then post the job to the sequencer.

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

import logging
import math
import threading
import time
from typing import Callable, Generic, List, Optional, Sequence, Tuple, TypeVar

from pyprofibus_vendor.phy import Link

from ..kinematics.preview import MovePreviewer
from ..kinematics.solver import Kinematics
from ..errors import VrDriverError
from ..params import DriverParams
from .motion.announced import Announced, announce_moves, announce_plan
from .joints.arm_joints import ArmJoints
from .bus_loop import BusLoop
from .checks.job_control import JobControl, PlanningThread, TrajectoryRun
from .motion.jobs import MoveJob, MoveRequest, Preview, StreamPoint, SubmitMode
from .checks.joint_command import JointCommander
from .checks.commissioned import controller_notes
from .link.link import LinkState, LinkSupervisor, open_serial_link
from .checks.path_checks import PathChecks, load_cell
from .checks.scene_guard import SceneGuard
from .link.stations import ControllerIo, IoLine
from .motion.inbox import MotionSnapshot
from .motion.status import DriverError, DriverStatus
from .checks.stream_prep import stream_preparation
from .motion.stream_points import MAX_STREAM_TOLERANCE
from .motion.trajectories import ValidTrajectory

Clock = Callable[[], float]
log = logging.getLogger("vr_driver.driver")

__all__ = ["DriverCore", "DriverError", "DriverStatus", "TrajectoryRun", "driver_kinematics"]


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


_Part = TypeVar("_Part")


class _OfChecks(Generic[_Part]):
    """A part of the core's path checks (:class:`PathChecks`) that the core names too: read there
    and replaced there as a whole, so the checks always use the current one."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, core: Optional["DriverCore"], owner: Optional[type] = None) -> _Part:
        if core is None:
            return self     # type: ignore[return-value]  (the class's attribute: the descriptor)
        return getattr(core.checks, self.name)

    def __set__(self, core: "DriverCore", value: _Part) -> None:
        setattr(core.checks, self.name, value)


class DriverCore:
    """See the module docstring. ``open_link(device, baud)`` makes the link (tests may pass a
    factory for an in-memory or fault-injecting link)."""

    def __init__(self, params: DriverParams, kinematics: Optional[Kinematics] = None,
                 previewer: Optional[MovePreviewer] = None, clock: Clock = time.monotonic,
                 open_link: Callable[[str, int], Link] = open_serial_link) -> None:
        self.params = params
        self.bus = params.bus()
        self.slave_config = self.bus.slaves[0]
        if kinematics is None:
            kinematics = driver_kinematics(params)     # the package's model or ``model``'s
        self.kin = kinematics
        self.clock = clock
        # the I/O stations beside the controller (io_signals), cycled by the link's master
        signals = params.signal_map(self.bus)
        self.io: Optional[IoLine] = IoLine(signals, params.link_timeout) if signals is not None else None
        self.wire = params.wire
        self.streaming = self.wire.streams
        # the protocol object names its sequencer (driver/sequencers.py registers v1 / v2 / v3's);
        # its inbox is all that requests touch of the bus side (posts, the wake-up, MotionSnapshot)
        self.sequencer = self.wire.sequencer()(params, clock, self._schedule_replan)
        self.inbox = self.sequencer.inbox
        self.link = LinkSupervisor(params, self.bus, clock, open_link, stations=self.io, wake=self.inbox.wake)
        # the controller's own I/O (v2) as a station of the signal map at the controller's address
        self.controller_io: Optional[ControllerIo] = None
        if self.io is not None and self.wire.controller_io and \
                any(st.address == self.slave_config.address for st in self.io.map.stations):
            self.controller_io = ControllerIo(self.slave_config.address, self._set_controller_outputs)
            self.io.add_local(self.controller_io)
        self._stop = threading.Event()      # ends the bus thread and the planning thread
        self.arm = ArmJoints(params, self.kin, self.wire)
        self.bus_loop = BusLoop(params, clock, self.bus.cycle_rate_hz, self.link, self.sequencer, self.wire,
                                self.arm, self.io, self.controller_io, self._stop)
        self.planning_thread = PlanningThread(self._stop)
        # one planner at a time: requests plan in their callers' threads (an action server runs one
        # per goal); twenty goals planning at once starved the bus thread of the interpreter lock
        # for over 0.3 s (every blocking call of a DP cycle waits its turn behind each of them) and
        # the card's watchdog expired. Waiting here costs no CPU and no interpreter lock.
        self._planning_gate = threading.Lock()
        # the cell and the collision checks (scene_guard; MissingDependency: a scene but no libraries)
        self.checks = PathChecks(self.kin, previewer or MovePreviewer(self.kin), params.workspace, self._planning_gate,
                                 SceneGuard(self.kin, self._planning_gate, load_cell(params.scene),
                                            params.collision_padding, params.collision_check, params.prefix,
                                            model=params.model), self.wire)
        self.streams = stream_preparation(params, self.kin, self.wire, self.checks, self.stream_cycle_rate)
        self.jobs = JobControl(params, self.kin, clock, self.sequencer, self.checks, self.streams,
                               self.motion_snapshot)
        self.joint_commander = JointCommander(params, self.kin, self.wire, clock, self.status, self.jobs,
                                              self.checks, self.streams)
        #: what the commissioned G2 changes, in words (logged at every connect; the node's diagnostics)
        self.controller_notes = controller_notes(params, self.kin)
        self._notes_said = False
        self.add_listener(self._say_controller_notes)

    # ------------------------------------------------------------------------ the parts' state
    @property
    def handshake(self):
        """The master side of the target handshake (read-only use: ``handshake.ready``)."""
        return self.sequencer.handshake

    @property
    def tracker(self):
        """The joints of the reported pose (v1, v3): :class:`~vr_driver.driver.joints.tracking.JointTracker`."""
        return self.arm.tracker

    #: the previews of moves (replaceable as a whole, e.g. by a test's recording previewer)
    previewer = _OfChecks[MovePreviewer]()
    #: the cell and its collision checks
    scene_guard = _OfChecks[SceneGuard]()

    @property
    def planning_gate(self) -> threading.Lock:
        """Held while planning or checking a path (one at a time, off the bus thread)."""
        return self._planning_gate

    @property
    def last_posted(self) -> Optional[MoveJob]:
        """The job posted last (a move, a trajectory, a joint_command stream), or None."""
        return self.jobs.last_posted

    @property
    def joint_names(self) -> Tuple[str, ...]:
        return self.params.controller_joint_names

    def stream_cycle_rate(self) -> float:
        """[Hz] the bus cycles per second a stream is fed at: the configured rate, or the measured
        one when the wire is slower (a 72-byte record at 19.2 kbit/s). The stream preparation takes
        its shortest segment and a target's feed as cycles of it (``streams.min_segment()``,
        ``streams.feed_period()``), the planning process the same rate with every plan."""
        rate = self.bus.cycle_rate_hz
        measured = self.motion_snapshot().cycle_rate     # (the link's, as of the last bus iteration)
        if measured > 0.0:
            rate = min(rate, measured)
        return rate

    def _say_controller_notes(self, status: DriverStatus) -> None:
        """At every connect (bus thread): what the commissioned G2 changes, in words
        (:attr:`controller_notes`), one warning each."""
        up = status.link is LinkState.CONNECTED
        if up and not self._notes_said:
            for note in self.controller_notes:
                log.warning("controller: %s", note)
        self._notes_said = up

    # ------------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        if self.bus_loop.thread is not None:
            return
        self._stop.clear()
        self.planning_thread.start()
        self.bus_loop.start()

    def request_stop(self) -> None:
        """Ask the bus thread to end, without waiting (safe from a signal handler or a ROS shutdown
        hook, which may interrupt a thread that holds a lock :meth:`stop` needs)."""
        self.bus_loop.request_stop()

    def stop(self, timeout: float = 3.0) -> None:
        self.bus_loop.request_stop()
        self.planning_thread.wake_to_stop()
        self.bus_loop.join(timeout)
        self.planning_thread.join(timeout)
        self.sequencer.shutdown("driver shut down")
        self.link.close()

    def add_listener(self, callback: Callable[[DriverStatus], None]) -> None:
        """``callback(status)`` after every bus iteration (bus thread)."""
        self.bus_loop.add_listener(callback)

    def status(self, now: Optional[float] = None) -> DriverStatus:
        """The latest snapshot, read at ``now`` (default: the clock): one older than
        ``link_timeout``, or with feedback older than that, reads as a lost link."""
        return self.bus_loop.status(self.clock() if now is None else now)

    def motion_snapshot(self, now: Optional[float] = None) -> MotionSnapshot:
        """What a request reads before it posts -- motion possible or why not, the arm's joints, the
        measured bus cycle rate -- as of the latest bus iteration, read at ``now`` (default: the
        clock) as :meth:`status` is; from the inbox, without touching the bus side."""
        return self.inbox.snapshot(self.clock() if now is None else now)

    def status_after(self, t: float, timeout: Optional[float] = None) -> DriverStatus:
        """The snapshot of a bus iteration that began at ``t`` (the clock) or later -- e.g. the status
        beside a job that ended -- waiting for it at most ``timeout`` (default ``link_timeout``),
        then :meth:`status` (after a timeout: what it is then, a lost link when it is old)."""
        self.bus_loop.status_after(t, self.params.link_timeout if timeout is None else timeout)
        return self.status()

    # ------------------------------------------------------------------------ stepping (tests)
    def spin_once(self) -> DriverStatus:
        """One bus iteration (:meth:`BusLoop.spin_once`)."""
        return self.bus_loop.spin_once()

    def next_cycle(self, now: float, scheduled: float) -> float:
        """When the next bus cycle starts (:meth:`BusLoop.next_cycle`)."""
        return self.bus_loop.next_cycle(now, scheduled)

    def run_planning(self) -> int:
        """Run the planning tasks waiting now, in the caller's thread (stepped tests); returns
        how many ran."""
        return self.planning_thread.run_pending()

    def wake(self) -> None:
        """Run a bus cycle now (a request was posted), not at the next tick (the inbox's wake)."""
        self.inbox.wake.set()

    def _schedule_replan(self, job: MoveJob, joints: Tuple[float, ...]) -> None:
        """Called by the sequencer (bus thread): plan ``job`` again from ``joints``, off the bus."""
        self.planning_thread.post(lambda: self.jobs.replan(job, joints))

    def _set_controller_outputs(self, value: int) -> None:
        self.sequencer.outputs = value      # type: ignore[attr-defined]  (StreamSequencer)
        self.wake()

    # ------------------------------------------------------------------------ requests
    # (JobControl has their rules; each validates and plans in the caller's thread, then queues)
    def preview(self, request: MoveRequest, start_joints: Optional[Sequence[float]] = None) -> Preview:
        return self.jobs.preview(request, start_joints)

    def claim_ticket(self) -> int:
        return self.jobs.claim_ticket()

    def submit(self, request: MoveRequest, on_update: Optional[Callable[[MoveJob], None]] = None,
               mode: SubmitMode = SubmitMode.APPEND, ticket: Optional[int] = None) -> MoveJob:
        return self.jobs.submit(request, on_update, mode, ticket)

    def submit_joint_path(self, names: Sequence[str], points: Sequence[Sequence[float]],
                          on_update: Optional[Callable[[MoveJob], None]] = None) -> List[MoveJob]:
        return self.jobs.submit_joint_path(names, points, on_update)

    def submit_trajectory(self, traj: ValidTrajectory, on_update: Optional[Callable[[MoveJob], None]] = None,
                          mode: SubmitMode = SubmitMode.REPLACE, started: Optional[float] = None) -> TrajectoryRun:
        return self.jobs.submit_trajectory(traj, on_update, mode, started)

    def prepare_trajectory(self, traj: ValidTrajectory, start: Sequence[float]):
        return self.jobs.prepare_trajectory(traj, start)

    # ------------------------------------------------------------------------ said before a move
    def bus_cycle(self) -> float:
        """[s] the bus cycle: measured, else the configured rate's."""
        rate = self.motion_snapshot().cycle_rate
        return 1.0 / rate if rate and rate > 0.0 else 1.0 / self.bus.cycle_rate_hz

    def announce(self, times: Sequence[float], positions: Sequence[Sequence[float]],
                 previews: Optional[Sequence[Preview]] = None,
                 stream: Optional[Sequence[StreamPoint]] = None) -> Announced:
        """The time and the TCP's top speed this protocol delivers for the planned path ``times`` /
        ``positions`` (from ``positions[0]``; :func:`.announced.announce_plan`): v1 its PTP moves
        between the plan's stop points (``previews``, made here when not given) at the program's
        speed; a streaming protocol its ``stream`` as fed (made here when not given: the stream the
        trajectory action would send, without its segment checks). Raises as
        :meth:`prepare_trajectory` when v1 would refuse the path."""
        if stream is None and self.wire.streams and self.streams is not None and len(times) > 1:
            tol = math.radians(self.params.stream_path_tolerance)
            try:
                stream = self.streams.points(times, positions, tol, max(tol, MAX_STREAM_TOLERANCE))
            except VrDriverError:
                stream = ()        # (refused: the plan's own time is said; the run's check says why)
        if previews is None and not self.wire.streams and len(times) > 1:
            from .joints.resolution import WireResolution
            from .motion.trajectories import TrajectoryGoal, validate
            lim = self.kin.limits
            names = tuple(self.joint_names)
            traj = validate(TrajectoryGoal(names, tuple(tuple(q) for q in positions[1:]), tuple(times[1:])), names,
                            tuple(positions[0]), lim.lower, lim.upper, 0.0,
                            default_path_tolerance=self.wire.default_path_tolerance,
                            default_goal_tolerance=self.wire.default_goal_tolerance,
                            resolution=WireResolution.of(self.kin, self.wire))
            previews = self.prepare_trajectory(traj, traj.positions[0])[2]
        return announce_plan(self.kin, self.wire, times, positions, previews or (), self.params, self.bus_cycle(),
                             stream or ())

    def announce_run(self, run: TrajectoryRun) -> Announced:
        """:meth:`announce` of a trajectory queued (v1: its jobs' previews; a stream: its job's points)."""
        previews = [job.preview for job in run.jobs if job.preview is not None]
        stream = run.jobs[0].points if self.wire.streams and len(run.jobs) == 1 else None
        return self.announce(run.traj.times, run.traj.positions, previews, stream)

    def announce_move(self, preview: Preview) -> Announced:
        """The time and the TCP's top speed of one previewed move on this protocol: v1 at the program's
        speed, a streaming protocol its previewed timing."""
        if self.wire.streams:
            traj = preview.trajectory
            return announce_plan(self.kin, self.wire, [float(t) for t in traj.times],
                                 [tuple(float(v) for v in q) for q in traj.positions], cycle_time=self.bus_cycle())
        return announce_moves(self.wire, [preview], self.params, self.bus_cycle())

    def post_job(self, job: MoveJob) -> None:
        self.jobs.post_job(job)

    def cancel(self, job: MoveJob, reason: str = "cancelled") -> None:
        self.jobs.cancel(job, reason)

    def stop_motion(self, reason: str = "stop requested") -> int:
        return self.jobs.stop_motion(reason)

    def joint_command(self, names: Sequence[str], positions: Sequence[float],
                      time_from_start: float = 0.0) -> MoveJob:
        """One streamed joint target (the ``joint_command`` topic; :mod:`.joint_command` has the
        rules): validated here, in the caller's thread, then a point of the live stream job it
        returns. Raises JointCommandRefused (nothing sent) with the rule and the reason."""
        return self.joint_commander.command(names, positions, time_from_start)

    # ------------------------------------------------------------------------ streams (stream_prep)
    def cartesian_points(self, start: Sequence[float], points: Sequence[StreamPoint],
                         first: int = 0) -> Tuple[StreamPoint, ...]:
        """A Cartesian protocol's stream points with their poses, checked as the controller will
        solve them (:meth:`CartesianStreams.with_poses`)."""
        return self._streams().with_poses(start, points, first)

    def check_segments(self, start: Sequence[float], points: Sequence[StreamPoint]) -> None:
        """Every straight joint move of a stream checked (:meth:`JointStreams.check_segments`)."""
        self._streams().check_segments(start, points)

    def _streams(self):
        if self.streams is None:
            raise DriverError("protocol %s does not stream" % self.wire.name)
        return self.streams

    # ------------------------------------------------------------------------ the cell (scene_guard)
    @property
    def collision(self):
        """The CollisionChecker of the current scene (kinematics.collision), or None when nothing is
        checked (collision_check false, or pinocchio / coal missing with no scene). Replaced as a
        whole on every scene change; not thread-safe: use it under :attr:`planning_gate`, or
        ``copy()`` it (a planner of its own)."""
        return self.checks.collision

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
        """CollisionError when ``samples`` or a chord between two collides (:class:`PathChecks`)."""
        self.checks.check_collision_path(samples, what, times)

    def _joints_now(self) -> Optional[Tuple[float, ...]]:
        status = self.status()
        return status.joints if status.joints is not None and status.joints_valid else None
