"""The driver core behind the ROS node `interface` (ROS-free, testable with plain pytest).

One bus thread owns the serial link, the DP master and the target handshake. Every cycle it sends
the handshake's outputs, reads the controller's feedback, advances the handshake and the current
move job, and publishes an immutable :class:`DriverStatus` snapshot. Other threads (ROS callbacks,
tests) only call the thread-safe methods: :meth:`DriverCore.preview`, :meth:`DriverCore.submit`,
:meth:`DriverCore.submit_joint_path`, :meth:`DriverCore.stop_motion` and :meth:`DriverCore.status`.

Safety rules enforced here:
- nothing reaches the bus that was not validated first: finite values, the workspace box (on the
  rounded values that are sent), int16, reachability and joint limits along the whole previewed
  path, and a controller that says motion is possible;
- each target is requested exactly once (protocol.MasterHandshake); a job whose link is lost, that
  times out or is cancelled is ended with its reason and never re-sent;
- while the link is down the status keeps being produced (link state, reason), position feedback
  is withheld, and the port is reopened every ``reconnect_period``.
"""
from __future__ import annotations

import collections
import enum
import errno
import itertools
import logging
import re
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence, Tuple

from pyprofibus_vendor.dp import DiagStatus1
from pyprofibus_vendor.dp_master import BusTiming, DpMaster, MasterSlaveState, SlaveSpec
from pyprofibus_vendor.errors import ProfibusError
from pyprofibus_vendor.phy import Link

from .errors import HandshakeError, ProtocolError, VrDriverError
from .kinematics import Kinematics
from .motion import MotionPlanner, MoveType, Trajectory
from .params import DriverParams
from .poses import ControllerPose
from .protocol import (Aborted, Accepted, Command, Done, Feedback, MasterHandshake,
                       Rejected, StatusBits, TimedOut, commands_for)

log = logging.getLogger("vr_driver.driver")

Clock = Callable[[], float]


class DriverError(VrDriverError):
    """A request the driver refuses (not connected, e-stop, bad input...). The message says why."""


class LinkState(enum.Enum):
    STARTING = "starting"          # port not opened yet
    CONNECTING = "connecting"      # port open, DP slave not (yet) in Data_Exchange
    CONNECTED = "connected"        # Data_Exchange with fresh, valid feedback
    LOST = "lost"                  # was connected; feedback stale, slave silent or invalid data
    PORT_ERROR = "port_error"      # the port cannot be opened / died; reopening periodically


class JobPhase(enum.Enum):
    QUEUED = "queued"
    SENDING = "sending"            # target sent, waiting for the controller to accept it
    MOVING = "moving"
    SUCCEEDED = "succeeded"
    FAILED = "failed"              # rejected, timed out, link lost
    CANCELLED = "cancelled"


# Error codes in RobotStatus.error_code (documented in doc/README.md).
ERROR_NONE = 0
ERROR_LINK = 1                     # link to the controller down
ERROR_CONTROLLER = 2               # the controller reports its error bit
ERROR_PROTOCOL = 3                 # the controller's feedback cannot be decoded

# a queued job whose planned start differs from the current joints by more than this [rad] is
# planned again before it is sent (whole-mm / whole-degree feedback alone stays well below it)
START_TOLERANCE = 0.02

# the first request of a Data_Exchange session waits for this many replies in the session: the
# controller then got our record with the flag at 0 in as many telegrams, which arms it (it must
# see the flag at 0 after a link loss; the virtual controller, like a careful G2 program, acts on
# a record only once it arrived unchanged in two consecutive telegrams)
SESSION_RECORDS_BEFORE_REQUEST = 2

# a port that cannot be opened is a warning at first (a virtual controller may still be starting),
# an error once it has been missing this long [s]
PORT_ERROR_AFTER = 5.0


@dataclass(frozen=True)
class MoveRequest:
    """A move in controller units (mm, deg; frame base)."""

    move_type: MoveType
    target: ControllerPose
    via: Optional[ControllerPose] = None
    preview_only: bool = False
    label: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "move_type", MoveType.parse(self.move_type))
        if not isinstance(self.target, ControllerPose):
            object.__setattr__(self, "target", ControllerPose.from_sequence(self.target))
        if self.via is not None and not isinstance(self.via, ControllerPose):
            object.__setattr__(self, "via", ControllerPose.from_sequence(self.via))


