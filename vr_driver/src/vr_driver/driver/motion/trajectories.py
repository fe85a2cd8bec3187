"""Joint trajectories from a planner: validation with control_msgs' error codes, the speed each
segment needs to keep the planned timing, and thinning for the v1 program. ROS-free, no I/O.

This is the part of ``joint_trajectory_action`` (FollowJointTrajectory) and ``joint_path_command``
that needs no ROS and no bus: the ROS adapter converts the goal into a :class:`TrajectoryGoal`,
:func:`validate` checks it (refusing with :class:`TrajectoryError` whose ``code`` is the
control_msgs result code), :func:`segment_speeds` says how fast each segment must be, and
:func:`thin` picks the fewest points a stop-at-every-point program (v1) must visit so that the
path stays within the path tolerance.

Tolerances a goal leaves empty (0) are the protocol's defaults. On the Cartesian protocols (v1,
v3), given the arm's kinematics (``validate(..., resolution=WireResolution.of(kin, wire))``), they
are per configuration: at each planned point, the protocol's rule
(``goal_tolerance_for`` / ``path_tolerance_for``) of the joint error the wire's resolution allows
there (:mod:`vr_driver.driver.joints.resolution`); within the wrist band (joint_5 near 0) joint_4 and
joint_6 are judged by their sum (:class:`ConfigurationTolerances`). :func:`path_check` measures a
sample against the planned path with them; :func:`thin` keeps the stop points that leave every
straight joint move between them -- with the wire's error at its two ends and at the sample --
inside them.

Units: radians, seconds; joint order is the controller's (``controller_joint_names``) after
:func:`validate`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ...errors import VrDriverError

__all__ = [
    "SUCCESSFUL", "INVALID_GOAL", "INVALID_JOINTS", "OLD_HEADER_TIMESTAMP",
    "PATH_TOLERANCE_VIOLATED", "GOAL_TOLERANCE_VIOLATED",
    "TrajectoryError", "TrajectoryGoal", "ValidTrajectory", "ConfigurationTolerances", "PathCheck",
    "validate", "segment_speeds", "thin", "path_deviation", "path_check", "split_keep",
    "DEFAULT_PATH_TOLERANCE", "V1_WIRE_ERROR", "THIN_SHARE",
]

# control_msgs/FollowJointTrajectoryResult error codes
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
OLD_HEADER_TIMESTAMP = -3
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5

#: the path and goal tolerance [rad] :func:`validate` uses for a joint the goal leaves at 0 when the
#: caller names no defaults. A caller that knows the protocol passes its defaults instead
#: (:attr:`vr_driver.protocol.base.Protocol.default_path_tolerance` / ``default_goal_tolerance``:
#: what the wire can reach; the action server does): 1 deg is tighter than v1's targets can land.
DEFAULT_PATH_TOLERANCE = math.radians(1.0)
#: how far a joint may land from a joint point sent through v1 (whole mm / degree Cartesian targets,
#: solved again by the controller's IK): the thinning keeps this much of the tolerance in reserve
V1_WIRE_ERROR = math.radians(1.5)
#: per configuration (:class:`ConfigurationTolerances`): a straight joint move between two stop
#: points, with the wire's error at its ends and at the sample, may use this share of the path
#: tolerance at each dropped point (the rest: the linearisation of the wire's error, the reading
#: of the joints between two reports)
THIN_SHARE = 0.9


class TrajectoryError(VrDriverError):
    """A trajectory refused; ``code`` is the control_msgs error code, the message says why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class TrajectoryGoal:
    """What a FollowJointTrajectory goal (or a joint_path_command) asks, ROS types removed.
    Tolerances map a joint name to a position tolerance [rad] (0 or absent: the default; negative:
    no limit, as control_msgs defines)."""

    joint_names: Tuple[str, ...]
    positions: Tuple[Tuple[float, ...], ...]
    times: Tuple[float, ...]                         # time_from_start of each point [s]
    path_tolerance: Dict[str, float] = field(default_factory=dict)
    goal_tolerance: Dict[str, float] = field(default_factory=dict)
    goal_time_tolerance: float = 0.0
    start_time: Optional[float] = None               # header.stamp, seconds (None: now)

    @classmethod
    def of(cls, trajectory: Any, **kwargs: Any) -> "TrajectoryGoal":
        """The goal of a timed joint trajectory that has ``joint_names``, ``positions`` and ``times``
        (e.g. kinematics.planner's PlannedTrajectory); ``kwargs``: tolerances and start time."""
        return cls(tuple(trajectory.joint_names), tuple(tuple(p) for p in trajectory.positions),
                   tuple(trajectory.times), **kwargs)


