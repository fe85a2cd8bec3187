"""From a plan to a stream (ROS-free, pure computation, in the caller's thread, never the bus
thread): :func:`stream_points` turns a planned joint path into the points of one stream job. The
planned points are thinned with their timing (:mod:`.stream_thinning`; no kept segment shorter than
the bus can feed); each kept point gets the speed that makes the controller's synchronous joint move
end at its planned time (:func:`stream_speeds`: rounded up to the wire's 0.1 %, the rounding carried
into the next segment so that the arrivals do not drift), and a smooth level: the largest up to
``stream_smooth`` whose rounded corner (:func:`~vr_driver.protocol.common.blend_window`) stays
within the corner tolerance, at least 1 (the last point: 0, an exact stop; :func:`corner_levels`).
A pause of the plan is held: the arm stops exactly at the point before it, and the next point is
offered only when the pause ends (``StreamPoint.release``). Putting the points on the wire is
:mod:`.streaming`'s job."""
from __future__ import annotations

import math
from typing import Callable, List, Optional, Sequence, Tuple

from ...protocol.common import blend_window
from .jobs import StreamPoint
from .stream_thinning import PAUSE_EPS, SKIP_TOLERANCE, split_long, thin_timed

__all__ = ["MAX_CARTESIAN_TOLERANCE", "MAX_STREAM_TOLERANCE", "MIN_SEGMENT_CYCLES", "corner_levels",
           "corner_rounding", "fed_times", "stream_points", "stream_speeds"]

#: the largest thinning tolerance [rad] a planner trajectory's stream may use to keep its segments
#: longer than MIN_SEGMENT_CYCLES (a quarter of the default path tolerance: the thinning, the blended
#: corners and the timing share it; a Cartesian move's: 0.05 deg)
MAX_STREAM_TOLERANCE = math.radians(0.25)
MAX_CARTESIAN_TOLERANCE = math.radians(0.05)
#: a kept segment lasts at least this many bus cycles (the record moves on once the feedback says
#: the controller took its target, one cycle after it was sent: shorter segments would starve the
#: look-ahead)
MIN_SEGMENT_CYCLES = 2.0


def stream_speeds(start: Sequence[float], points: Sequence[Sequence[float]], times: Sequence[float],
                  vmax: Sequence[float]) -> List[int]:
    """The wire speed (0.1 % of the joint speed limits, 1..1000) of each segment so that the
    synchronous joint move to ``points[k]`` ends at ``times[k]`` (seconds from the start at
    ``start``). Each speed is rounded up (the arm is never slower than planned) and the time that
    rounding gains is carried into the next segment, so the arrivals do not drift. A segment that
    would need more than the limits gets 1000 (full speed): the caller validates the plan first."""
    speeds = []
    elapsed = 0.0
    prev = start
    for q, t in zip(points, times):
        full = max(abs(b - a) / v for a, b, v in zip(prev, q, vmax))   # its time at 100 %
        want = t - elapsed
        if full <= 0.0:
            permille = 1000                      # no motion: a pause, held until its planned end
            elapsed = max(elapsed, t)
        elif want <= 0.0:
            permille = 1000
        else:
            permille = min(1000, max(1, int(math.ceil(1000.0 * full / want - 1e-9))))
        if full > 0.0:
            elapsed += full * 1000.0 / permille
        speeds.append(permille)
        prev = q
    return speeds



def fed_times(times: Sequence[float], held: Sequence[bool], releases: Sequence[float], feed: float) -> List[float]:
    """The times [s from the stream's start] the arm reaches each target so that the next is in the
    controller by then: the bus brings one target every ``feed`` s (a bus cycle; two where the master
    sends one per acknowledgement) and the arm starts with the first -- target ``j + 1`` (1-based)
    arrives about ``j`` feeds after it, so point ``j`` is reached no sooner than ``j + 1`` feeds (one
    for the cycle's jitter) after the start, or after the end of a pause (``held[j]``: the arm
    stops at point ``j`` for a pause of the plan ending at ``releases[j + 1]``: the ring runs dry
    there and the next targets come as at a start).

    A point that would come too soon is reached that much later, and every point after it by as
    much: the segments keep their planned durations or run longer, never faster (the top speed said
    holds), and the time said before the run counts it (the last point's shift). On a slow line a
    plan's first samples (the arm speeding up, 50 ms apart) came faster than the bus: the arm reached
    point 1 before point 2 came and stopped there (the planning rostest, 4 runs in 6 at 23 cycles/s);
    a plan dense all along (31 of 41 points kept over 2 s) ran 1.29 x its time with no target late.
    The cost: where the arm is held back, it is off the plan at the same time (the trajectory bench's
    wrist goals, after the one start delay that fits best: median 0.18 -> 0.38-0.41 deg, the largest
    1.13 -> 0.87-1.02 deg)."""
    out = []
    origin, count, shift = 0.0, 0, 0.0
    for j, t in enumerate(times):
        count += 1
        if feed > 0.0 and j < len(times) - 1:
            shift = max(shift, origin + (count + 1) * feed - float(t))
        out.append(float(t) + shift)
        if j < len(held) and held[j] and j + 1 < len(releases):
            origin, count = releases[j + 1] + shift, 0
    return out