@dataclass(frozen=True)
class Preview:
    """A validated move: the wire commands (rounded, checked) and the planned trajectory."""

    request: MoveRequest
    commands: Tuple[Command, ...]
    trajectory: Trajectory
    joint_target: Tuple[float, ...]

    @property
    def duration(self) -> float:
        return self.trajectory.duration

    @property
    def target(self) -> ControllerPose:
        return self.commands[-1].pose


@dataclass(frozen=True)
class JobResult:
    success: bool
    phase: JobPhase
    reason: str = ""
    reached: Optional[ControllerPose] = None


class MoveJob:
    """One move on its way to the controller. Wait with :meth:`wait`; the bus thread sets the
    phase and the result. ``on_update(job)`` (optional) is called from the bus thread on changes."""

    _ids = itertools.count(1)

    def __init__(self, preview: Preview, on_update: Optional[Callable[["MoveJob"], None]] = None,
                 group: Optional[int] = None):
        self.id = next(MoveJob._ids)
        self.group = self.id if group is None else group   # the jobs of one streamed path share it
        self.preview = preview
        self.on_update = on_update
        self.phase = JobPhase.QUEUED
        self.result: Optional[JobResult] = None
        self.next_command = 0           # index into preview.commands of the next one to send
        self.seqs: List[int] = []       # handshake sequence numbers of what was sent
        self.created = time.monotonic()
        self._done = threading.Event()
        self._changed = threading.Condition()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def wait(self, timeout: Optional[float] = None) -> Optional[JobResult]:
        self._done.wait(timeout)
        return self.result

    def wait_change(self, phase: JobPhase, timeout: float) -> JobPhase:
        """Wait until the phase differs from ``phase`` (or ``timeout``); return the phase."""
        with self._changed:
            self._changed.wait_for(lambda: self.phase is not phase, timeout)
            return self.phase

    def _set_phase(self, phase: JobPhase) -> None:
        if self.phase is not phase:
            with self._changed:
                self.phase = phase
                self._changed.notify_all()
            self._notify()

    def _finish(self, success: bool, phase: JobPhase, reason: str,
                reached: Optional[ControllerPose]) -> None:
        if self._done.is_set():
            return
        with self._changed:
            self.phase = phase
            self.result = JobResult(success, phase, reason, reached)
            self._done.set()
            self._changed.notify_all()
        self._notify()

    def _notify(self) -> None:
        if self.on_update is not None:
            try:
                self.on_update(self)
            except Exception:  # a client callback must never kill the bus thread
                log.exception("job %d: update callback failed", self.id)

    def __repr__(self) -> str:
        return "MoveJob(%d, %s, %s)" % (self.id, self.preview.request.move_type.name, self.phase.value)


@dataclass
class LinkCounters:
    cycles: int = 0
    port_opens: int = 0
    port_errors: int = 0
    reconnect_attempts: int = 0
    losses: int = 0
    reconnects: int = 0
    protocol_errors: int = 0
    targets_sent: int = 0
    targets_done: int = 0
    targets_rejected: int = 0
    targets_aborted: int = 0


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


def _diag_words(diag: Any) -> str:
    from pyprofibus_vendor.dp import explain_diag
    try:
        return explain_diag(diag)
    except Exception:  # a diag we cannot explain is still worth showing raw
        return repr(diag)


def why_no_motion(fb: Feedback) -> str:
    """What in the controller's status bits forbids motion ("" when nothing does)."""
    bits = fb.status
    reasons = []
    if bits & StatusBits.ESTOP:
        reasons.append("the emergency stop is active")
    if bits & StatusBits.ERROR:
        reasons.append("the controller reports an error")
    if not bits & StatusBits.DRIVES_POWERED:
        reasons.append("the drives are off")
    if not bits & StatusBits.PROGRAM_RUNNING:
        reasons.append("the controller program is not running (manual mode)")
    return "; ".join(reasons)