@dataclass(frozen=True)
class ConfigurationTolerances:
    """A trajectory's tolerances on a Cartesian protocol, per planned point (``validate(...,
    resolution=...)``): a joint the goal left at 0 gets, at each point, the protocol's rule of the joint
    error the wire's resolution allows there (``errors``); a given one keeps its value. Where
    joint_5 is within ``band`` of 0 (the plan's or the arm's) joint_4 and joint_6 are judged by
    ``joint_4 + sign * joint_6`` (the pose fixes only that): against ``path_sum`` / ``goal_sum``,
    each of the two joints contributing its given tolerance, or half the sum's default (the rule of
    ``sum_errors``)."""

    path: Tuple[Tuple[float, ...], ...]              # per point, per joint [rad] (inf: none)
    path_sum: Tuple[float, ...]                      # per point: joint_4 + sign * joint_6 [rad]
    goal_sum: float                                  # at the end: joint_4 + sign * joint_6 [rad]
    errors: Tuple[Tuple[float, ...], ...]            # per point, per joint: the wire's bound [rad]
    sum_errors: Tuple[float, ...]                    # per point: the same for the sum [rad]
    band: float                                      # rad: |joint_5| below it: judged by the sum
    sign: float                                      # +1: joint_4 + joint_6; -1: joint_4 - joint_6
    wrist: Tuple[int, int, int] = (3, 4, 5)          # indices of joint_4, joint_5, joint_6

    def in_band(self, q: Sequence[float]) -> bool:
        return abs(q[self.wrist[1]]) < self.band

    def sum_of(self, q: Sequence[float]) -> float:
        return q[self.wrist[0]] + self.sign * q[self.wrist[2]]

    def sum_name(self, names: Sequence[str]) -> str:
        return "%s %s %s" % (names[self.wrist[0]], "+" if self.sign > 0 else "-", names[self.wrist[2]])

    def band_words(self, names: Sequence[str]) -> str:
        """The rule in words, e.g. "joint_4 + joint_6 judged by their sum within 5.0 deg of joint_5 = 0"."""
        return "%s judged by their sum within %.1f deg of %s = 0" % (
            self.sum_name(names), math.degrees(self.band), names[self.wrist[1]])


@dataclass(frozen=True)
class ValidTrajectory:
    """A checked trajectory in the controller's joint order, starting where the arm is.
    ``path_tolerance`` / ``goal_tolerance``: per joint; with per-configuration tolerances
    (``per_configuration``) the path tolerance is the smallest over the points and the goal tolerance
    the one at the end -- the checks (:func:`path_check`, the supervisor's goal check) use
    ``per_configuration``."""

    positions: Tuple[Tuple[float, ...], ...]         # point 0 = the arm's joints now
    times: Tuple[float, ...]                         # times[0] = 0
    path_tolerance: Tuple[float, ...]                # per joint, inf = none
    goal_tolerance: Tuple[float, ...]
    goal_time_tolerance: float
    delay: float                                     # how long after "now" the motion starts
    per_configuration: Optional[ConfigurationTolerances] = None     # Cartesian protocols' tolerances

    @property
    def duration(self) -> float:
        return self.times[-1]

    def sample(self, t: float) -> Tuple[float, ...]:
        """The planned joints at ``t`` seconds from the start (linear between points)."""
        times, pts = self.times, self.positions
        if t <= times[0]:
            return pts[0]
        if t >= times[-1]:
            return pts[-1]
        lo, hi = 0, len(times) - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if times[mid] <= t:
                lo = mid
            else:
                hi = mid
        f = (t - times[lo]) / (times[hi] - times[lo])
        return tuple(a + f * (b - a) for a, b in zip(pts[lo], pts[hi]))


def _left_empty(names: Sequence[str], given: Dict[str, float]) -> Tuple[bool, ...]:
    """Per joint: the goal leaves its tolerance to the default (0 or not named)."""
    return tuple(given.get(name, 0.0) == 0 for name in names)