def _motion(start: Sequence[float], points: Sequence[Sequence[float]], speeds: Sequence[int],
            vmax: Sequence[float]) -> Tuple[List[float], List[Tuple[float, ...]]]:
    """Each segment's move time [s] at its wire speed and its joint velocities [rad/s]."""
    moves, velocities = [], []
    prev = start
    for q, permille in zip(points, speeds):
        full = max(abs(b - a) / v for a, b, v in zip(prev, q, vmax))
        move = full * 1000.0 / permille
        moves.append(move)
        velocities.append(tuple((b - a) / move if move > 0.0 else 0.0 for a, b in zip(prev, q)))
        prev = q
    return moves, velocities


def corner_rounding(level: int, moves: Sequence[float], velocities: Sequence[Sequence[float]], k: int) -> float:
    """How far [rad, the worst joint] a blend of ``level`` rounds the corner at point ``k``
    (between segments ``k`` and ``k + 1``): the velocity jump times the blend window / 8."""
    jump = max(abs(a - b) for a, b in zip(velocities[k], velocities[k + 1]))
    return jump * blend_window(level, moves[k], moves[k + 1]) / 8.0


def corner_levels(start: Sequence[float], points: Sequence[Sequence[float]], speeds: Sequence[int],
                  vmax: Sequence[float], smooth: int, tolerance: float) -> List[int]:
    """The smooth level of each point but the last (0): the largest up to ``smooth`` whose blend
    rounds the corner there (the joint velocity changing from one segment's to the next's over the
    blend window: about ``|v1 - v2| * window / 8`` from the point, every joint) within ``tolerance``
    [rad]; at least 1, so that the arm never stops on the way (``smooth`` 0: 0 everywhere)."""
    if not points:
        return []
    return _levels(*_motion(start, points, speeds, vmax), smooth, tolerance)


def _levels(moves: Sequence[float], velocities: Sequence[Sequence[float]], smooth: int,
            tolerance: float) -> List[int]:
    """:func:`corner_levels` from the segments' move times and velocities (:func:`_motion`)."""
    levels = []
    for k in range(len(moves) - 1):
        level = max(smooth, 0)
        while level > 1 and corner_rounding(level, moves, velocities, k) > tolerance:
            level -= 1
        levels.append(level)
    return levels + [0]


def _timed(times: Sequence[float], positions: Sequence[Sequence[float]], kept: Sequence[int],
           vmax: Sequence[float], smooth: int, corner_tolerance: float, feed: float = 0.0
           ) -> Tuple[Tuple[StreamPoint, ...], List[int]]:
    """The stream of the planned points ``kept`` (indices, not the start): timed (no point reached
    before the bus can have brought the next, :func:`fed_times`, ``feed`` [s] a target), pauses
    held, corners blended (see :func:`stream_points`); and the planned indices of the corners even
    smooth level 1 rounds by more than ``corner_tolerance``."""
    pts = [tuple(float(v) for v in positions[k]) for k in kept]
    ts = [float(times[k]) for k in kept]
    if feed > 0.0:
        # the motion's targets (a pause's end repeats the point before it: not one of them)
        before = [tuple(float(v) for v in positions[0])] + pts[:-1]
        moving = [max(abs(a - b) for a, b in zip(p, q)) > PAUSE_EPS for p, q in zip(before, pts)]
        idx = [i for i, m in enumerate(moving) if m]
        held = [i + 1 < len(moving) and not moving[i + 1] for i in idx]
        releases = [ts[i - 1] if i > 0 and not moving[i - 1] else 0.0 for i in idx]
        fed = fed_times([ts[i] for i in idx], held, releases, feed)
        arrive = list(ts)
        for i, t in zip(idx, fed):
            arrive[i] = t
    else:
        arrive = list(ts)
    speeds = stream_speeds(positions[0], pts, arrive, vmax)
    # a pause of the plan (a kept point where the previous one is): not a target; the arm stops
    # exactly at the point before it, and the point after it is offered only when the pause ends
    out_pts: List[Tuple[float, ...]] = []
    out = []                                      # (speed, time, index, release, fed) per target
    holds = set()                                 # targets the arm stops at for a pause
    prev, release = tuple(float(v) for v in positions[0]), 0.0
    for q, speed, t, k, fed_at in zip(pts, speeds, ts, kept, arrive):
        if max(abs(a - b) for a, b in zip(prev, q)) <= PAUSE_EPS:
            release = t
            if out:
                holds.add(len(out) - 1)
            continue
        out_pts.append(q)
        out.append((speed, t, k, release, fed_at))
        prev, release = q, 0.0
    if not out:
        return (), []
    moves, velocities = _motion(positions[0], out_pts, [o[0] for o in out], vmax)
    levels = _levels(moves, velocities, smooth, corner_tolerance)
    tight = [] if smooth <= 0 else [
        out[i][2] for i in range(len(out) - 1)
        if i not in holds and corner_rounding(1, moves, velocities, i) > corner_tolerance]
    stream = tuple(StreamPoint(q, speed, 0 if i in holds else level, t, k, release, fed=fed_at)
                   for i, (q, level, (speed, t, k, release, fed_at)) in enumerate(zip(out_pts, levels, out)))
    return stream, tight