def _port_hint(exc: BaseException) -> str:
    """What an error opening the port most likely means, for the errors with a clear remedy."""
    codes = set()
    seen: Optional[BaseException] = exc
    for _ in range(5):
        if seen is None:
            break
        if isinstance(getattr(seen, "errno", None), int):
            codes.add(seen.errno)
        seen = seen.__cause__ or seen.__context__
    text = str(exc)
    if codes & {errno.EACCES, errno.EPERM} or "Permission denied" in text:
        return (" (permission denied: the driver's user needs read and write access to the device, "
                "usually membership of its group, e.g. dialout)")
    if errno.EBUSY in codes or "Device or resource busy" in text:
        return " (the device is busy: another program has it open)"
    return ""


def open_serial_link(device: str, baud: int) -> Link:
    """Default link factory: the serial PHY (raises PhyError with the OS reason)."""
    from pyprofibus_vendor.phy_serial import SerialLink
    return SerialLink(device, baud)


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
            kinematics = Kinematics.default()
            if any(params.tcp_offset):
                kinematics.conventions = kinematics.conventions.with_tcp(params.tcp_offset)
        self.kin = kinematics
        self.planner = planner or MotionPlanner(self.kin)
        self.clock = clock
        self.open_link = open_link
        self.handshake = MasterHandshake(params.accept_timeout, params.release_timeout, clock=clock)
        self.counters = LinkCounters()
        self._lock = threading.RLock()
        self._queue: Deque[MoveJob] = collections.deque()
        self._job: Optional[MoveJob] = None
        self._stop_request: Optional[str] = None
        self._stop = threading.Event()
        self._wake = threading.Event()      # set by requests: run a bus cycle now, not at the next tick
        self._thread: Optional[threading.Thread] = None
        self._link: Optional[Link] = None
        self._master: Optional[DpMaster] = None
        self._slave = None
        self._link_state = LinkState.STARTING
        self._link_reason = "not started"
        self._next_open = 0.0
        self._feedback: Optional[Feedback] = None
        self._feedback_time: Optional[float] = None  # when the feedback's record arrived
        self._record_time: Optional[float] = None    # when the last record (good or bad) arrived
        self._good_time: Optional[float] = None      # when the last good record arrived
        self._bad_record = ""                          # why the last record could not be decoded
        self._session_start = 0.0                      # the slave (re)entered Data_Exchange
        self._session_records = 0                      # good records received in this session
        self._logged_slave_reason = ""                 # the last card failure logged (numbers out)
        self._garbage_seen = 0                         # master's garbled bytes at the last good
                                                       # record or failure
        self._last_good: Optional[Feedback] = None
        self._joints: Optional[Tuple[float, ...]] = None
        self._joints_valid = False
        self._joints_pose: Optional[Tuple[int, ...]] = None
        self._slave_reason = ""
        self._port_missing_since = 0.0
        self._port_error_logged = False
        self._error_code = ERROR_LINK
        self._error_reason = "not started"
        self._cycle_times: Deque[float] = collections.deque(maxlen=50)
        self._listeners: List[Callable[[DriverStatus], None]] = []
        self._status = self._snapshot(self.clock())

    # ------------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vr_driver-bus", daemon=True)
        self._thread.start()

    def request_stop(self) -> None:
        """Ask the bus thread to end, without waiting (safe from a signal handler or a ROS shutdown
        hook, which may interrupt a thread that holds a lock :meth:`stop` needs)."""
        self._stop.set()
        self._wake.set()

    def stop(self, timeout: float = 3.0) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        with self._lock:
            self._fail_all(JobPhase.CANCELLED, "driver shut down")
        self._close_link()

    def add_listener(self, callback: Callable[[DriverStatus], None]) -> None:
        """``callback(status)`` after every bus cycle and link state change (bus thread)."""
        self._listeners.append(callback)

    # ------------------------------------------------------------------------ queries
    def status(self) -> DriverStatus:
        return self._status

    @property
    def joint_names(self) -> Tuple[str, ...]:
        return self.params.controller_joint_names

    # ------------------------------------------------------------------------ requests
    def preview(self, request: MoveRequest, start_joints: Optional[Sequence[float]] = None) -> Preview:
        """Validate and plan ``request`` from the current joints (or ``start_joints``); sends
        nothing. Raises VrDriverError (PoseError, KinematicsError, MotionError, ProtocolError,
        DriverError) with the reason."""
        if start_joints is None:
            status = self._status
            if status.joints is None or not status.joints_valid:
                raise DriverError("no valid current joint state to plan from (%s)"
                                  % (status.link_reason or status.link.value))
            start_joints = status.joints
        commands = tuple(commands_for(request.move_type, request.target, request.via,
                                      self.params.workspace))
        # plan to exactly what will be sent (whole mm / deg)
        target = commands[-1].pose
        via = commands[0].pose if len(commands) == 2 else None
        trajectory = self.planner.plan(request.move_type, start_joints, target, via)
        return Preview(request, commands, trajectory, tuple(trajectory.goal))

    def submit(self, request: MoveRequest, on_update: Optional[Callable[[MoveJob], None]] = None
               ) -> MoveJob:
        """Validate, preview and queue a move. Raises (and queues nothing) when it is invalid,
        unreachable, or the controller cannot move now."""
        self._require_motion_possible()
        with self._lock:
            start = self._planning_start()
            job = MoveJob(self.preview(request, start), on_update)
            self._queue.append(job)
        self._wake.set()
        log.info("job %d queued: %s %s", job.id, request.move_type.name,
                 " then ".join(c.describe() for c in job.preview.commands))
        return job

    def submit_joint_path(self, names: Sequence[str], points: Sequence[Sequence[float]],
                          on_update: Optional[Callable[[MoveJob], None]] = None) -> List[MoveJob]:
        """Each joint point -> FK -> a PTP target, streamed in order. All points are validated
        and previewed first; if any is bad, nothing is queued and DriverError names the point.
        An empty ``points`` stops the motion."""
        if not points:
            self.stop_motion("empty joint path: stop requested")
            return []
        order = self._joint_order(names)
        self._require_motion_possible()
        with self._lock:
            start = self._planning_start()
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
            jobs = [MoveJob(p, on_update) for p in previews]
            for job in jobs[1:]:
                job.group = jobs[0].group
            self._queue.extend(jobs)
        self._wake.set()
        log.info("joint path: %d PTP targets queued (jobs %d..%d)", len(jobs), jobs[0].id, jobs[-1].id)
        return jobs

    def cancel(self, job: MoveJob, reason: str = "cancelled") -> None:
        """Cancel one job: a queued one is dropped; the one in flight stops the motion."""
        with self._lock:
            if job in self._queue:
                self._queue.remove(job)
                job._finish(False, JobPhase.CANCELLED, reason, None)
                return
            if job is self._job:
                self._stop_request = reason
        self._wake.set()

    def stop_motion(self, reason: str = "stop requested") -> int:
        """Drop the queue and give up the target in flight; returns the number of jobs ended."""
        with self._lock:
            n = len(self._queue) + (1 if self._job is not None else 0)
            for job in list(self._queue):
                job._finish(False, JobPhase.CANCELLED, reason, None)
            self._queue.clear()
            if self._job is not None:
                self._stop_request = reason
        self._wake.set()
        log.info("stop motion: %s (%d job(s) ended)", reason, n)
        return n

    # ------------------------------------------------------------------------ request helpers
    def _require_motion_possible(self) -> None:
        status = self._status
        if not status.motion_possible:
            raise DriverError("motion is not possible: %s" % status.why_no_motion())

    def _planning_start(self) -> Tuple[float, ...]:
        """Where the next queued move starts: the last queued job's joint target, else now."""
        if self._queue:
            return self._queue[-1].preview.joint_target
        if self._job is not None:
            return self._job.preview.joint_target
        status = self._status
        if status.joints is None or not status.joints_valid:
            raise DriverError("no valid current joint state to plan from")
        return status.joints

    def _joint_order(self, names: Sequence[str]) -> List[int]:
        expected = list(self.params.controller_joint_names)
        names = list(names)
        if sorted(names) != sorted(expected) or len(names) != len(set(names)):
            raise DriverError("joint names %s do not match the controller's joints %s"
                              % (names, expected))
        return [expected.index(n) for n in names]

    # ------------------------------------------------------------------------ bus thread
    def _run(self) -> None:
        period = 1.0 / self.bus.cycle_rate_hz
        next_start = self.clock()
        while not self._stop.is_set():
            try:
                self._iteration()
            except Exception:  # never let the bus thread die: log, drop the link, reopen
                log.exception("bus thread: unexpected error; reopening the link")
                self._link_down(LinkState.PORT_ERROR, "internal error (see log)")
                self._close_link()
            next_start += period
            now = self.clock()
            if next_start < now:
                next_start = now
            if self._wake.wait(next_start - now):
                self._wake.clear()
                next_start = self.clock()     # an extra cycle now; the rate resumes from here

    def _iteration(self) -> None:
        now = self.clock()
        if self._master is None:
            if now < self._next_open:
                self._publish(now)
                return
            self._open(now)
            if self._master is None:
                self._publish(now)
                return
        master = self._master
        try:
            master.cycle(timeout=max(0.2, 2.0 / self.bus.cycle_rate_hz))
        except ProfibusError as exc:
            self.counters.port_errors += 1
            self._close_link()
            self._next_open = self.clock() + self.params.reconnect_period
            self._link_down(LinkState.PORT_ERROR, "serial port %s failed: %s" % (self.bus.phy.device, exc))
            self._publish(self.clock())
            return
        now = self.clock()
        self.counters.cycles += 1
        self._cycle_times.append(now)
        self._after_cycle(now)
        self._publish(now)

    def _open(self, now: float) -> None:
        device, baud = self.bus.phy.device, self.bus.baud
        self.counters.reconnect_attempts += 1
        try:
            link = self.open_link(device, baud)
        except (ProfibusError, OSError, ValueError) as exc:
            self._next_open = now + self.params.reconnect_period
            reason = "cannot open %s: %s%s" % (device, exc, _port_hint(exc))
            if reason != self._link_reason:
                self._port_missing_since = now
                log.warning("%s (retrying every %.2g s)", reason, self.params.reconnect_period)
            elif now - self._port_missing_since >= PORT_ERROR_AFTER and not self._port_error_logged:
                log.error("%s for %.0f s now (still retrying every %.2g s)", reason,
                          now - self._port_missing_since, self.params.reconnect_period)
            self._port_error_logged = now - self._port_missing_since >= PORT_ERROR_AFTER
            self._link_down(LinkState.PORT_ERROR, reason)
            return
        self.counters.port_opens += 1
        self._slave_reason = ""
        self._garbage_seen = 0
        timing = BusTiming.for_baud(self.bus.baud, self.bus.retry_limit)
        if self.bus.slot_time is not None:
            timing = replace(timing, slot_bits=self.bus.slot_time)
        # dx_tolerance: a Data_Exchange without a reply (a corrupted telegram) does not drop the
        # slave -- and with its Set_Prm the controller's program session -- before the link counts
        # as lost here anyway (link_timeout without a good record); retry_steps: a lost reply in
        # the start-up sequence repeats that step instead of restarting it after a back-off
        master = DpMaster(link, self.bus.master_address, self.bus.baud, clock=self.clock,
                          timing=timing, backoff_max=min(1.0, self.params.reconnect_period),
                          dx_tolerance=self.params.link_timeout, retry_steps=True,
                          on_state_change=self._on_slave_state)
        sc = self.slave_config
        spec = SlaveSpec(sc.address, sc.ident, sc.cfg, user_prm_data=sc.user_prm_data,
                         group_ident=sc.group_mask,
                         watchdog=None if not sc.watchdog_ms else sc.watchdog_ms / 1000.0)
        self._slave = master.add_slave(spec)
        self._slave.outputs = Command.idle().encode(self.params.byte_order)
        self._master = master
        self._link = link
        log.info("opened %s at %d bit/s; bringing slave %d (ident 0x%04X) to Data_Exchange",
                 device, baud, sc.address, sc.ident)
        self._link_down(LinkState.CONNECTING, "port open, waiting for the controller's PROFIBUS card")

    def _close_link(self) -> None:
        link, self._link, self._master, self._slave = self._link, None, None, None
        if link is not None:
            try:
                link.close()
            except Exception:  # closing a dead port may fail; nothing to do about it
                pass

    def _on_slave_state(self, slave, old: MasterSlaveState, new: MasterSlaveState, reason: str) -> None:
        """The DP master's per-slave state changes: keep the last reason for the status."""
        if new is MasterSlaveState.INIT:
            self.counters.reconnect_attempts += 1
        connected = (MasterSlaveState.DATA_EXCHANGE, MasterSlaveState.DX_DIAG)
        if new in connected and old not in connected:
            self._session_start = self.clock()    # records from before are of the old session
            self._session_records = 0
        if new is MasterSlaveState.BACKOFF:
            self._slave_reason = "controller's PROFIBUS card (slave %d): %s" % (
                slave.address, self._explain_failure(slave, reason))
            key = re.sub(r"[0-9]+(\.[0-9]+)?", "#", self._slave_reason)   # not for new numbers
            if key != self._logged_slave_reason:
                self._logged_slave_reason = key
                log.warning("%s", self._slave_reason)
        elif new in connected:
            self._logged_slave_reason = ""

    def _explain_failure(self, slave, reason: str) -> str:
        """The master's reason for ending an attempt, with what it most likely means."""
        diag = slave.last_diag
        sc = self.slave_config
        master = self._master
        garbage = master.counters.garbage_bytes + master.counters.fcs_errors if master is not None else 0
        garbled, self._garbage_seen = garbage > self._garbage_seen, garbage
        if reason.startswith("diag:") and diag is not None:
            if diag.ident != sc.ident:
                hint = ("the station at address %d reports ident 0x%04X, the driver expects 0x%04X "
                        "(another device at this address, or the wrong slave_address?)"
                        % (slave.address, diag.ident, sc.ident))
            elif diag.status1 & DiagStatus1.CFG_FAULT:
                hint = ("the card rejects the configuration %s (%d bytes in / %d out): its modules "
                        "differ from the bus config" % (sc.cfg.hex(" "), slave.spec.input_size,
                                                        slave.spec.output_size))
            elif diag.status1 & DiagStatus1.PRM_FAULT:
                hint = "the card rejects the parameters (Set_Prm: ident, watchdog, user data)"
            else:
                hint = ""
            return "%s%s (diag bytes %s)" % (hint + "; " if hint else "", reason,
                                             diag.encode()[:3].hex(" "))
        if reason.startswith("no reply"):
            if garbled:
                hint = ("bytes arrive but form no valid telegram: wrong baud rate or parity at the "
                        "other end, or a noisy line")
            else:
                hint = ("nothing valid received: is the controller on, the cable connected, the card "
                        "at address %d and %d bit/s?" % (slave.address, self.bus.baud))
            return "%s; %s" % (reason, hint)
        extra = "; diag: %s" % _diag_words(diag) if diag is not None else ""
        return reason + extra

    def _after_cycle(self, now: float) -> None:
        """Take the cycle's record (if a new one arrived), update the link state, the handshake
        and the jobs. Only a record that arrived since the last cycle is an observation for the
        handshake; the link counts as up while the last good record of this Data_Exchange session
        is at most ``link_timeout`` old (a record lost or garbled in between is not a loss)."""
        slave = self._slave
        fresh: Optional[Feedback] = None
        reason = ""
        if slave is None or not slave.connected:
            state = slave.state.value if slave is not None else "none"
            reason = self._slave_reason or "controller's PROFIBUS card not in Data_Exchange (%s)" % state
        else:
            data, at = slave.inputs, slave.inputs_time
            if data is not None and at is not None and at >= self._session_start \
                    and at != self._record_time:
                self._record_time = at
                try:
                    fresh = Feedback.decode(data, self.params.byte_order)
                    self._bad_record = ""
                except ProtocolError as exc:
                    self.counters.protocol_errors += 1
                    if not self._bad_record:
                        log.warning("invalid feedback from the controller (ignored while the link "
                                    "holds): %s", exc)
                    self._bad_record = "invalid feedback from the controller: %s" % exc
            if fresh is not None:
                self._good_time = at
                self._session_records += 1
                master = self._master
                if master is not None:        # garbled bytes are counted from the last good record
                    self._garbage_seen = master.counters.garbage_bytes + master.counters.fcs_errors
            last = max(self._session_start, self._good_time or 0.0)
            if now - last > self.params.link_timeout or self._good_time is None \
                    or self._good_time < self._session_start:
                reason = self._bad_record or \
                    "no fresh data from the controller for %.2f s" % (now - last)
        with self._lock:
            if reason:
                was = self._link_state
                self._link_down(LinkState.LOST if was in (LinkState.CONNECTED, LinkState.LOST)
                                else LinkState.CONNECTING, reason)
                if self._bad_record and reason == self._bad_record:
                    self._error_code, self._error_reason = ERROR_PROTOCOL, reason
                self.handshake.update(None, now)
            else:
                if fresh is not None:
                    if self._link_state is not LinkState.CONNECTED:
                        if self.counters.losses:
                            self.counters.reconnects += 1
                        log.info("link to the controller up: %s", fresh.describe())
                    self._slave_reason = ""
                    self._link_state, self._link_reason = LinkState.CONNECTED, "Data_Exchange"
                    self._feedback = self._last_good = fresh
                    self._feedback_time = at
                    self._update_joints(fresh)
                fb = self._feedback
                if fb is not None:
                    event = self.handshake.update(fresh, now)
                    self._on_event(event, fb)
                    self._advance_jobs(now, fb)
                    if fb.status & StatusBits.ERROR:
                        self._error_code, self._error_reason = ERROR_CONTROLLER, "the controller reports an error"
                    else:
                        self._error_code, self._error_reason = ERROR_NONE, ""
            if self._slave is not None:
                self._slave.outputs = self.handshake.outputs().encode(self.params.byte_order)

    def _link_down(self, state: LinkState, reason: str) -> None:
        with self._lock:
            was = self._link_state
            if was is LinkState.CONNECTED and state is not LinkState.CONNECTED:
                self.counters.losses += 1
                log.error("link to the controller lost: %s", reason)
            if was is LinkState.CONNECTED or state is LinkState.PORT_ERROR:
                aborted = self.handshake.reset(reason)
                if aborted is not None:
                    self.counters.targets_aborted += 1
                self._fail_all(JobPhase.FAILED, "link to the controller lost (%s); the target is "
                               "not re-sent" % reason)
            self._link_state, self._link_reason = state, reason
            self._feedback = None
            self._feedback_time = None
            self._joints_valid = False
            self._error_code, self._error_reason = ERROR_LINK, reason

    def _fail_all(self, phase: JobPhase, reason: str) -> None:
        jobs = ([self._job] if self._job is not None else []) + list(self._queue)
        self._job = None
        self._queue.clear()
        self._stop_request = None
        for job in jobs:
            job._finish(False, phase, reason, self._last_good.pose if self._last_good else None)

    def _update_joints(self, fb: Feedback) -> None:
        values = fb.values
        if values == self._joints_pose and self._joints_valid:
            return
        try:
            self._joints = self.kin.ik_pose(fb.pose, seed=self._joints)
            self._joints_valid = True
            self._joints_pose = values
        except VrDriverError as exc:
            if self._joints_valid:
                log.warning("no joint solution for the reported pose %s: %s", values, exc)
            self._joints_valid = False

    def _on_event(self, event, fb: Feedback) -> None:
        job = self._job
        if event is None:
            return
        if isinstance(event, Accepted):
            if job is not None:
                job._set_phase(JobPhase.MOVING)
            return
        if isinstance(event, Done):
            self.counters.targets_done += 1
            if job is None:
                return
            if job.next_command < len(job.preview.commands):
                return                       # the via point of a CIRC: the end point follows
            self._job = None
            self._stop_request = None
            log.info("job %d done at %s", job.id, fb.values)
            job._finish(True, JobPhase.SUCCEEDED, "", fb.pose)
            return
        if isinstance(event, TimedOut) and not event.final:
            log.warning("%s", event.reason)
            return
        if isinstance(event, Rejected):
            self.counters.targets_rejected += 1
        elif isinstance(event, (TimedOut, Aborted)):
            self.counters.targets_aborted += 1
        if job is not None:
            self._job = None
            cancelled = self._stop_request is not None and isinstance(event, Aborted)
            reason = event.reason
            self._stop_request = None
            log.warning("job %d ended: %s", job.id, reason)
            job._finish(False, JobPhase.CANCELLED if cancelled else JobPhase.FAILED, reason, fb.pose)
            # a failed target ends the rest of its streamed path too: never skip ahead silently
            self._fail_queue("an earlier target of the same path failed (%s)" % reason, job.group)

    def _fail_queue(self, reason: str, group: Optional[int] = None) -> None:
        """End the queued jobs (of one group only, when given) with ``reason``."""
        for queued in list(self._queue):
            if group is None or queued.group == group:
                queued._finish(False, JobPhase.FAILED, reason, None)
                self._queue.remove(queued)

    def _advance_jobs(self, now: float, fb: Feedback) -> None:
        if self._stop_request is not None:
            reason = self._stop_request
            event = self.handshake.abort(reason, now, stop=True)
            if event is not None:
                self._on_event(event, fb)
            elif self._job is not None and self._job.next_command > 0:
                # between the via point and the end point of a CIRC: nothing in flight
                job, self._job = self._job, None
                job._finish(False, JobPhase.CANCELLED, reason, fb.pose)
            self._stop_request = None
        if not self.handshake.ready:
            return
        if self._session_records < SESSION_RECORDS_BEFORE_REQUEST:
            return          # the controller has not surely seen our flag at 0 twice yet
        if self._job is None:
            if not self._queue:
                return
            why = why_no_motion(fb)
            if why:
                self._fail_queue("motion is no longer possible: %s" % why)
                return
            self._job = self._queue.popleft()
        job = self._job
        if job.next_command >= len(job.preview.commands):
            return
        if job.next_command == 0 and not self._still_valid(job):
            return
        command = job.preview.commands[job.next_command]
        timeout = (self.params.motion_timeout_factor * job.preview.duration
                   + self.params.motion_timeout_margin)
        try:
            seq = self.handshake.submit(command, timeout, now)
        except HandshakeError as exc:   # cannot happen when ready; keep the job queued
            log.warning("job %d: %s", job.id, exc)
            return
        job.seqs.append(seq)
        job.next_command += 1
        self.counters.targets_sent += 1
        log.info("job %d: sent target %d: %s", job.id, seq, command.describe())
        job._set_phase(JobPhase.SENDING)

    def _still_valid(self, job: MoveJob) -> bool:
        """A job is previewed from where the arm was expected to be when it was queued. If the arm
        is elsewhere now (an earlier move was stopped or failed), plan it again from here, so the
        path that was validated is the path that runs; if that fails, the job fails (not sent)."""
        current = self._joints if self._joints_valid else None
        start = job.preview.trajectory.start
        if current is not None and max(abs(a - b) for a, b in zip(current, start)) <= START_TOLERANCE:
            return True
        try:
            if current is None:
                raise DriverError("no valid joint state to plan from")
            job.preview = self.preview(job.preview.request, current)
        except VrDriverError as exc:
            self._job = None
            log.warning("job %d not sent: the arm is not where it was planned from, and from "
                        "here: %s", job.id, exc)
            job._finish(False, JobPhase.FAILED, "not sent: from the arm's current pose: %s" % exc,
                        self._last_good.pose if self._last_good else None)
            self._fail_queue("an earlier target of the same path failed (%s)" % exc, job.group)
            return False
        log.info("job %d planned again from the arm's current pose (%.1f s)", job.id, job.preview.duration)
        return True

    # ------------------------------------------------------------------------ snapshots
    def _snapshot(self, now: float) -> DriverStatus:
        times = self._cycle_times
        rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 and times[-1] > times[0] else 0.0
        master = self._master
        slave = self._slave
        diag = _diag_words(slave.last_diag) if slave is not None and slave.last_diag is not None else ""
        fb = self._feedback
        return DriverStatus(
            time=now, link=self._link_state, link_reason=self._link_reason, feedback=fb,
            pose=fb.pose if fb is not None else None,
            joints=self._joints, joints_valid=self._joints_valid and fb is not None,
            job=self._job, queue_length=len(self._queue), cycle_rate=rate,
            counters=replace(self.counters),
            master_counters=dict(vars(master.counters)) if master is not None else {},
            slave_state=slave.state.value if slave is not None else "closed",
            last_diag=diag, error_code=self._error_code, error_reason=self._error_reason,
            feedback_time=self._feedback_time if fb is not None else None)

    def _publish(self, now: float) -> None:
        with self._lock:
            self._status = self._snapshot(now)
        for callback in self._listeners:
            try:
                callback(self._status)
            except Exception:
                log.exception("status listener failed")
