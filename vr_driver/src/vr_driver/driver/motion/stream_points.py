"""From a plan to a stream (ROS-free, pure computation, in the caller's thread, never the bus
thread): :func:`stream_points` turns a planned joint path into the points of one stream job. The
planned points are thinned with their timing (:mod:`.stream_thinning`; no kept segment shorter than
the bus can feed); each kept point gets the speed that makes the controller's synchronous joint move
end at its planned time (:func:`stream_speeds`: rounded up to the wire's 0.1 %, the rounding carried
into the next segment so that the arrivals do not drift), and a smooth level: the largest up to
``stream_smooth`` whose rounded corner (:func:`~vr_driver.protocol.common.blend_window`) stays
within the corner tolerance, at least 1 (the last point: 0, an exact stop; :func:`corner_levels`).
A pause of the plan is held: the arm stops exactly at the point before it, and the next point is
offered only when the pause ends (``StreamPoint.release``). Fed in time (:func:`fed_schedule`): no
point is reached before the bus can have brought the next; where a plan's first points come sooner
than that, the stream begins with a hold -- its first target just off the start toward the first
point (:func:`hold_point`), reached after the lead the bus needs to fill the controller's ring --
and then runs the plan's own timing, every point that lead later (``StreamPoint.fed``, ``hold``).
Putting the points on the wire is :mod:`.streaming`'s job."""
from __future__ import annotations

import math
from typing import Callable, List, NamedTuple, Optional, Sequence, Tuple

from ...protocol.common import blend_window
from .jobs import StreamPoint
from .stream_thinning import PAUSE_EPS, SKIP_TOLERANCE, split_long, thin_timed

__all__ = ["Fed", "HOLD_CREEP", "MAX_CARTESIAN_TOLERANCE", "MAX_STREAM_TOLERANCE", "MIN_SEGMENT_CYCLES",
           "corner_levels", "corner_rounding", "fed_schedule", "hold_lead", "hold_point", "hold_speed", "stream_points",
           "stream_speeds"]

#: the largest thinning tolerance [rad] a planner trajectory's stream may use to keep its segments
#: longer than MIN_SEGMENT_CYCLES (a quarter of the default path tolerance: the thinning, the blended
#: corners and the timing share it; a Cartesian move's: 0.05 deg)
MAX_STREAM_TOLERANCE = math.radians(0.25)
MAX_CARTESIAN_TOLERANCE = math.radians(0.05)
#: a kept segment lasts at least this many bus cycles (the record moves on once the feedback says
#: the controller took its target, one cycle after it was sent: shorter segments would starve the
#: look-ahead)
MIN_SEGMENT_CYCLES = 2.0
#: [rad] how far the hold at a stream's start moves the arm toward its first target (the joint that
#: moves most; more where the slowest wire speed, 0.1 %, would cross it sooner than the hold lasts):
#: a target with a speed the controller runs like any other, an exact stop (fed_schedule,
#: hold_point). Its speed is set from where the controller will solve its wire pose, to the nearest
#: 0.1 % (hold_speed; CartesianStreams.with_poses: near joint_5 = 0 that may be another joint_4 /
#: joint_6 split, and the point after the hold is timed from there too). The wire's rounding of the
#: arm's reported start stays: measured on the paced line 0.83-1.15 x the lead (a plan turning one
#: joint, each joint in turn), within the feed's cycle of margin
HOLD_CREEP = math.radians(0.05)


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



class Fed(NamedTuple):
    """A stream's timing as the bus feeds it (:func:`fed_schedule`)."""

    lead: float          #: [s] the hold at the start: the arm runs the plan this much later (0: none)
    times: List[float]   #: each point's arrival [s from the stream's start], the lead included