def stream_points(times: Sequence[float], positions: Sequence[Sequence[float]], vmax: Sequence[float],
                  smooth: int, tolerance: float, min_dt: float, max_tolerance: Optional[float] = None,
                  corner_tolerance: Optional[float] = None, max_step: Optional[float] = None,
                  reaches: Optional[Callable[[Sequence[float], Sequence[float]], bool]] = None,
                  feed: float = 0.0) -> Tuple[StreamPoint, ...]:
    """The stream for a planned joint path (``positions[0]`` = the start at ``times[0]`` = 0):
    thinned (:func:`thin_timed`), timed (:func:`stream_speeds`), each point but the last blended
    with the level :func:`corner_levels` gives for ``corner_tolerance`` (default: ``tolerance``;
    the last point: 0, an exact stop).

    ``max_step`` [rad] (a Cartesian protocol): no joint moves farther than that between two stream
    points (:func:`split_long` puts planned points back): the controller solves each pose nearest the
    previous target, which is the planned joints only while a wrist joint turns by well under half a
    turn -- a thinned straight segment turning joint_6 by 270 deg would be run as -90 deg. ``reaches``
    (with ``max_step``): where the controller would solve the next point onto another branch (near
    the elbow's stretch, where two branches lie a few degrees apart), planned points are put back too.

    A kept segment shorter than ``min_dt`` may starve the look-ahead (the controller would stop at a
    point and wait: a gap): the thinning tolerance is then doubled, up to ``max_tolerance`` (default
    ``tolerance``), until no segment is that short; short segments left then are sent as they are.

    ``feed`` [s] (0: none): the time the bus takes to bring one target; each point's speed makes the
    arm reach it no sooner than the next can be there (:func:`fed_times`).

    A sharp corner (the planned velocity jumps there) that even smooth level 1 would round by more
    than ``corner_tolerance`` gets back the planned points nearest to it on both sides that thinning
    dropped (no closer than ``min_dt`` in time): the segments at the corner become shorter, and so
    does the blend window (a fraction of them)."""
    tol = tolerance
    top = tolerance if max_tolerance is None else max(tolerance, max_tolerance)
    while True:
        kept = thin_timed(times, positions, tol)
        short = any(times[b] - times[a] < min_dt for a, b in zip(kept, kept[1:-1]))
        if not short or tol >= top:
            break
        tol = min(2.0 * tol, top)
    if len(kept) < 2:
        return ()
    corner_tol = tolerance if corner_tolerance is None else corner_tolerance
    chosen = set(kept if max_step is None else split_long(positions, kept, max_step, reaches, times,
                                                          max(tol, SKIP_TOLERANCE)))
    while True:
        order = sorted(chosen)
        stream, tight = _timed(times, positions, order[1:], vmax, smooth, corner_tol, feed)
        added = False
        for k in tight:
            at = order.index(k)
            before, after = order[at - 1], order[at + 1]
            # the dropped planned point nearest the corner on each side, min_dt from both neighbours
            gap = min_dt - 1e-9                  # (planned times in float seconds)
            for j in range(k - 1, before, -1):
                if times[k] - times[j] >= gap and times[j] - times[before] >= gap:
                    chosen.add(j)
                    added = True
                    break
            for j in range(k + 1, after):
                if times[j] - times[k] >= gap and times[after] - times[j] >= gap:
                    chosen.add(j)
                    added = True
                    break
        if not added:
            return stream
