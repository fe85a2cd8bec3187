"""Collision-aware motion planning in joint space: OMPL (RRTConnect by default), OMPL's path
simplifier, TOPP-RA timing under the joint speed and acceleration limits. ROS-free; the planning
part of the MoveIt stand-in (issue 27).

    planner = Planner(kinematics, checker)            # a CollisionChecker, or any is_valid(q) -> bool
    plan = planner.plan(start, "home")                # a named state of the SRDF
    plan = planner.plan(start, (0.1, 0.5, ...))       # joints [rad], chain order (or {name: value})
    plan = planner.plan(start, ControllerPose(...))   # TCP in ``base``, mm / deg (the controller's)
    plan = planner.plan(start, ((x, y, z), (qx, qy, qz, qw)))  # tool0 in base_link, m / quaternion
    plan.joint_names, plan.times, plan.positions, plan.velocities, plan.accelerations
    TrajectoryGoal.of(plan)                            # the driver's goal (driver.motion.trajectories)
    plan.to_msg(JointTrajectory, JointTrajectoryPoint, rospy.Duration.from_sec)

What :meth:`Planner.plan` does, in order; every failure is a :class:`PlanningError` saying which
step and why, and nothing else happens:

1. The start: inside the joint limits and valid (a checker's contacts are named).
2. The goal: joints inside the limits and valid; a named state looked up in the SRDF's group states
   (``Kinematics.named_states``); a pose solved for *every* IK branch and full wrist turn
   (``Kinematics.ik_solutions``), those inside the limits and valid kept, the nearest to the start
   chosen ("nearest": the shortest synchronous joint move, max over joints of |dq| / speed limit);
   only when the planner finds no path to it within half the budget may it end at another of them.
3. Planning: when the straight joint-space move is valid it is the path; otherwise OMPL's planner
   (``planner``, one of :data:`PLANNERS`; :mod:`~vr_driver.kinematics.plan_search` holds OMPL's part
   of steps 3 and 4) within ``time_budget`` seconds. The planner keeps ``clearance`` more than the
   validity asks (a checker: a copy of it padded by that much more; a callable:
   ``planning_validity`` when given) except near the start and the goal, so that what the later
   steps deviate from the checked path stays valid. Given a ``roadmap`` (the paths of earlier
   plans in the same cell, :mod:`~vr_driver.kinematics.roadmap`), a route of them joined to the
   start and the goal is tried before the search, every motion of it checked as the search checks
   its motions; the simplification, the timing and the checks below are the same for it.
4. Simplification (OMPL's PathSimplifier, step counts rather than a time limit, so that a seed
   gives one result): vertex reduction, partial shortcuts, collapsing close vertices, B-spline
   smoothing of the corners; each step keeps the path valid (it checks its motions as the planner
   does).
5. Timing (:mod:`~vr_driver.kinematics.plan_timing`): a cubic spline through the path (resampled
   densely, so that it stays on the checked path), TOPP-RA time-optimal under the joint speed and
   acceleration limits times the scaling factors (less :data:`TOPP_MARGIN`), from rest to rest.
6. Sampling every ``dt`` (at most; evenly spaced over the duration): positions, velocities,
   accelerations, times. Every sample is checked again -- joint limits, speed and acceleration,
   validity -- and so is every straight chord between two samples (what the driver interpolates),
   at the motion-check resolution below.

**Motion-check resolution.** OMPL checks a motion at states at most one "longest valid segment"
apart. The planner plans in *scaled* joint coordinates x_i = w_i q_i, where w_i [m/rad] bounds
how far any point of the arm beyond joint i is from that joint's axis (the chain's link lengths
beyond it, plus :data:`LINK_ALLOWANCE` for the links' own size and a tool): a joint move dq moves no
point of the arm by more than sum_i w_i |dq_i| <= sqrt(n) |dx|. The segment length is set so that
this bound is ``max_sweep`` (default 20 mm): between two checked configurations no point of the
arm travels farther than that, so a collision is missed only where less than ``max_sweep`` / 2 of
the arm crosses less than ``max_sweep`` of an obstacle -- the checker's padding covers it. For the
VR-006L (w = 2.09, 1.64, 1.08, 0.95, 0.39, 0.39 m/rad) OMPL's own resolution checks a move of joint
1 alone every 0.22 deg, of joint 6 alone every 1.2 deg; RRTConnect (the default) and the
simplification after it are given a motion validator that subdivides each motion by the sum itself
(:mod:`~vr_driver.kinematics.plan_search`, ``SWEEP_VALIDATED``): the same bound with up to sqrt(n)
fewer checks, every 0.55 and 2.9 deg, as the check of the result. The scaled space also
makes the planner's distance (which tree node is nearest) a measure of how far the arm moves.

``time_budget`` bounds the planner's search (OMPL's solve); the goal's IK, the simplification, the
timing and the checks come on top (milliseconds to a few tens of them: bench/planning.py).

Not thread-safe: a Planner keeps a copy of its checker and the plan it is making; one per thread.

Determinism: OMPL's random numbers come from one process-wide seed generator; :meth:`Planner.plan`
reseeds it with ``seed`` (when given) before it makes its planner and simplifier, so one seed and
one problem give one path (as long as the planner finishes within its budget: a planner cut off by
the clock stops where the clock stops it).

The optional libraries (OMPL, TOPP-RA) are imported when a Planner is made, through
:mod:`vr_driver.kinematics.deps`: a machine without them gets :class:`~vr_driver.errors.MissingDependency`
naming the package and scripts/setup, and ``import vr_driver.kinematics.planner`` itself always works.
"""
from __future__ import annotations