def _fed(times: Sequence[float], held: Sequence[bool], releases: Sequence[float], feed: float, ring: int,
         lead: Optional[float]) -> List[float]:
    """The arrivals of :func:`fed_schedule` for one ``lead`` (None: no hold target; a number: a hold
    target first, reached at the start's release + ``lead``, every point ``lead`` later than planned):
    each point no sooner than one ``feed`` after the controller can have the next target -- one
    target a ``feed`` after the one before, none before the ``ring``'s room (the target ``ring``
    before it passed; ``ring`` < 2: not modelled), after a pause of the plan none before its end --
    and every point after a late one that much later too."""
    n = len(times)
    origin = float(releases[0]) if releases else 0.0
    shift = 0.0 if lead is None else float(lead)
    passed = [] if lead is None else [origin + shift]   # when the arm is at each target (its slot frees)
    arrival = origin if lead is None else origin + feed  # when the controller can have this point's target
    out = []
    for j, t in enumerate(times):
        k = len(passed)
        stop = j < len(held) and held[j]
        nxt = arrival + feed
        if ring >= 2 and k + 1 - ring >= 0:
            nxt = max(nxt, passed[k + 1 - ring])
        if j < n - 1 and not stop:
            shift = max(shift, nxt + feed - float(t))
        out.append(float(t) + shift)
        passed.append(out[-1])
        # after a pause the next target is offered at its end: the ring is empty, the feed starts again
        arrival = float(releases[j + 1]) + shift if stop and j + 1 < len(releases) else nxt
    return out


def fed_schedule(times: Sequence[float], held: Sequence[bool], releases: Sequence[float], feed: float,
                 ring: int = 0, hold: bool = True) -> Fed:
    """When the arm reaches each target [s from the stream's start] so that the next is in the
    controller by then. The bus brings one target every ``feed`` s (a bus cycle; two where the master
    sends one per acknowledgement), the controller holds at most ``ring`` targets (a target's slot
    frees once the arm passed it; < 2: not modelled) and the arm starts with the first: so a point
    is reached no sooner than one ``feed`` (the cycle's jitter) after the next target can be there.
    ``held[j]``: the arm stops at point ``j`` for a pause of the plan ending at ``releases[j + 1]``
    (the ring runs dry there and the next targets come as at a start); ``releases[0]``: the first
    target's (a pause at the start).

    A plan the bus keeps up with is unchanged (lead 0). Where its first points come sooner (a
    planner's first samples, 50 ms apart while the arm speeds up, on a slow line), the stream begins
    with a **hold**: a target reached ``lead`` s after the start (see :func:`stream_points`), while
    the bus fills the controller's ring, and then the plan runs on its own timing, every point
    ``lead`` later -- the smallest lead, of those that make the first points in time, after which
    the fewest later points must wait. A point the ring or a pause still makes too soon is reached
    that much later, and every point after it by as much (segments keep their planned durations or
    run longer, never faster: the top speed said holds). So the run is the plan delayed by a
    constant where the ring can hold the difference: the trajectory bench's wrist goals deviate from
    the plan at the same time as they did unfed (the bench fits the start delay), and the arm never
    reaches a point before the next came. Before (every point shifted as needed from the first,
    no hold) the arm crept through its first segment and no single start delay fitted the run: the
    median deviation 0.18 -> 0.38-0.41 deg. ``hold`` False (a controller whose queue has no room for
    the targets a hold would gather: v2's two), or a ring of fewer than 3: that, every point shifted
    as needed from the first. What is said before the run counts the lead and the later shifts (the
    last point's)."""
    plain = [float(t) for t in times]
    if feed <= 0.0 or not plain:
        return Fed(0.0, plain)
    unfed = _fed(plain, held, releases, feed, ring, None)
    # the first run: up to the first pause (a later one's feed starts again at its end anyway)
    first = next((j for j, h in enumerate(held[:len(plain)]) if h), len(plain) - 1)
    if not hold or 0 < ring < 3 or all(unfed[j] <= plain[j] + 1e-9 for j in range(first + 1)):
        return Fed(0.0, unfed)
    origin = float(releases[0]) if releases else 0.0
    # each point's own lead (the hold is the first target: point j is target j + 1, the next j + 2
    # feeds after the start, and one feed more); at least the two feeds that bring point 1 in time
    needs = [origin + (j + 3) * feed - plain[j] for j in range(min(first + 1, len(plain) - 1))]
    if ring >= 2:
        needs = needs[:ring + 2]                # beyond, the ring (not the lead) brings them
    leads = sorted({max(2.0 * feed, need) for need in needs} or {2.0 * feed})
    if ring < 2:
        leads = leads[-1:]
    best: Optional[Tuple[float, float, List[float]]] = None
    for lead in leads:
        fed = _fed(plain, held, releases, feed, ring, lead)
        later = fed[-1] - plain[-1] - lead
        if best is None or later < best[0] - 1e-9:
            best = (later, lead, fed)
    assert best is not None
    return Fed(best[1], best[2])