def _per_configuration(points: Sequence[Tuple[float, ...]], resolution: Any, path_given: Tuple[float, ...],
                       goal_given: Tuple[float, ...], path_empty: Tuple[bool, ...],
                       goal_empty: Tuple[bool, ...]) -> Tuple[ConfigurationTolerances, Tuple[float, ...]]:
    """The tolerances at each point and the goal tolerance at the end: the protocol's rule of the
    wire's error there for the joints left empty, the given ones otherwise (see
    :class:`ConfigurationTolerances`)."""
    wire = resolution.wire
    errors, sums = resolution.errors_along(points)
    w4, _w5, w6 = wrist = (3, 4, 5)
    path, path_sum = [], []
    for err, err_sum in zip(errors, sums):
        path.append(tuple(wire.path_tolerance_for(e) if empty else given
                          for e, empty, given in zip(err, path_empty, path_given)))
        half = wire.path_tolerance_for(err_sum / 2.0)
        path_sum.append(sum(half if path_empty[i] else path_given[i] for i in (w4, w6)))
    half = wire.goal_tolerance_for(sums[-1] / 2.0)
    goal_sum = sum(half if goal_empty[i] else goal_given[i] for i in (w4, w6))
    goal = tuple(wire.goal_tolerance_for(e) if empty else given
                 for e, empty, given in zip(errors[-1], goal_empty, goal_given))
    return ConfigurationTolerances(path=tuple(path), path_sum=tuple(path_sum), goal_sum=goal_sum,
                                   errors=tuple(errors), sum_errors=tuple(sums), band=resolution.band,
                                   sign=resolution.sign, wrist=wrist), goal


def _tolerances(names: Sequence[str], given: Dict[str, float], default: float, what: str
                ) -> Tuple[float, ...]:
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise TrajectoryError(INVALID_JOINTS, "%s names unknown joint(s) %s" % (what, ", ".join(unknown)))
    out = []
    for name in names:
        value = given.get(name, 0.0)
        if not isinstance(value, (int, float)) or isinstance(value, bool) or math.isnan(value):
            raise TrajectoryError(INVALID_GOAL, "%s of %s is not a number: %r" % (what, name, value))
        out.append(math.inf if value < 0 else (default if value == 0 else float(value)))
    return tuple(out)