import importlib
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import KinematicsError, MissingDependency, MotionError, PoseError
from ..params import PLANNERS
from ..poses import ControllerPose, ros_to_matrix
from . import deps
from .plan_search import SWEEP_VALIDATED, BatchValidity, OmplSearch, SweepZone, first_invalid
from .plan_timing import TIMING_ATTEMPTS, TOPP_MARGIN, PathTiming, TimingError
from .roadmap import Roadmap

__all__ = ["PlanningError", "PlannedTrajectory", "Planner", "SearchTest", "BatchValidity", "first_invalid", "PLANNERS", "DEFAULT_PLANNER", "DEFAULT_MAX_SWEEP",
           "DEFAULT_DT", "DEFAULT_CLEARANCE", "ESCAPE_SWEEP", "NEAREST_SHARE", "LINK_ALLOWANCE", "TOPP_MARGIN",
           "joint_weights"]

DEFAULT_PLANNER = "RRTConnect"
#: [m] no point of the arm moves farther than this between two checked configurations
DEFAULT_MAX_SWEEP = 0.02
#: [s] the largest spacing of the sampled trajectory (the rate MoveIt-timed goals usually have)
DEFAULT_DT = 0.05
#: [m] the planner keeps this much farther from everything than the validity asks (a checker's
#: padding + this; module text): what the motion checks may miss between two checked
#: configurations (half of ``max_sweep``) and what the timing spline and the chords between the
#: samples deviate from the checked path stay inside it, so the check of the result passes
DEFAULT_CLEARANCE = 0.01
#: the share of the budget spent on the nearest IK solution of a pose before any other is allowed
NEAREST_SHARE = 0.5
#: [m] near the start and the goal (this far by the sweep bound, sum_i w_i |dq_i|) the clearance is
#: not asked for, only the validity: a random cell configuration is often closer than the clearance
#: to something, and must be left or reached through that. The bound overstates the real motion
#: (joint 1 alone: 0.8 m is 22 deg); on bench/planning.py 0.2 m solved 96 to 99 % of the queries
#: (narrow passages the clearance made near the goals), 0.8 m 100 % of 4 x 100, equally fast.
#: The result is checked with the validity itself everywhere.
ESCAPE_SWEEP = 0.8
#: [m] added to each joint's lever arm: the links' own size (their collision shapes stand out of
#: the joint axes) and a tool on the flange
LINK_ALLOWANCE = 0.3
_FEATURE = "collision-aware planning (vr_driver.kinematics.planner)"


class PlanningError(MotionError):
    """No trajectory: the start or the goal is invalid, the goal is unreachable or in collision,
    the planner found no path within its budget, or the timed result failed its checks. ``step`` names
    the step (start, goal, plan, time, check); ``contacts`` holds a checker's contacts when
    there were some."""

    def __init__(self, step: str, message: str, contacts: Sequence[Any] = ()) -> None:
        super().__init__(message)
        self.step = step
        self.contacts = tuple(contacts)