def hold_lead(stream: Sequence[StreamPoint]) -> float:
    """[s] the hold a ``stream`` begins with (its first point's ``fed`` arrival past its planned time,
    where that point is the hold of :func:`fed_schedule`); 0 without one."""
    first = stream[0] if stream else None
    return first.fed - float(first.time) if first is not None and first.hold and first.fed is not None else 0.0


def hold_speed(start: Sequence[float], joints: Sequence[float], lead: float, vmax: Sequence[float]) -> int:
    """The wire speed (0.1 %, 1..1000) at which the move from ``start`` to ``joints`` -- the hold,
    as the controller will solve its wire pose -- lasts ``lead`` s: the nearest whole step (the
    hold's few hundredths of a degree run at 0.1-1 %, where rounding up, as :func:`stream_speeds`
    does, would halve a 1.02 into 2)."""
    full = max(abs(b - a) / v for a, b, v in zip(start, joints, vmax))
    return max(1, min(1000, int(round(1000.0 * full / lead)))) if lead > 0.0 else 1000


def hold_point(start: Sequence[float], first: Sequence[float], lead: float, vmax: Sequence[float]) -> Tuple[float, ...]:
    """Where the hold at a stream's start (:func:`fed_schedule`) ends: a little way from ``start``
    toward the first target ``first`` (about HOLD_CREEP in the joint that moves most, or as far as
    the slowest wire speed, 0.1 %, takes in ``lead`` s), so that a move at a whole wire speed lasts
    ``lead`` s; at most half way."""
    delta = [b - a for a, b in zip(start, first)]
    full = max(abs(d) / v for d, v in zip(delta, vmax))       # the first segment at full speed [s]
    reach = max(abs(d) for d in delta)
    if full <= 0.0 or lead <= 0.0:
        return tuple(float(v) for v in start)
    slowest = lead / (1000.0 * full)            # the share 0.1 % covers in ``lead`` s
    # a whole wire speed (0.1 % steps): the share at that speed takes ``lead`` exactly -- save where
    # even 0.1 % crosses half the first segment sooner (a segment of hundredths of a degree)
    share = min(0.5, slowest * max(1, min(round(HOLD_CREEP / reach / slowest), math.floor(0.5 / slowest))))
    return tuple(a + share * d for a, d in zip(start, delta))


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
           vmax: Sequence[float], smooth: int, corner_tolerance: float, feed: float = 0.0, ring: int = 0,
           hold_start: bool = True) -> Tuple[Tuple[StreamPoint, ...], List[int]]:
    """The stream of the planned points ``kept`` (indices, not the start): timed (no point reached
    before the bus can have brought the next, :func:`fed_schedule`, ``feed`` [s] a target, ``ring``
    targets the controller holds; a hold first where it needs one), pauses held, corners blended
    (see :func:`stream_points`); and the planned indices of the corners even smooth level 1 rounds
    by more than ``corner_tolerance``."""
    start = tuple(float(v) for v in positions[0])
    pts = [tuple(float(v) for v in positions[k]) for k in kept]
    ts = [float(times[k]) for k in kept]
    arrive = list(ts)
    index = list(kept)
    hold = -1                                     # where the hold target is in pts (-1: none)
    if feed > 0.0 and pts:
        # the motion's targets (a pause's end repeats the point before it: not one of them)
        before = [start] + pts[:-1]
        moving = [max(abs(a - b) for a, b in zip(p, q)) > PAUSE_EPS for p, q in zip(before, pts)]
        idx = [i for i, m in enumerate(moving) if m]
        held = [i + 1 < len(moving) and not moving[i + 1] for i in idx]
        releases = [ts[i - 1] if i > 0 and not moving[i - 1] else 0.0 for i in idx]
        fed = fed_schedule([ts[i] for i in idx], held, releases, feed, ring, hold_start)
        for i, t in zip(idx, fed.times):
            arrive[i] = t
        if fed.lead > 0.0:
            # the hold: a target just off the start toward the first, reached ``lead`` after the
            # plan leaves the start (0, or a pause's end), an exact stop; the plan's timing after it
            hold, origin = idx[0], releases[0]
            pts.insert(hold, hold_point(start, pts[hold], fed.lead, vmax))
            ts.insert(hold, origin)
            arrive.insert(hold, origin + fed.lead)
            index.insert(hold, kept[hold - 1] if hold > 0 else 0)
    speeds = stream_speeds(start, pts, arrive, vmax)
    # a pause of the plan (a kept point where the previous one is): not a target; the arm stops
    # exactly at the point before it, and the point after it is offered only when the pause ends
    out_pts: List[Tuple[float, ...]] = []
    out = []                                      # (speed, time, index, release, fed) per target
    holds = set()                                 # targets the arm stops at (a pause, the hold)
    prev, release = start, 0.0
    for i, (q, speed, t, k, fed_at) in enumerate(zip(pts, speeds, ts, index, arrive)):
        if i != hold and max(abs(a - b) for a, b in zip(prev, q)) <= PAUSE_EPS:
            release = t
            if out:
                holds.add(len(out) - 1)
            continue
        if i == hold:
            holds.add(len(out))
        out_pts.append(q)
        out.append((speed, t, k, release, fed_at))
        prev, release = q, 0.0
    if not out:
        return (), []
    moves, velocities = _motion(start, out_pts, [o[0] for o in out], vmax)
    levels = _levels(moves, velocities, smooth, corner_tolerance)
    tight = [] if smooth <= 0 else [
        out[i][2] for i in range(len(out) - 1)
        if i not in holds and corner_rounding(1, moves, velocities, i) > corner_tolerance]
    first = 0 if hold >= 0 else -1               # the hold is the first target when there is one
    stream = tuple(StreamPoint(q, speed, 0 if i in holds else level, t, k, release, fed=fed_at, hold=i == first)
                   for i, (q, level, (speed, t, k, release, fed_at)) in enumerate(zip(out_pts, levels, out)))
    return stream, tight


def stream_points(times: Sequence[float], positions: Sequence[Sequence[float]], vmax: Sequence[float],
                  smooth: int, tolerance: float, min_dt: float, max_tolerance: Optional[float] = None,
                  corner_tolerance: Optional[float] = None, max_step: Optional[float] = None,
                  reaches: Optional[Callable[[Sequence[float], Sequence[float]], bool]] = None,
                  feed: float = 0.0, ring: int = 0, hold: bool = True) -> Tuple[StreamPoint, ...]:
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

    ``feed`` [s] (0: none): the time the bus takes to bring one target, ``ring`` the targets the
    controller holds (< 2: not modelled), ``hold`` whether a hold may begin the stream; each point's speed makes the arm reach it no sooner than
    the next can be there (:func:`fed_schedule`): where the plan's first points come sooner, the
    stream begins with a hold -- a target a little way toward the first point (:func:`hold_point`,
    planned point 0 or the start's pause, an exact stop) reached ``lead`` s after the start, at a
    speed of its own -- while the bus fills the ring, and the plan's own timing follows.

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
        stream, tight = _timed(times, positions, order[1:], vmax, smooth, corner_tol, feed, ring, hold)
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