def validate(goal: TrajectoryGoal, controller_names: Sequence[str], current: Sequence[float],
             lower: Sequence[float], upper: Sequence[float], now: float,
             start_tolerance: float = math.radians(2.0), late_start: float = 0.5,
             default_path_tolerance: float = DEFAULT_PATH_TOLERANCE,
             default_goal_tolerance: float = DEFAULT_PATH_TOLERANCE, resolution: Any = None) -> ValidTrajectory:
    """Check a goal and bring it into the controller's joint order. Raises TrajectoryError:

    - INVALID_JOINTS: names missing, unknown, duplicated;
    - INVALID_GOAL: no points, a point of the wrong length, NaN / inf, outside the joint limits
      (naming the point and the joint), times not finite, not strictly increasing, or the first
      point's time negative; a first point at time 0 that is not where the arm is (by more than
      ``start_tolerance``);
    - OLD_HEADER_TIMESTAMP: a start time (``header.stamp``) more than ``late_start`` in the past
      (0 / None means now; a start in the future delays the motion: ``delay``).

    A first point at a time > 0 is reached from the arm's joints now; otherwise the first point
    is the start and must be where the arm is.

    A joint the goal's path / goal tolerance leaves at 0 (or does not name) gets
    ``default_path_tolerance`` / ``default_goal_tolerance`` [rad]; a negative one means no limit.
    ``resolution`` (a :class:`~vr_driver.driver.joints.resolution.WireResolution`: a Cartesian protocol on
    the arm's kinematics; None: the scalar defaults) makes those defaults per configuration instead
    (:class:`ConfigurationTolerances`, the trajectory's ``per_configuration``).
    """
    names = list(goal.joint_names)
    expected = list(controller_names)
    if len(set(names)) != len(names):
        raise TrajectoryError(INVALID_JOINTS, "joint names %s contain a duplicate" % names)
    if sorted(names) != sorted(expected):
        missing = sorted(set(expected) - set(names))
        extra = sorted(set(names) - set(expected))
        raise TrajectoryError(INVALID_JOINTS, "joint names %s do not match the controller's %s%s%s"
                              % (names, expected, "; missing %s" % ", ".join(missing) if missing else "",
                                 "; unknown %s" % ", ".join(extra) if extra else ""))
    order = [names.index(n) for n in expected]
    if not goal.positions:
        raise TrajectoryError(INVALID_GOAL, "the trajectory has no points")
    if len(goal.times) != len(goal.positions):
        raise TrajectoryError(INVALID_GOAL, "%d times for %d points" % (len(goal.times), len(goal.positions)))
    points: List[Tuple[float, ...]] = []
    for k, point in enumerate(goal.positions):
        if len(point) != len(names):
            raise TrajectoryError(INVALID_GOAL, "point %d has %d positions for %d joints"
                                  % (k, len(point), len(names)))
        q = tuple(float(point[i]) for i in order)
        for name, v, lo, hi in zip(expected, q, lower, upper):
            if not math.isfinite(v):
                raise TrajectoryError(INVALID_GOAL, "point %d: %s is not finite (%r)" % (k, name, v))
            if not lo - 1e-9 <= v <= hi + 1e-9:
                raise TrajectoryError(INVALID_GOAL, "point %d: %s = %.4f rad is outside its limits "
                                      "[%.4f, %.4f]" % (k, name, v, lo, hi))
        points.append(q)
    times = [float(t) for t in goal.times]
    for k, t in enumerate(times):
        if not math.isfinite(t):
            raise TrajectoryError(INVALID_GOAL, "point %d: time_from_start is not finite (%r)" % (k, t))
    if times[0] < 0.0:
        raise TrajectoryError(INVALID_GOAL, "point 0: time_from_start %.3f s is negative" % times[0])
    for k in range(1, len(times)):
        if not times[k] > times[k - 1]:
            raise TrajectoryError(INVALID_GOAL, "point %d: time_from_start %.3f s does not increase "
                                  "(point %d: %.3f s)" % (k, times[k], k - 1, times[k - 1]))
    delay = 0.0
    if goal.start_time:                                # None / 0: start now
        delay = goal.start_time - now
        if delay + times[-1] < 0.0:
            raise TrajectoryError(OLD_HEADER_TIMESTAMP, "the trajectory ended %.3f s ago (header.stamp "
                                  "%.3f s in the past)" % (-(delay + times[-1]), -delay))
        if delay < -late_start:
            raise TrajectoryError(OLD_HEADER_TIMESTAMP, "header.stamp is %.3f s in the past: the "
                                  "trajectory cannot be run as planned (the limit is %.3f s; a stamp of "
                                  "0 means now)" % (-delay, late_start))
        delay = max(0.0, delay)
    start = tuple(float(v) for v in current)
    if times[0] == 0.0:
        off = max(abs(a - b) for a, b in zip(points[0], start))
        if off > start_tolerance:
            worst = max(range(len(start)), key=lambda i: abs(points[0][i] - start[i]))
            raise TrajectoryError(INVALID_GOAL, "point 0 (time 0) is not where the arm is: %s is "
                                  "%.2f deg away (the limit is %.2f deg)" % (
                                      expected[worst], math.degrees(off), math.degrees(start_tolerance)))
        points[0] = start
    else:
        points.insert(0, start)
        times.insert(0, 0.0)
    path_tolerance = _tolerances(expected, goal.path_tolerance, default_path_tolerance, "path_tolerance")
    goal_tolerance = _tolerances(expected, goal.goal_tolerance, default_goal_tolerance, "goal_tolerance")
    per_configuration = None
    if resolution is not None:
        per_configuration, goal_tolerance = _per_configuration(
            points, resolution, path_tolerance, goal_tolerance, _left_empty(expected, goal.path_tolerance),
            _left_empty(expected, goal.goal_tolerance))
        path_tolerance = tuple(min(column) for column in zip(*per_configuration.path))
    return ValidTrajectory(
        positions=tuple(points), times=tuple(times), path_tolerance=path_tolerance,
        goal_tolerance=goal_tolerance, goal_time_tolerance=max(0.0, float(goal.goal_time_tolerance)),
        delay=delay, per_configuration=per_configuration)


