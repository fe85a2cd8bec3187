"""Joint trajectories from a planner: validation with control_msgs' error codes, the speed each
segment needs to keep the planned timing, and thinning for the v1 program. ROS-free, no I/O.

This is the part of ``joint_trajectory_action`` (FollowJointTrajectory) and ``joint_path_command``
that needs no ROS and no bus: the ROS adapter converts the goal into a :class:`TrajectoryGoal`,
:func:`validate` checks it (refusing with :class:`TrajectoryError` whose ``code`` is the
control_msgs result code), :func:`segment_speeds` says how fast each segment must be, and
:func:`thin` picks the fewest points a stop-at-every-point program (v1) must visit so that the
path stays within the path tolerance.

Units: radians, seconds; joint order is the controller's (``controller_joint_names``) after
:func:`validate`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from ..errors import VrDriverError

__all__ = [
    "SUCCESSFUL", "INVALID_GOAL", "INVALID_JOINTS", "OLD_HEADER_TIMESTAMP",
    "PATH_TOLERANCE_VIOLATED", "GOAL_TOLERANCE_VIOLATED",
    "TrajectoryError", "TrajectoryGoal", "ValidTrajectory", "validate", "segment_speeds", "thin",
    "path_deviation", "split_keep",
    "DEFAULT_PATH_TOLERANCE", "V1_WIRE_ERROR",
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
class ValidTrajectory:
    """A checked trajectory in the controller's joint order, starting where the arm is."""

    positions: Tuple[Tuple[float, ...], ...]         # point 0 = the arm's joints now
    times: Tuple[float, ...]                         # times[0] = 0
    path_tolerance: Tuple[float, ...]                # per joint, inf = none
    goal_tolerance: Tuple[float, ...]
    goal_time_tolerance: float
    delay: float                                     # how long after "now" the motion starts

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
             default_goal_tolerance: float = DEFAULT_PATH_TOLERANCE) -> ValidTrajectory:
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
    return ValidTrajectory(
        positions=tuple(points), times=tuple(times),
        path_tolerance=_tolerances(expected, goal.path_tolerance, default_path_tolerance, "path_tolerance"),
        goal_tolerance=_tolerances(expected, goal.goal_tolerance, default_goal_tolerance, "goal_tolerance"),
        goal_time_tolerance=max(0.0, float(goal.goal_time_tolerance)), delay=delay)


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
    tolerance (inf) never forces a point."""
    pts = traj.positions
    tol = [max(t - reserve, 0.25 * t) if math.isfinite(t) else math.inf for t in traj.path_tolerance]
    return split_keep(len(pts), lambda a, b, k: _deviation(pts[a], pts[b], pts[k], tol), 1.0)


def split_keep(n: int, excess: Callable[[int, int, int], float], limit: float) -> List[int]:
    """The points to keep of ``n`` (always the first and the last), by recursive split: between two
    kept points ``a`` and ``b``, the dropped point ``k`` with the largest ``excess(a, b, k)`` above
    ``limit`` is kept, and both halves are split again. Used by :func:`thin` (v1: distance to the
    chord) and :func:`~vr_driver.driver.streaming.thin_timed` (v2: distance at the planned time)."""
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


def path_deviation(traj: ValidTrajectory, q: Sequence[float]) -> Tuple[float, int]:
    """How far the joints ``q`` are from the planned path (anywhere along it, not at a given
    time), in units of each joint's path tolerance (> 1: outside), and the index of the nearest
    segment. Used where the timing is not kept (v1): the path, not the schedule, is checked."""
    pts = traj.positions
    if len(pts) == 1:
        return _deviation(pts[0], pts[0], q, traj.path_tolerance), 0
    best, where = math.inf, 0
    for k in range(1, len(pts)):
        d = _deviation(pts[k - 1], pts[k], q, traj.path_tolerance)
        if d < best:
            best, where = d, k
    return best, where