@dataclass(frozen=True)
class PlannedTrajectory:
    """A timed joint trajectory, from rest to rest, as trajectory_msgs/JointTrajectory carries one
    (radians, rad/s, rad/s^2, seconds from the start); ``path`` is the geometric path it follows
    (after simplification), ``timings`` how long each step took [s]."""

    joint_names: Tuple[str, ...]
    times: Tuple[float, ...]
    positions: Tuple[Tuple[float, ...], ...]
    velocities: Tuple[Tuple[float, ...], ...]
    accelerations: Tuple[Tuple[float, ...], ...]
    path: Tuple[Tuple[float, ...], ...]
    planner: str
    timings: Dict[str, float] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return self.times[-1]

    @property
    def start(self) -> Tuple[float, ...]:
        return self.positions[0]

    @property
    def goal(self) -> Tuple[float, ...]:
        return self.positions[-1]

    def then(self, other: "PlannedTrajectory", hold: float) -> "PlannedTrajectory":
        """This trajectory, at rest at its end for ``hold`` seconds (a pause: the end's sample again,
        ``hold`` later), then ``other``, which must start where this one ends."""
        if not hold > 0.0:
            raise ValueError("hold must be > 0 s, got %r" % (hold,))
        if max(abs(a - b) for a, b in zip(self.goal, other.start)) > 1e-9:
            raise ValueError("the second trajectory starts at %s, not where the first ends, %s"
                             % (_fmt(other.start), _fmt(self.goal)))
        t0 = self.duration + hold
        timings = dict(self.timings)
        for key, value in other.timings.items():
            timings[key] = timings.get(key, 0.0) + value
        return PlannedTrajectory(self.joint_names, self.times + tuple(t0 + t for t in other.times),
                                 self.positions + other.positions, self.velocities + other.velocities,
                                 self.accelerations + other.accelerations, self.path + other.path[1:],
                                 self.planner, timings)

    def to_msg(self, trajectory_type: Callable[..., Any], point_type: Callable[..., Any],
               duration: Callable[[float], Any]) -> Any:
        """A trajectory_msgs/JointTrajectory, the message classes and the Duration maker given by
        the caller (this module imports no ROS): ``to_msg(JointTrajectory, JointTrajectoryPoint,
        rospy.Duration.from_sec)``. The header is left to the caller (stamp 0: start now)."""
        msg = trajectory_type()
        msg.joint_names = list(self.joint_names)
        msg.points = [point_type(positions=list(p), velocities=list(v), accelerations=list(a),
                                 time_from_start=duration(t))
                      for t, p, v, a in zip(self.times, self.positions, self.velocities, self.accelerations)]
        return msg


def joint_weights(kinematics: Any, allowance: float = LINK_ALLOWANCE) -> Tuple[float, ...]:
    """Per movable joint [m/rad]: a bound on the distance from the joint's axis to any point of the
    arm beyond it -- the lengths of the chain's joint offsets after it (whatever the pose: the
    triangle inequality) plus ``allowance``. A rotation dq of the joint moves no such point farther
    than weight * |dq|."""
    joints = kinematics.chain_joints
    out = []
    for k, j in enumerate(joints):
        if not j.movable:
            continue
        beyond = sum(float(np.linalg.norm(o.origin[:3, 3])) for o in joints[k + 1:])
        out.append(beyond + allowance if j.type != "prismatic" else 1.0)
    return tuple(out)


def _checker_validity(checker: Any) -> Callable[[Sequence[float]], bool]:
    """not ``checker.in_collision(q)``, with the checker's batch test (``first_invalid`` or
    ``first_collision``) where it has one."""
    in_collision = checker.in_collision
    batch = getattr(checker, "first_invalid", None) or getattr(checker, "first_collision", None)
    if batch is None:
        return lambda q: not in_collision(q)
    return BatchValidity(lambda q: not in_collision(q), batch)