def segment_speeds(traj: ValidTrajectory, vmax: Sequence[float], names: Sequence[str]
                   ) -> List[float]:
    """The speed of each segment (point k-1 -> k) as a fraction of the joint speed limits that
    makes a synchronous joint move take exactly its planned time: max over joints of
    |dq_i| / (dt * vmax_i). Raises TrajectoryError(INVALID_GOAL) naming the first segment that
    needs more than the limits (1.0)."""
    speeds = []
    for k in range(1, len(traj.positions)):
        dt = traj.times[k] - traj.times[k - 1]
        needs = [abs(b - a) / (dt * v) for a, b, v in zip(traj.positions[k - 1], traj.positions[k], vmax)]
        worst = max(range(len(needs)), key=needs.__getitem__)
        if needs[worst] > 1.0 + 1e-9:
            raise TrajectoryError(INVALID_GOAL, "segment %d -> %d (%.3f s) needs %.0f %% of %s's "
                                  "speed limit (%.3f rad/s): beyond the limits"
                                  % (k - 1, k, dt, 100.0 * needs[worst], names[worst], vmax[worst]))
        speeds.append(needs[worst])
    return speeds


def thin(traj: ValidTrajectory, reserve: float = V1_WIRE_ERROR) -> List[int]:
    """The indices of the fewest points (always the first and the last) such that moving in a
    straight joint-space line between kept points stays within each joint's path tolerance (less
    ``reserve``) of the planned path: a point is kept where dropping it would take the chord too
    far from a dropped point (recursive split at the worst point). A joint without a path
    tolerance (inf) never forces a point.

    With per-configuration tolerances (``traj.per_configuration``: a Cartesian protocol) ``reserve`` is not
    used: a dropped point's distance to the chord plus the wire's error at the chord's two ends
    (interpolated: the controller lands each stop point that far off) and at the point itself (the
    reported pose's rounding) must stay within :data:`THIN_SHARE` of its path tolerance; within the
    wrist band joint_4 and joint_6 count by their sum. A stop point is never placed inside the band
    where one outside it will do (the band's first or last point outside, before or after it): there
    the controller's IK of the rounded pose chooses the split of joint_4 / joint_6 itself (on v1 by
    tens of degrees), which the next move would carry out of the band."""
    pts = traj.positions
    if traj.per_configuration is not None:
        return _thin_per_configuration(traj, traj.per_configuration)
    tol = [max(t - reserve, 0.25 * t) if math.isfinite(t) else math.inf for t in traj.path_tolerance]
    return split_keep(len(pts), lambda a, b, k: _deviation(pts[a], pts[b], pts[k], tol), 1.0)


def _wrist_coordinates(tolerances: ConfigurationTolerances) -> List[int]:
    """The joints judged one by one inside the band (all but joint_4 and joint_6)."""
    return [i for i in range(len(tolerances.path[0])) if i not in (tolerances.wrist[0], tolerances.wrist[2])]


