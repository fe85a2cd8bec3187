"""A stream made ready to send, per protocol family (ROS-free, no I/O; callers' threads and the
planning thread, never the bus thread). A planned path (times and joint positions) becomes the
points of one stream job (:func:`vr_driver.driver.motion.stream_points.stream_points`: thinned with its
timing, each segment's speed from its planned duration, blended through with ``stream_smooth``),
and every straight joint move between them is checked -- the joint limits, the workspace box and
the cell -- before anything is queued.

- :class:`JointStreams` (v2: joint targets): the controller runs the joints as sent.
- :class:`CartesianStreams` (v3: pose targets): the controller solves each target's pose itself,
  as the IK solution nearest the joints its configuration rule names (``controller/configuration``,
  :class:`~vr_driver.kinematics.solver.ConfigurationRule`; doc/controller_program.md section 7 and
  section 10.9): the previous target's (``previous_target``, the documented assumption) or the
  arm's when it takes the target (``current_joints``). Each point also gets the pose the wire
  carries -- the planned pose rounded, or near joint_5 = 0 the one-step neighbour of that rounding
  the controller solves nearest the plan (:mod:`.wire_targets`) -- solved as the controller will
  by that rule: it must land on the planned joints within CONFIGURATION_TOLERANCE, or the
  controller would run another configuration than the one planned and checked; no joint turns by
  more than :attr:`CartesianStreams.max_step` between two points.

  **current_joints: where the arm is when the G2 takes a target** (the driver's assumption, stated
  here and in doc/controller_program.md section 10.9): the master offers each target as soon as the
  one before was taken, and the G2 takes it once its ring (``controller/ring_size`` targets, the one
  the arm runs to and those read ahead) has room -- once the arm passed the target ``ring_size``
  before it, i.e. began blending out of it. So when the G2 takes point i the arm lies on the planned
  path between point i - ring_size - 1 and point i - 1 (the start for the first points; a blend
  around point i - ring_size stays inside the triangle of it and its two neighbours); later still
  when the bus or a pause held the target back, but never past point i - 1, where it stops and
  waits. Which of a pose's IK solutions lies nearest a seed changes only across planes (the seeds
  nearer one solution than another form a half-space), so the same solution is nearest every
  joints of that stretch exactly when it is nearest each of its points: every point is solved from
  each of the ring_size + 1 points before it (:func:`~.wire_targets.wire_target`'s ``also``), and
  all must land on the plan. Points are kept at most CARTESIAN_MAX_STEP / (ring_size + 1) apart in
  each joint and CARTESIAN_MAX_REACH / (ring_size + 1) in all joints together, so that over the
  stretch a joint turns by no more than CARTESIAN_MAX_STEP and the wrist moves no more than a
  quarter of the way to its flip (measured: a straight move to the flipped wrist in 18 deg steps
  of joint_4 and joint_6 was solved back onto the start's wrist halfway, at joint_5 = 0).

:func:`stream_preparation` makes the family a protocol names ready (``wire.stream_family()``,
registered by :mod:`.sequencers`; None for one that does not stream: v1).

The preparation runs between a goal's arrival and its first target (issue 46: a goal moves within
0.1 s of its arrival), in the goal's thread beside the bus thread: it does not hand the interpreter
over point by point -- the node's switch interval (1 ms, ``ros/interface.py``) lets the bus thread in
whenever it wakes, and a yield per point cost a time slice each on a loaded machine.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Optional, Sequence, Tuple

from ...errors import VrDriverError
from ...kinematics.solver import ConfigurationRule, Kinematics
from ...params import DriverParams
from ...poses import ControllerPose
from ...protocol.base import Protocol
from ..motion.jobs import MoveJob, Preview, StreamPoint
from .path_checks import PathChecks
from ..motion.status import DriverError
from ..motion.stream_points import (MAX_CARTESIAN_TOLERANCE, MAX_STREAM_TOLERANCE, hold_speed, stream_points,
                                    stream_speeds)
from .commissioned import feed_cycles, min_segment_cycles
from .wire_targets import CARTESIAN_MAX_STEP, FINE, WireMemo, WireTarget, wire_target

__all__ = ["CARTESIAN_MAX_REACH", "CARTESIAN_MAX_STEP", "CONFIGURATION_TOLERANCE", "CartesianStreams", "JointStreams",
           "stream_preparation"]

#: rad: a Cartesian stream's target, solved as the controller will (the IK solution nearest the
#: joints its configuration rule names), must land this near the planned point (every joint);
#: farther, the controller would run another configuration than the one planned and checked
CONFIGURATION_TOLERANCE = math.radians(1.0)
#: [rad] current_joints: the widest straight joint distance (all joints together) over the stretch
#: of the plan the arm may be on when the controller takes a target -- a quarter of the distance
#: to the pose's flipped-wrist solution (joint_4 and joint_6 half a turn each: pi sqrt 2), as
#: CARTESIAN_MAX_STEP is a quarter of a joint's turn; per step, this over the window
CARTESIAN_MAX_REACH = math.pi * math.sqrt(2.0) / 4.0


def fmt_pose(pose: ControllerPose) -> str:
    return "(%.1f, %.1f, %.1f mm, %.2f, %.2f, %.2f deg)" % pose.as_tuple()


class JointStreams:
    """Streams of joint targets (v2). ``cycle_rate()``: the bus cycles per second the stream is fed
    at now [Hz] (the driver's: the configured rate, or the measured one where it is slower); the
    segment and the feed it allows are that many cycles of it (:meth:`min_segment`,
    :meth:`feed_period`)."""

    #: the widest joint step between two points (None: any)
    max_step: Optional[float] = None

    def __init__(self, params: DriverParams, kinematics: Kinematics, wire: Protocol, checks: PathChecks,
                 cycle_rate: Callable[[], float]) -> None:
        self.params = params
        self.kin = kinematics
        self.wire = wire
        self.checks = checks
        self.cycle_rate = cycle_rate
        # the bus cycles of a segment and of a target's feed: the commissioned G2's and the
        # protocol's, fixed for the driver's life (not a goal's work)
        self._segment_cycles = min_segment_cycles(params, wire)
        self._feed_cycles = feed_cycles(wire)

    def min_segment(self) -> float:
        """[s] the shortest stream segment the bus feeds without a gap now:
        :func:`~.commissioned.min_segment_cycles` of its cycles."""
        return self._segment_cycles / self.cycle_rate()

    def points(self, times: Sequence[float], positions: Sequence[Sequence[float]], tolerance: float,
               max_tolerance: float) -> Tuple[StreamPoint, ...]:
        """The stream of the path ``times`` / ``positions`` (from ``positions[0]``, where the arm
        is), thinned to ``tolerance`` (at most ``max_tolerance`` where the bus could not feed the
        segments); () when the path does not move."""
        memo = self.memo()          # (v3: the wire poses and their solutions, shared by both steps)
        points = stream_points(times, positions, self.kin.limits.velocity, self.params.stream_smooth,
                               tolerance, self.min_segment(), max_tolerance,
                               corner_tolerance=math.radians(self.params.stream_path_tolerance),
                               max_step=self.max_step, reaches=self.reaches(memo), feed=self.feed_period(),
                               ring=self.ring(), hold=self.holds())
        if not points:
            return points
        return self.with_poses(positions[0], points, memo=memo)

    def trajectory(self, times: Sequence[float], positions: Sequence[Sequence[float]]) -> Tuple[StreamPoint, ...]:
        """A planner trajectory's stream (thinned to ``stream_path_tolerance``) with every segment
        checked (:meth:`check_segments`); () when it does not move. Raises DriverError naming the
        point or the segment (and that nothing was sent)."""
        tol = math.radians(self.params.stream_path_tolerance)
        points = self.points(times, positions, tol, max(tol, MAX_STREAM_TOLERANCE))
        if points:
            try:
                self.check_segments(positions[0], points)
            except VrDriverError as exc:
                raise DriverError("%s; nothing was sent" % exc) from None
        return points

    def feed_period(self) -> float:
        """[s] how long the bus takes to bring the controller one target now:
        :func:`~.commissioned.feed_cycles` of its cycles."""
        return self._feed_cycles / self.cycle_rate()

    def ring(self) -> int:
        """The targets the controller holds at once, a new one taken once the arm passed the one
        that many before (:func:`~vr_driver.driver.motion.stream_points.fed_schedule`); 0: not
        modelled -- v2's queue of two takes the next target once the arm passed the one before, and
        its segments of at least MIN_SEGMENT_CYCLES keep it fed."""
        return 0

    def holds(self) -> bool:
        """May a stream begin with a hold while the bus fills the controller's ring
        (:func:`~vr_driver.driver.motion.stream_points.fed_schedule`)? v2: no -- its queue of two has
        no room for the targets a hold would gather."""
        return False

    def memo(self) -> Optional[WireMemo]:
        """A memo for one stream check's wire poses (None: joint targets have none)."""
        return None

    def reaches(self, memo: Optional[WireMemo] = None) -> Optional[Callable[[Sequence[float], Sequence[float]], bool]]:
        """Would the controller, after a target at the first joints, run the second as planned?
        (None: joint targets are run as sent.)"""
        return None

    def with_poses(self, start: Sequence[float], points: Sequence[StreamPoint], first: int = 0,
                   memo: Optional[WireMemo] = None) -> Tuple[StreamPoint, ...]:
        """``points`` as they go out after a target at ``start``, checked as the controller will take
        them; joint targets go out as they are."""
        return tuple(points)

    def preview_stream(self, preview: Preview) -> Tuple[StreamPoint, ...]:
        """A validated move as a stream: its planned samples (a PTP's joint line with its speed
        ramps, a LIN / CIRC's Cartesian path) thinned to 0.01 deg at their planned times; the last
        point is exactly the previewed target."""
        traj = preview.trajectory
        positions = [tuple(float(v) for v in q) for q in traj.positions]
        positions[-1] = tuple(preview.joint_target)
        points = self.points([float(t) for t in traj.times], positions, math.radians(0.01),
                             MAX_CARTESIAN_TOLERANCE)
        if not points:      # already there: one target at the goal
            points = (StreamPoint(tuple(preview.joint_target), 1000, 0, 0.0, len(positions) - 1),)
            points = self.with_poses(positions[0], points)
        return points

    def step_refusal(self, prev: Sequence[float], joints: Sequence[float]) -> Tuple[Optional[ControllerPose], str]:
        """One step of a live stream (a joint command) as the controller will take it after a target
        at ``prev``: (the pose the wire carries, "") or (..., why the controller would not run
        ``joints``). Joint targets run as sent: (None, "")."""
        return None, ""

    def check_segments(self, start: Sequence[float], points: Sequence[StreamPoint]) -> None:
        """Every straight joint move of the stream (from ``start``) inside the joint limits and the
        workspace box, sampled as a PTP preview; raises (EnvelopeError, KinematicsError...) naming
        the segment; CollisionError naming the point where a chord collides."""
        self.checks.check_collision_path([tuple(start)] + [p.joints for p in points],
                                         "the stream's straight joint moves", [0.0] + [p.time for p in points])
        prev = tuple(start)
        for i, point in enumerate(points):
            try:
                self.checks.check_joint_move(prev, point.joints)
            except VrDriverError as exc:
                raise type(exc)("segment %d of %d (to planned point %d): %s"
                                % (i + 1, len(points), point.index, exc)) from None
            prev = point.joints

    def restream(self, job: MoveJob, joints: Tuple[float, ...]) -> Tuple[Tuple[StreamPoint, ...], Tuple[float, ...]]:
        """A stream job's points from ``joints`` (the arm is not where the stream was planned to
        start): the first segment is checked again and its speed set for its planned arrival (no
        faster than the limits)."""
        points = job.points
        if points[0].hold and len(points) > 1:
            # the arm is elsewhere: no hold, the first segment takes its lead from the hold's release
            points = (replace(points[1], release=points[0].release),) + tuple(points[2:])
        self.check_segments(joints, points[:1])
        first = self.with_poses(joints, points[:1])[0]     # (v3: its wire pose solved from here)
        # (a pause at the start, first.release > 0: the move begins when it ends; the arrival its
        # speed was set for, ``fed``: the hold's at the start, later than planned where the bus feeds it)
        speed = stream_speeds(joints, [tuple(joints), first.joints],
                              [first.release, first.time if first.fed is None else first.fed],
                              self.kin.limits.velocity)[1]
        return (replace(first, speed=speed),) + tuple(points[1:]), tuple(joints)


class CartesianStreams(JointStreams):
    """Streams of pose targets (v3): each point with the pose the wire carries, solved as the
    controller will by its configuration rule, ``params.controller.configuration`` (module
    docstring)."""

    def __init__(self, params: DriverParams, kinematics: Kinematics, wire: Protocol, checks: PathChecks,
                 cycle_rate: Callable[[], float]) -> None:
        super().__init__(params, kinematics, wire, checks, cycle_rate)
        #: the controller's rule for a target's joint solution
        self.rule = ConfigurationRule.parse(params.controller.configuration)
        #: the points before a target whose joints the controller may solve it nearest: the
        #: previous one (previous_target), or the ring's worth and one more (current_joints)
        self.window = 1 if self.rule is ConfigurationRule.PREVIOUS_TARGET else params.controller.ring_size + 1
        #: the widest joint step between two points: CARTESIAN_MAX_STEP over the window
        self.max_step = CARTESIAN_MAX_STEP / self.window

    def ring(self) -> int:
        """The targets the G2's ring holds (``controller/ring_size``, doc/controller_program.md §10.4
        rule 2): a new one is taken once the arm passed the one that many before."""
        return self.params.controller.ring_size

    def holds(self) -> bool:
        """v3: a stream may begin with a hold (a ring of at least 3 gathers the first targets)."""
        return True

    def memo(self) -> Optional[WireMemo]:
        """A fresh memo of wire poses and their solutions (:class:`.wire_targets.WireMemo`): one
        stream check's :meth:`reaches` and :meth:`with_poses` solve the same points' poses, the
        second time from the memo (the same answers: the same function of the same arguments)."""
        return WireMemo()

    def reaches(self, memo: Optional[WireMemo] = None) -> Optional[Callable[[Sequence[float], Sequence[float]], bool]]:
        """The controller, after a target at ``a``, solves the wire pose of ``b`` onto ``b`` within
        CONFIGURATION_TOLERANCE (:meth:`target`, the coordinate search only): where it would not --
        another elbow or wrist branch lies nearer ``a`` than ``b`` does -- the stream keeps planned
        points in between (:func:`.stream_thinning.split_long`). current_joints: ``a`` the seed (one of
        those :meth:`with_poses` then checks), and ``b`` within CARTESIAN_MAX_REACH over the window
        of ``a`` (all joints together; module docstring)."""
        reach = CARTESIAN_MAX_REACH / self.window if self.rule is ConfigurationRule.CURRENT_JOINTS else math.inf

        def reaches(a: Sequence[float], b: Sequence[float]) -> bool:
            if math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b))) > reach:
                return False
            try:
                # the coordinate search stops as soon as a pose lands within the tolerance: its
                # steps are those of the full search up to there, so the answer is the same (and
                # the plain rounding, one IK solution, answers it away from joint_5 = 0)
                return self.target(a, b, search=False, fine=CONFIGURATION_TOLERANCE, memo=memo).error \
                    <= CONFIGURATION_TOLERANCE
            except VrDriverError:
                return False
        return reaches

    def target(self, prev: Sequence[float], joints: Sequence[float], search: bool = True,
               earlier: Sequence[Sequence[float]] = (), fine: float = FINE,
               memo: Optional[WireMemo] = None) -> WireTarget:
        """The wire pose for ``joints`` after a target at ``prev`` and the controller's solution of
        it (:func:`.wire_targets.wire_target`: the plain rounding, or where that lands off the plan
        -- near joint_5 = 0 -- the one-step neighbour that lands nearest; ``search`` False: within
        FULL_SEARCH_BAND the coordinate search only, for a caller at a command's rate).
        ``earlier``: current_joints, the points before ``prev`` the arm may still be at (or
        between) when the controller takes the target: solved from each as well, the worst counts.
        ``fine``: a pose landing this near the plan ends the search. ``memo``: poses and solutions
        already computed in this stream check (:meth:`memo`). VrDriverError when the controller
        cannot solve it."""
        also = tuple(earlier) if self.rule is ConfigurationRule.CURRENT_JOINTS else ()
        with self.checks.gate:
            if search:
                return wire_target(self.kin, self.wire, joints, prev, fine=fine, also=also, memo=memo)
            return wire_target(self.kin, self.wire, joints, prev, fine=fine, full_band=0.0, also=also, memo=memo)

    def with_poses(self, start: Sequence[float], points: Sequence[StreamPoint], first: int = 0,
                   memo: Optional[WireMemo] = None) -> Tuple[StreamPoint, ...]:
        """Each point gets the pose the wire carries -- its planned pose rounded, or the one-step
        neighbour of that rounding whose solution lands nearest the plan (:meth:`target`) -- and
        is solved as the controller will solve it by its rule: the IK solution nearest the previous
        target's joints (the controller's own solution of the previous target; the arm's,
        ``start``, for the first), or -- current_joints -- nearest each of the :attr:`window`
        points before it (the controller's solutions; ``start`` the first of them: the module
        docstring says why these; after a pause of the plan only the point it holds at: the
        sequencer offers the next point once the arm is there). It must be the planned point within
        CONFIGURATION_TOLERANCE. Raises DriverError naming the point (nothing is sent)."""
        out = []
        prev = tuple(start)
        history = [prev]            # the arm's path so far: start, then each point as solved
        held: Optional[StreamPoint] = None          # the hold, while the point after it is solved
        for i, point in enumerate(points):
            where = "point %d of %d (planned point %d)" % (first + i + 1, first + len(points), point.index)
            if point.release > 0.0:
                # after a pause of the plan: offered once the arm reached the point before, at rest there
                # (StreamSequencer.record), so the G2 takes it with the arm at that point, whatever its rule
                history = [prev]
            try:
                found = self.target(prev, point.joints, earlier=history[-self.window:-1], memo=memo)
            except VrDriverError as exc:
                pose = self.wire.wire_pose(self.kin.fk_pose(point.joints))
                raise DriverError("%s: the controller cannot solve its pose %s: %s; nothing was sent"
                                  % (where, fmt_pose(pose), exc)) from None
            refusal = self.refusal(found, point.joints)
            if refusal:
                raise DriverError("%s: %s; plan a path that stays in one configuration, or use a protocol "
                                  "with joint targets; nothing was sent" % (where, refusal))
            if point.hold:
                # timed from the solution of its wire pose: near joint_5 = 0 it may take another
                # joint_4 / joint_6 split than the start's (the band rule allows it), and the point
                # after it is timed from there too -- crawled at the hold's 0.1-1 %, or undone at
                # the next segment's planned speed, that excursion took seconds
                point = replace(point, speed=hold_speed(prev, found.joints, point.fed - point.release,
                                                        self.kin.limits.velocity))
                held = point
            elif held is not None:
                point = replace(point, speed=stream_speeds(prev, [found.joints], [point.fed - held.fed],
                                                           self.kin.limits.velocity)[0])
                held = None
            out.append(replace(point, pose=found.pose))
            prev = found.joints
            history.append(prev)
            if len(history) > self.window:
                del history[0]
        return tuple(out)

    def step_refusal(self, prev: Sequence[float], joints: Sequence[float]) -> Tuple[Optional[ControllerPose], str]:
        """The wire pose of ``joints`` after a target at ``prev`` (the coordinate search only: a
        command's rate) and :meth:`refusal` of the controller's solution; VrDriverError when the
        controller cannot solve it."""
        found = self.target(prev, joints, search=False)
        return found.pose, self.refusal(found, joints)

    def refusal(self, found: WireTarget, joints: Sequence[float]) -> str:
        """"" when the controller's solution ``found`` is the planned ``joints`` within
        CONFIGURATION_TOLERANCE, else why not, in words (naming the rule)."""
        if found.error <= CONFIGURATION_TOLERANCE:
            return ""
        off = [abs(a - b) for a, b in zip(found.joints, joints)]
        worst = max(range(len(off)), key=off.__getitem__)
        if self.rule is ConfigurationRule.PREVIOUS_TARGET:
            nearest = "the solution nearest the previous target's joints"
        else:
            nearest = ("the solution nearest the arm's joints when the controller takes it, up to %d points "
                       "before it (controller/configuration current_joints, ring_size %d)"
                       % (self.window, self.window - 1))
        return ("the controller would reach its pose %s in another configuration than planned (joint_%d "
                "%.1f deg instead of %.1f deg: %s)"
                % (fmt_pose(found.pose), worst + 1, math.degrees(found.joints[worst]), math.degrees(joints[worst]),
                   nearest))


def stream_preparation(params: DriverParams, kinematics: Kinematics, wire: Protocol, checks: PathChecks,
                       cycle_rate: Callable[[], float]) -> Optional[JointStreams]:
    """The stream preparation of the family the protocol ``wire`` names (registered with it:
    :mod:`vr_driver.driver.sequencers`), fed at ``cycle_rate()`` bus cycles per second; None when it
    does not stream (v1). ProtocolError in words for a streaming protocol without one."""
    if not wire.streams:
        return None
    return wire.stream_family()(params, kinematics, wire, checks, cycle_rate)