def chord_states(positions: Sequence[Sequence[float]], weights: Sequence[float], max_sweep: float
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """(the states motion_valid checks on each straight chord between two of ``positions``, chord
    after chord, as rows; the chord of each row, 0 for the first) -- ``max_sweep`` apart by the
    sweep bound (``weights``)."""
    pos = np.asarray(positions, dtype=float)
    steps = np.array([max(1, int(math.ceil(sum(w * abs(x - y) for w, x, y in zip(weights, a, b)) / max_sweep)))
                      for a, b in zip(positions, positions[1:])])
    chord = np.repeat(np.arange(len(steps)), steps)
    f = (np.arange(len(chord)) - np.repeat(np.cumsum(steps) - steps, steps) + 1) / steps[chord]
    return pos[chord] + f[:, None] * (pos[1:] - pos[:-1])[chord], chord


def _validity(validity: Any) -> Tuple[Callable[[Sequence[float]], bool], Optional[Callable[[Sequence[float]], list]]]:
    """(is_valid, contacts or None) of a checker (``in_collision`` / ``contacts``) or a callable."""
    if validity is None:
        return (lambda q: True), None
    if hasattr(validity, "in_collision"):
        return _checker_validity(validity), getattr(validity, "contacts", None)
    if callable(validity):
        return validity, None
    raise TypeError("validity must be a collision checker (in_collision(q)) or a callable is_valid(q) -> bool, "
                    "got %r" % (validity,))


def _require(module: str) -> Any:
    """The module ``module`` of an optional package, or MissingDependency naming the package."""
    top = module.split(".")[0]
    deps.require(top, _FEATURE)
    try:
        return importlib.import_module(module)
    except ImportError as exc:  # the package is there but a part of it does not load
        raise MissingDependency(deps.PACKAGES.get(top, top), module, _FEATURE,
                                "%s: %s" % (type(exc).__name__, exc)) from exc


def _fmt(q: Sequence[float]) -> str:
    return "(%s) deg" % ", ".join("%.1f" % math.degrees(v) for v in q)


def _number(value: Any, name: str, lo: float, hi: float = math.inf, lo_open: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value) \
            or not ((lo < value) if lo_open else (lo <= value)) or not value <= hi:
        raise PoseError("%s must be a number in %s%g, %g], got %r" % (name, "(" if lo_open else "[", lo, hi, value))
    return float(value)


def pose_target(kin: Any, goal: Any) -> Optional[np.ndarray]:
    """The tip pose (4x4 in the chain root of ``kin``) of a pose goal -- a ControllerPose, a 4x4
    matrix or ((x, y, z) [m], (qx, qy, qz, qw)) -- or None for a joint goal. PlanningError for a
    malformed pose."""
    if isinstance(goal, ControllerPose):
        return kin.conventions.controller_to_tip(goal)
    if isinstance(goal, np.ndarray) and goal.shape == (4, 4):
        return goal.astype(float)
    if isinstance(goal, (tuple, list)) and len(goal) == 2 and all(isinstance(g, (tuple, list, np.ndarray))
                                                                   for g in goal):
        position, quaternion = goal
        if len(position) != 3 or len(quaternion) != 4:
            raise PlanningError("goal", "a pose goal is ((x, y, z) [m], (qx, qy, qz, qw)), got %r" % (goal,))
        try:
            return ros_to_matrix(position, quaternion)
        except (PoseError, ValueError) as exc:
            raise PlanningError("goal", "goal pose: %s" % exc) from exc
    return None


class SearchTest:
    """The planner's test of a configuration in its search (:attr:`Planner.planning_valid`): valid
    with the clearance (``strict``) -- or, within ``ESCAPE_SWEEP`` of the start or a goal of the
    plan being made (``ends``), valid (``is_valid``: an arm that starts or ends closer than the
    clearance to something must be able to leave or reach that place); and, while a leg is planned,
    that leg's own test (``leg``, see ``Planner``'s ``leg_validity``) above both."""

    def __init__(self, is_valid: Callable[[Sequence[float]], bool], strict: Callable[[Sequence[float]], bool],
                 weights: Sequence[float]) -> None:
        self.is_valid, self.strict, self.weights = is_valid, strict, tuple(weights)
        self.ends = SweepZone((), ())                                   # the plan's start and goals
        self.leg: Optional[Callable[[Sequence[float]], bool]] = None    # the leg being planned's test

    def sweep(self, a: Sequence[float], b: Sequence[float]) -> float:
        return sum(w * abs(x - y) for w, x, y in zip(self.weights, a, b))

    def valid(self, q: Sequence[float]) -> bool:
        if self.leg is not None and not self.leg(q):
            return False
        return bool(self.strict(q)) or self.escapes(q)

    def escapes(self, q: Sequence[float]) -> bool:
        return self.ends.near(q, ESCAPE_SWEEP, self.sweep) and bool(self.is_valid(q))

    def first_invalid(self, qs: Sequence[Sequence[float]]) -> Optional[int]:
        """:meth:`valid` of a batch (BatchValidity.first_invalid): the clearance's test in one call
        up to its first refusal, that row in the escape zone tested again alone."""
        qs = np.asarray(qs, dtype=float)
        cut = first_invalid(self.leg, qs) if self.leg is not None else None
        if cut is not None:
            qs = qs[:cut]                 # (the leg's own test refuses that row: none after it counts)
        k = 0
        while k < len(qs):
            f = first_invalid(self.strict, qs[k:])
            if f is None:
                break
            k += f
            if not self.escapes(tuple(float(v) for v in qs[k])):
                return k
            k += 1
        return cut


class Planner:
    """Plans collision-free, timed joint trajectories for one chain (see the module text).

    ``kinematics``: a :class:`~vr_driver.kinematics.solver.Kinematics`; ``validity``: a
    CollisionChecker (``in_collision(q)``, ``contacts(q)``) or any callable ``is_valid(q) -> bool``
    (None: everything within the limits is valid); ``limits``: a JointLimits (default: the
    kinematics'; ``velocity`` and ``acceleration`` are the speed and acceleration limits);
    ``planner``: one of :data:`PLANNERS`; ``time_budget`` [s] of the planner; ``seed``: an int
    for reproducible plans; ``velocity_scaling`` / ``acceleration_scaling`` in (0, 1];
    ``dt`` [s] the largest sample spacing; ``max_sweep`` [m] the motion-check resolution;
    ``goal_preference(start, q)``: a rank (lower first) that orders a pose goal's IK solutions
    before their nearness -- e.g. the driver's: a controller that solves poses itself cannot be
    relied on to change the elbow branch, so the solutions on the start's branch come first;
    ``leg_validity(a, b)``: what every state of a leg from ``a`` to ``b`` (the start, the ``via``
    waypoints, the goal) must also pass in the search, its escape zones included -- an
    ``is_valid(q)`` (a BatchValidity for batches) or None (nothing more) -- e.g. the driver's: a
    leg between two configurations on one side of the stretched elbow stays on that side (the
    controller does not follow a plan across it elsewhere than where it turns joint_3 alone)."""

    def __init__(self, kinematics: Any, validity: Any = None, limits: Any = None,
                 planner: str = DEFAULT_PLANNER, time_budget: float = 1.0, seed: Optional[int] = None,
                 velocity_scaling: float = 1.0, acceleration_scaling: float = 1.0, dt: float = DEFAULT_DT,
                 max_sweep: float = DEFAULT_MAX_SWEEP, clearance: float = DEFAULT_CLEARANCE,
                 planning_validity: Optional[Callable[[Sequence[float]], bool]] = None,
                 goal_preference: Optional[Callable[[Sequence[float], Sequence[float]], int]] = None,
                 roadmap: Optional[Roadmap] = None,
                 leg_validity: Optional[Callable[[Sequence[float], Sequence[float]], Any]] = None) -> None:
        if planner not in PLANNERS:
            raise PlanningError("plan", "unknown planner %r: the planners are %s" % (planner, ", ".join(PLANNERS)))
        self.kin = kinematics
        self.limits = limits if limits is not None else kinematics.limits
        self.names = tuple(self.limits.names)
        self.dof = len(self.names)
        self.planner_name = planner
        self.time_budget = _number(time_budget, "time_budget [s]", 0.0)
        self.seed = seed
        self.velocity_scaling = _number(velocity_scaling, "velocity_scaling", 0.0, 1.0)
        self.acceleration_scaling = _number(acceleration_scaling, "acceleration_scaling", 0.0, 1.0)
        self.dt = _number(dt, "dt [s]", 0.0)
        self.max_sweep = _number(max_sweep, "max_sweep [m]", 0.0)
        self.is_valid, self._contacts = _validity(validity)
        self.clearance = _number(clearance, "clearance [m]", 0.0, lo_open=False)
        strict = self._strict_validity(validity, planning_validity)
        if goal_preference is not None and not callable(goal_preference):
            raise TypeError("goal_preference must be a callable rank(start, q) -> int, got %r" % (goal_preference,))
        self._prefer = goal_preference
        #: the paths of earlier plans (a Roadmap, kept by the caller) tried before the search, or None
        self.roadmap = roadmap
        if leg_validity is not None and not callable(leg_validity):
            raise TypeError("leg_validity must be a callable (a, b) -> is_valid or None, got %r" % (leg_validity,))
        self._leg_validity = leg_validity
        for what, values in (("velocity", self.limits.velocity), ("acceleration", self.limits.acceleration)):
            if len(values) != self.dof or not all(math.isfinite(v) and v > 0 for v in values):
                raise PlanningError("time", "every joint needs a finite %s limit > 0 for the timing, got %r"
                                    % (what, tuple(values)))
        self.lower = tuple(self.limits.lower)
        self.upper = tuple(self.limits.upper)
        for n, lo, hi in zip(self.names, self.lower, self.upper):
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise PlanningError("plan", "joint %s needs finite position limits to plan in, got [%r, %r]"
                                    % (n, lo, hi))
        self.weights = joint_weights(kinematics)
        self.search_test = SearchTest(self.is_valid, strict, self.weights)
        #: the planner's test of a configuration (and of a batch: BatchValidity), see SearchTest
        self.planning_valid = BatchValidity(self.search_test.valid, self.search_test.first_invalid)
        ob, og, ou = (_require(m) for m in ("ompl.base", "ompl.geometric", "ompl.util"))
        ou.setLogLevel(ou.LOG_WARN)
        self._ompl = (ob, og, ou)
        toppra = _require("toppra")
        _require("toppra.algorithm")
        _require("toppra.constraint")
        self._timing = PathTiming(toppra, self.limits.velocity, self.limits.acceleration)

    # --------------------------------------------------------------------------------- checks
    def _strict_validity(self, validity: Any, given: Optional[Callable]) -> Callable[[Sequence[float]], bool]:
        """What the planner plans with: ``given``; else, for a checker that can be copied and padded,
        a copy padded by ``clearance`` more; else the validity itself."""
        if given is not None:
            if not callable(given):
                raise TypeError("planning_validity must be a callable is_valid(q) -> bool, got %r" % (given,))
            return given
        if self.clearance > 0.0 and all(hasattr(validity, a) for a in ("copy", "set_padding", "padding")):
            strict = validity.copy()
            strict.set_padding(validity.padding + self.clearance)
            return _checker_validity(strict)
        return self.is_valid

    def _why_invalid(self, q: Sequence[float]) -> Tuple[str, tuple]:
        if self._contacts is None:
            return "", ()
        try:
            contacts = tuple(self._contacts(q))
        except Exception:  # the naming is an aid; the verdict was is_valid's
            return "", ()
        return (": " + "; ".join(str(c) for c in contacts)) if contacts else "", contacts

    def motion_valid(self, a: Sequence[float], b: Sequence[float],
                     is_valid: Optional[Callable[[Sequence[float]], bool]] = None) -> Optional[Tuple[float, ...]]:
        """None when the straight joint move a -> b is valid (``is_valid``, default the validity) at
        the check resolution (``a`` is taken as checked), else the first invalid configuration on it."""
        is_valid = is_valid or self.is_valid
        n = max(1, int(math.ceil(self.search_test.sweep(a, b) / self.max_sweep)))
        a = np.asarray(a, dtype=float)
        qs = a + (np.arange(1, n + 1) / n)[:, None] * (np.asarray(b, dtype=float) - a)
        bad = first_invalid(is_valid, qs)
        return None if bad is None else tuple(float(v) for v in qs[bad])

    def _joints(self, q: Any, what: str) -> Tuple[float, ...]:
        try:
            q = self.kin.joint_vector(q)
        except PoseError as exc:
            raise PlanningError(what, "%s: %s" % (what, exc)) from exc
        bad = ["%s = %.4f outside [%.4f, %.4f]" % (n, v, lo, hi)
               for n, v, lo, hi in zip(self.names, q, self.lower, self.upper) if not lo - 1e-9 <= v <= hi + 1e-9]
        if bad:
            raise PlanningError(what, "%s %s is outside the joint limits: %s" % (what, _fmt(q), "; ".join(bad)))
        return tuple(min(max(v, lo), hi) for v, lo, hi in zip(q, self.lower, self.upper))

    def _nearness(self, a: Sequence[float], b: Sequence[float]) -> Tuple[float, float]:
        return (max(abs(x - y) / v for x, y, v in zip(a, b, self.limits.velocity)),
                sum((x - y) ** 2 for x, y in zip(a, b)))

    # ------------------------------------------------------------------------------------ goals
    def goal_candidates(self, start: Sequence[float], goal: Any) -> List[Tuple[float, ...]]:
        """The goal's joint configurations inside the limits, nearest to ``start`` first -- the
        ``goal_preference`` rank before the nearness, when given -- (one for a joint or named goal;
        every IK branch of a pose). PlanningError when there is none."""
        if isinstance(goal, str):
            states = getattr(self.kin, "named_states", {}) or {}
            if goal not in states:
                raise PlanningError("goal", "unknown named state %r: the SRDF's states are %s"
                                    % (goal, ", ".join(sorted(states)) or "(none)"))
            return [self._joints(states[goal], "goal state %r" % goal)]
        target = pose_target(self.kin, goal)
        if target is None:
            return [self._joints(goal, "goal")]
        try:
            sols = self.kin.ik_solutions(target, seed=start)
        except KinematicsError as exc:
            raise PlanningError("goal", "goal pose unreachable: %s" % exc) from exc
        sols = [tuple(q) for q in sols if all(lo - 1e-9 <= v <= hi + 1e-9
                                              for v, lo, hi in zip(q, self.lower, self.upper))]
        if not sols:
            raise PlanningError("goal", "goal pose unreachable within the planner's joint limits")
        if self._prefer is None:
            sols.sort(key=lambda q: self._nearness(start, q))
        else:
            sols.sort(key=lambda q: (self._prefer(start, q), self._nearness(start, q)))
        return sols

    # ------------------------------------------------------------------------------------ plan
    def plan(self, start: Any, goal: Any, velocity_scaling: Optional[float] = None,
             acceleration_scaling: Optional[float] = None, time_budget: Optional[float] = None,
             seed: Optional[int] = None, via: Sequence[Sequence[float]] = ()) -> PlannedTrajectory:
        """A collision-free timed trajectory from the joints ``start`` to ``goal`` (joints, a named
        state, a ControllerPose, ((x, y, z), (qx, qy, qz, qw)) of tool0 in base_link, or a 4x4 tip
        pose). Per-call overrides of the constructor's scaling, budget and seed. ``via``: joints the
        path passes through, in order (each leg that is not straight planned in an equal share of what
        the legs before left of the budget; the timing goes through them as through any point of the path). PlanningError when there is none (see
        the module text)."""
        t0 = time.perf_counter()
        vs = self.velocity_scaling if velocity_scaling is None else _number(velocity_scaling, "velocity_scaling",
                                                                            0.0, 1.0)
        acs = self.acceleration_scaling if acceleration_scaling is None else _number(
            acceleration_scaling, "acceleration_scaling", 0.0, 1.0)
        budget = self.time_budget if time_budget is None else _number(time_budget, "time_budget [s]", 0.0)
        seed = self.seed if seed is None else seed
        q0 = self._joints(start, "start")
        if not self.is_valid(q0):
            why, contacts = self._why_invalid(q0)
            raise PlanningError("start", "start %s is in collision%s" % (_fmt(q0), why), contacts)
        candidates = self.goal_candidates(q0, goal)
        valid = [q for q in candidates if self.is_valid(q)]
        if not valid:
            why, contacts = self._why_invalid(candidates[0])
            what = ("goal %s is in collision" % _fmt(candidates[0]) if len(candidates) == 1 else
                    "all %d joint solutions of the goal pose are in collision; the nearest, %s"
                    % (len(candidates), _fmt(candidates[0])))
            raise PlanningError("goal", what + why, contacts)
        stops = [self._joints(w, "waypoint %d" % (k + 1)) for k, w in enumerate(via)]
        for k, w in enumerate(stops):
            if not self.is_valid(w):
                why, contacts = self._why_invalid(w)
                raise PlanningError("plan", "waypoint %d %s is in collision%s" % (k + 1, _fmt(w), why), contacts)
        timings = {"goal": time.perf_counter() - t0}
        path = [q0]
        legs = [[w] for w in stops] + [valid]
        # the legs whose straight move is not free: the budget is theirs (a straight leg takes next
        # to nothing: the elbow crossing's middle one always, its first or last often)
        ends = [q0] + stops
        searching = [self.leg_searches(a, targets) for a, targets in zip(ends, legs)] if stops else [True]
        searched = 0.0                   # [s] the legs' searches so far
        try:
            for k, targets in enumerate(legs):
                leg: Dict[str, float] = {}
                leg_test = self.search_test.leg = self._leg_of(path[-1], targets[0])
                # (a pose's other solutions that the leg's own test refuses are not its goals)
                targets = [targets[0]] + [g for g in targets[1:] if leg_test is None or leg_test(g)]
                # an equal share of what the legs before left of the budget among the legs left to
                # search; never more in all
                share = max(budget - searched, 0.0) / max(1, sum(searching[k:]))
                path += self._geometric_path(path[-1], targets, share, None if seed is None else seed + k, leg)[1:]
                searched += leg.get("plan", 0.0)
                for key, value in leg.items():
                    timings[key] = timings.get(key, 0.0) + value
        finally:
            self.search_test.leg = None
        t = time.perf_counter()
        timings["time"] = timings["check"] = 0.0
        for attempt, (step, dt) in enumerate(TIMING_ATTEMPTS):
            try:
                result = self._timing.time(path, vs, acs, step, self.dt * dt)
            except TimingError as exc:
                raise PlanningError("time", str(exc)) from exc
            timings["time"] += time.perf_counter() - t
            t = time.perf_counter()
            try:
                self._check(*result)
            except PlanningError:
                if attempt == len(TIMING_ATTEMPTS) - 1:
                    raise
                continue
            finally:
                timings["check"] += time.perf_counter() - t
                t = time.perf_counter()
            break
        timings["total"] = time.perf_counter() - t0
        times, pos, vel, acc = result
        return PlannedTrajectory(self.names, times, pos, vel, acc, tuple(path), self.planner_name, timings)

    # ------------------------------------------------------------------- the path (OMPL's search)
    def _leg_of(self, a: Sequence[float], b: Sequence[float]) -> Optional[Callable[[Sequence[float]], bool]]:
        """The leg's own test from ``a`` to ``b`` (``leg_validity``), or None."""
        return None if self._leg_validity is None else self._leg_validity(tuple(a), tuple(b))

    def leg_searches(self, q0: Tuple[float, ...], goals: Sequence[Tuple[float, ...]]) -> bool:
        """Whether a leg from ``q0`` to ``goals`` needs a search: its straight move to the first
        is not free by the planner's test with the leg's own escape zone (as
        :meth:`_geometric_path` checks it; the zone of another leg or plan would refuse a straight
        crossing of a margin near this leg's ends and give the leg a share of the budget it does
        not use)."""
        self.search_test.ends = SweepZone((tuple(q0),) + tuple(tuple(g) for g in goals), self.weights)
        self.search_test.leg = self._leg_of(q0, goals[0])
        try:
            return self.motion_valid(q0, goals[0], self.planning_valid) is not None
        finally:
            self.search_test.leg = None

    def _geometric_path(self, q0, goals: Sequence[Tuple[float, ...]], budget: float, seed: Optional[int],
                        timings: Dict[str, float]) -> List[Tuple[float, ...]]:
        """A valid path from ``q0`` to the first of ``goals`` (the nearest) -- or, when there are
        several (the IK solutions of a pose) and the planner finds none to the first within
        ``NEAREST_SHARE`` of the budget, to any of them in the rest of it: the nearest solution may
        lie in a part of the free space the start is not in (e.g. the wrist folded past its own
        housing), as MoveIt, too, plans to any of a pose's IK solutions. (Not the first again: OMPL's
        RRTConnect takes a further goal only when its goal tree has grown, which it cannot where the
        first goal is walled in.)"""
        t = time.perf_counter()
        goals = [tuple(g) for g in goals]
        q1 = goals[0]
        self.search_test.ends = SweepZone((tuple(q0),) + tuple(goals), self.weights)
        if self.motion_valid(q0, q1, self.planning_valid) is None:
            timings["plan"] = time.perf_counter() - t
            timings["simplify"] = 0.0
            return [q0, q1]
        search = OmplSearch(self._ompl, self.weights, self.lower, self.upper, self.max_sweep,
                            self.planning_valid, seed, sweep_motions=self.planner_name in SWEEP_VALIDATED)
        stages = [(goals[:1], budget)] if len(goals) == 1 else [(goals[:1], budget * NEAREST_SHARE), (goals[1:], None)]
        path = None
        if self.roadmap is not None:
            # the earlier plans' paths first: a route of them, every motion checked now
            route = self.roadmap.route(q0, q1, lambda a, b: self.motion_valid(a, b, self.planning_valid) is None)
            if route is not None:
                path = search.path_of(route)
                timings["roadmap"] = timings.get("roadmap", 0.0) + 1.0
                stages = []
        for n_stage, (targets, share) in enumerate(stages):
            if n_stage:
                # the others: a straight move first (nearest first); then the planner to any of them
                for g in targets:
                    if self.motion_valid(q0, g, self.planning_valid) is None:
                        timings["plan"] = time.perf_counter() - t
                        timings["simplify"] = 0.0
                        return [q0, g]
            # a stage with a share of the budget: that long; the last of two: what is left of it
            path = (search.solve(self.planner_name, q0, targets, share) if share is not None else
                    search.solve(self.planner_name, q0, targets, budget, since=t))
            if path is not None:
                break
            if len(stages) > 1 and not n_stage:
                timings["nearest_given_up"] = timings.get("nearest_given_up", 0.0) + 1.0
        timings["plan"] = time.perf_counter() - t
        if path is None:
            raise PlanningError("plan", "%s found no path within %.3g s (%s) from %s to %s%s"
                                % (self.planner_name, budget, search.status, _fmt(q0), _fmt(q1),
                                   " nor to any other of its %d valid joint solutions" % (len(goals) - 1)
                                   if len(goals) > 1 else ""))
        t = time.perf_counter()
        out = search.simplified(path)
        timings["simplify"] = time.perf_counter() - t
        reached = min(goals, key=lambda g: sum((a - b) ** 2 for a, b in zip(g, out[-1])))
        out[0], out[-1] = tuple(q0), reached
        # the simplifier keeps the path valid; the check here is the planner's own guarantee
        for a, b in zip(out, out[1:]):
            bad = self.motion_valid(a, b)
            if bad is not None:
                why, contacts = self._why_invalid(bad)
                raise PlanningError("plan", "the simplified path passes an invalid configuration %s%s"
                                    % (_fmt(bad), why), contacts)
        if self.roadmap is not None:
            self.roadmap.add(out)
        return out

    # ---------------------------------------------------------------------- the result's check
    def chords_valid(self, positions: Sequence[Sequence[float]]) -> Optional[Tuple[int, Tuple[float, ...]]]:
        """None when every straight chord between two of ``positions`` is valid at the check
        resolution (the first position taken as checked), else (k, the first invalid
        configuration) of the first chord k - 1 -> k that has one: :meth:`motion_valid` of each chord
        in turn, its states all in one batch of the validity."""
        if len(positions) < 2:
            return None
        qs, chord = chord_states(positions, self.weights, self.max_sweep)
        first = first_invalid(self.is_valid, qs)
        return None if first is None else (int(chord[first]) + 1, tuple(float(v) for v in qs[first]))

    def _check(self, times, positions, velocities, accelerations) -> None:
        """Every sample inside the joint, speed and acceleration limits (less nothing: the margin
        of the timing is the slack) and valid, every chord between two samples valid and within
        the speed limits (what the driver's segment check asks)."""
        vlim, alim = self.limits.velocity, self.limits.acceleration
        for k, (t, q, v, a) in enumerate(zip(times, positions, velocities, accelerations)):
            for i, name in enumerate(self.names):
                if not self.lower[i] - 1e-9 <= q[i] <= self.upper[i] + 1e-9:
                    raise PlanningError("check", "sample %d (t = %.3f s): %s = %.4f rad is outside its limits "
                                        "[%.4f, %.4f]" % (k, t, name, q[i], self.lower[i], self.upper[i]))
                if abs(v[i]) > vlim[i] * (1 + 1e-6) or abs(a[i]) > alim[i] * (1 + 1e-6):
                    raise PlanningError("check", "sample %d (t = %.3f s): %s at %.3f rad/s, %.3f rad/s^2 exceeds its "
                                        "limits %.3f rad/s, %.3f rad/s^2" % (k, t, name, v[i], a[i], vlim[i], alim[i]))
            if k and any(abs(x - y) > (t - times[k - 1]) * vl * (1 + 1e-9)
                         for x, y, vl in zip(q, positions[k - 1], vlim)):
                raise PlanningError("check", "segment %d -> %d needs more than the speed limits" % (k - 1, k))
        if not self.is_valid(positions[0]):
            why, contacts = self._why_invalid(positions[0])
            raise PlanningError("check", "sample 0 is invalid%s" % why, contacts)
        found = self.chords_valid(positions)
        if found is not None:
            k, bad = found
            why, contacts = self._why_invalid(bad)
            raise PlanningError("check", "the timed trajectory between samples %d and %d (t = %.3f s) passes "
                                "an invalid configuration %s%s" % (k - 1, k, times[k], _fmt(bad), why), contacts)