def _thin_per_configuration(traj: ValidTrajectory, tolerances: ConfigurationTolerances) -> List[int]:
    pts = np.asarray(traj.positions, dtype=float)
    n = len(pts)
    tol = np.asarray(tolerances.path, dtype=float)
    err = np.asarray(tolerances.errors, dtype=float)
    others = _wrist_coordinates(tolerances)
    sums = pts[:, tolerances.wrist[0]] + tolerances.sign * pts[:, tolerances.wrist[2]]
    # inside the band: the joints but joint_4 / joint_6, and their sum
    band_q = np.column_stack([pts[:, others], sums])
    band_tol = np.column_stack([tol[:, others], np.asarray(tolerances.path_sum, dtype=float)])
    band_err = np.column_stack([err[:, others], np.asarray(tolerances.sum_errors, dtype=float)])
    inside = [tolerances.in_band(p) for p in traj.positions]

    def excess(a: int, b: int, k: int) -> float:
        q, t, e = (band_q, band_tol, band_err) if inside[k] else (pts, tol, err)
        finite = np.isfinite(t[k])
        if not finite.any():
            return 0.0
        tk = t[k][finite]
        if (tk <= 0.0).any():
            return math.inf
        qa, qb, qk = q[a][finite], q[b][finite], q[k][finite]
        d = (qb - qa) / tk
        v = (qk - qa) / tk
        dd = float(d @ d)
        f = 0.0 if dd == 0.0 else min(1.0, max(0.0, float(d @ v) / dd))
        chord = np.abs(qk - (qa + f * (qb - qa)))
        wire_error = (1.0 - f) * e[a][finite] + f * e[b][finite] + e[k][finite]
        return float(np.max((chord + wire_error) / (THIN_SHARE * tk)))

    def run_of(k: int) -> Tuple[int, int]:
        """The first and last point of the run of points inside the band that holds ``k``."""
        lo, hi = k, k
        while lo > 0 and inside[lo - 1]:
            lo -= 1
        while hi < n - 1 and inside[hi + 1]:
            hi += 1
        return lo, hi

    def outside_band(k: int, a: int, b: int) -> int:
        """The stop point to keep between ``a`` and ``b`` (exclusive) for the worst point ``k``.
        An end inside the band lands with a split of its own: a straight move from it to a point
        outside carries that split out of the band, so the band's edge next to it is kept first
        (its last point outside before ``b``'s run, its first after ``a``'s). Otherwise ``k``, or
        where it lies inside the band the nearer of the band's edges -- ``k`` when neither is."""
        edges = []
        if inside[b]:
            edges.append(run_of(b)[0] - 1)
        if inside[a]:
            edges.append(run_of(a)[1] + 1)
        edges = [c for c in edges if a < c < b]
        if edges:
            return min(edges, key=lambda c: abs(c - k))
        if not inside[k]:
            return k
        lo, hi = run_of(k)
        candidates = [c for c in (lo - 1, hi + 1) if a < c < b]
        return min(candidates, key=lambda c: abs(c - k)) if candidates else k

    return split_keep(n, excess, 1.0, outside_band)


def split_keep(n: int, excess: Callable[[int, int, int], float], limit: float,
               choose: Optional[Callable[[int, int, int], int]] = None) -> List[int]:
    """The points to keep of ``n`` (always the first and the last), by recursive split: between two
    kept points ``a`` and ``b``, the dropped point ``k`` with the largest ``excess(a, b, k)`` above
    ``limit`` is kept -- or ``choose(k, a, b)``, a point strictly between ``a`` and ``b`` to keep
    instead -- and both halves are split again. Used by :func:`thin` (v1: distance to the chord) and
    :func:`~vr_driver.driver.motion.stream_thinning.thin_timed` (v2: distance at the planned time)."""
    if n <= 2:
        return list(range(n))
    keep = {0, n - 1}
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        worst, worst_value = -1, limit
        for k in range(a + 1, b):
            value = excess(a, b, k)
            if value > worst_value:
                worst, worst_value = k, value
        if worst >= 0:
            if choose is not None:
                worst = choose(worst, a, b)
            keep.add(worst)
            stack.append((a, worst))
            stack.append((worst, b))
    return sorted(keep)


def _deviation(a: Sequence[float], b: Sequence[float], p: Sequence[float], tol: Sequence[float]) -> float:
    """How far ``p`` is from the joint-space segment a-b, in units of each joint's tolerance:
    max over joints of |p_i - c_i| / tol_i at the point c of the segment nearest p (nearest in
    the tolerance-scaled space; joints without a tolerance do not count). The deviation of the
    chord from a piecewise-linear path is largest at the path's vertices, so checking the dropped
    points is enough."""
    idx = [i for i, t in enumerate(tol) if math.isfinite(t)]
    if not idx:
        return 0.0
    if any(tol[i] <= 0.0 for i in idx):
        return math.inf
    d = [(b[i] - a[i]) / tol[i] for i in idx]
    v = [(p[i] - a[i]) / tol[i] for i in idx]
    dd = sum(x * x for x in d)
    f = 0.0 if dd == 0.0 else min(1.0, max(0.0, sum(x * y for x, y in zip(d, v)) / dd))
    return max(abs(y - f * x) for x, y in zip(d, v))


@dataclass(frozen=True)
class PathCheck:
    """Where joints are against a trajectory's planned path (:func:`path_check`)."""

    deviation: float          # x the path tolerance (> 1: outside); 0: no joint has a tolerance
    segment: int              # the nearest segment: points segment - 1 -> segment
    joint: int                # the joint that deviates most (index; by_sum: joint_4's for the sum)
    by_sum: bool              # inside the wrist band: joint_4 and joint_6 judged by their sum


def path_deviation(traj: ValidTrajectory, q: Sequence[float]) -> Tuple[float, int]:
    """How far the joints ``q`` are from the planned path (anywhere along it, not at a given
    time), in units of each joint's path tolerance (> 1: outside), and the index of the nearest
    segment. Used where the timing is not kept (v1): the path, not the schedule, is checked.
    :func:`path_check` with the joint."""
    check = path_check(traj, q)
    return check.deviation, check.segment


def path_check(traj: ValidTrajectory, q: Sequence[float]) -> PathCheck:
    """:func:`path_deviation` with the joint that deviates most. The distance to each segment is
    measured at its point nearest ``q`` (in the space scaled by the tolerances, which with
    per-configuration tolerances are interpolated along the segment). With ``traj.per_configuration``, where
    ``q``'s joint_5 or that point's is within the wrist band, joint_4 and joint_6 are judged by
    their sum (``by_sum``) against the sum's tolerance."""
    pts = np.asarray(traj.positions, dtype=float)
    if len(pts) == 1:
        pts = np.vstack([pts, pts])
    q = np.asarray(q, dtype=float)
    tolerances = traj.per_configuration
    if tolerances is None:
        tol = np.tile(np.asarray(traj.path_tolerance, dtype=float), (len(pts), 1))
    else:
        tol = np.asarray(tolerances.path, dtype=float)
        if len(tol) == 1:
            tol = np.vstack([tol, tol])
    dev, joint, c = _segment_deviations(pts, tol, q)
    by_sum = np.zeros(len(dev), dtype=bool)
    if tolerances is not None:
        others = _wrist_coordinates(tolerances)
        i4, i5, i6 = tolerances.wrist
        path_sum = np.asarray(tolerances.path_sum, dtype=float)
        if len(path_sum) == 1:
            path_sum = np.concatenate([path_sum, path_sum])
        band_pts = np.column_stack([pts[:, others], pts[:, i4] + tolerances.sign * pts[:, i6]])
        band_tol = np.column_stack([tol[:, others], path_sum])
        band_q = np.concatenate([q[others], [q[i4] + tolerances.sign * q[i6]]])
        band_dev, band_joint, band_c = _segment_deviations(band_pts, band_tol, band_q)
        j5 = others.index(i5)
        band = tolerances.band
        by_sum = (abs(q[i5]) < band) | (np.abs(band_c[:, j5]) < band) | (np.abs(c[:, i5]) < band)
        dev = np.where(by_sum, band_dev, dev)
        mapped = np.array(others + [i4])
        joint = np.where(by_sum, mapped[band_joint], joint)
    k = int(np.argmin(dev))
    return PathCheck(float(dev[k]), k + 1 if len(traj.positions) > 1 else 0, int(joint[k]), bool(by_sum[k]))


def _segment_deviations(pts: np.ndarray, tol: np.ndarray, q: np.ndarray
                        ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per segment ``pts[k] -> pts[k + 1]`` (tolerances ``tol`` at each point, inf: none): the
    deviation of ``q`` from the segment's point nearest it in the tolerance-scaled space, in units
    of the tolerance there, the coordinate of the largest, and that nearest point."""
    a, b = pts[:-1], pts[1:]
    ta, tb = tol[:-1], tol[1:]
    finite = np.isfinite(ta) & np.isfinite(tb)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(finite, 2.0 / (ta + tb), 0.0)
        d = (b - a) * scale
        v = (q - a) * scale
        dd = np.einsum("ij,ij->i", d, d)
        f = np.where(dd > 0.0, np.clip(np.einsum("ij,ij->i", d, v) / np.where(dd > 0.0, dd, 1.0), 0.0, 1.0), 0.0)
        c = a + f[:, None] * (b - a)
        t = np.where(finite, ta + f[:, None] * (tb - ta), np.inf)
        off = np.abs(q - c)
        dev = np.where(finite, np.where(t > 0.0, off / t, np.where(off > 0.0, np.inf, 0.0)), 0.0)
    return dev.max(axis=1), dev.argmax(axis=1), c
