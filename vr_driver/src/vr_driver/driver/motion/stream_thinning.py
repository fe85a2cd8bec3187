"""Which planned points a stream keeps (ROS-free, pure computation, the caller's thread): the
thinning with the timing (:func:`thin_timed`: a point is dropped only where the straight joint-space
move between its neighbours, run at constant speed, passes it at its planned time within the
tolerance; a pause of the plan is always kept, both its ends) and, for a Cartesian stream, the
points put back where a joint would turn too far between two targets or the controller would solve
the next one onto another branch -- with the skip across the elbow's stretch (:func:`split_long`).
Timing the kept points is :mod:`.stream_points`' job."""
from __future__ import annotations

import math
from typing import Callable, List, Optional, Sequence

from .trajectories import split_keep

__all__ = ["PAUSE_EPS", "SKIP_TOLERANCE", "paused", "split_long", "thin_timed", "timed_excess"]

#: [rad] a Cartesian stream skips planned points across the elbow's stretch (:func:`split_long`) when
#: the straight move over them stays this close to each at its planned time: a plan turns joint_3
#: alone there (driver.planning.planning, ELBOW_CROSS), so the straight move keeps to the path and differs only
#: in its timing -- the arm speeding up out of the stretch at the planner's acceleration, which the
#: constant speed of a segment puts up to ~1 deg ahead for a tenth of a second
SKIP_TOLERANCE = math.radians(1.0)
#: rad: a kept point this close to the previous one (every joint) is a pause of the plan, held
PAUSE_EPS = 1e-6


def timed_excess(times: Sequence[float], positions: Sequence[Sequence[float]], a: int, b: int, k: int) -> float:
    """[rad, the worst joint] how far planned point ``k`` is from the constant-speed straight joint
    move from point ``a`` to point ``b``, at its planned time."""
    f = (times[k] - times[a]) / (times[b] - times[a])
    return max(abs(pa + f * (pb - pa) - pk) for pa, pb, pk in zip(positions[a], positions[b], positions[k]))


def paused(positions: Sequence[Sequence[float]], k: int) -> bool:
    """Planned point ``k`` is where the one before is: the end of a pause of the plan."""
    return k > 0 and max(abs(x - y) for x, y in zip(positions[k], positions[k - 1])) <= PAUSE_EPS


def thin_timed(times: Sequence[float], positions: Sequence[Sequence[float]], tolerance: float) -> List[int]:
    """Indices of the points to keep (always the first and the last): a point is dropped where the
    constant-speed straight joint move between the kept points around it is within ``tolerance``
    [rad, every joint] of it *at its planned time* (segments too short for the bus are
    :func:`stream_points`' concern: it raises the tolerance)."""
    # a pause of the plan (a point where the one before is, later) is always kept, both its ends:
    # the arm holds there (a short one could otherwise be thinned into the motion around it)
    pauses = [j for k in range(1, len(times)) if times[k] > times[k - 1] and paused(positions, k)
              for j in (k - 1, k)]
    bounds = sorted({0, len(times) - 1, *pauses})
    kept = set()
    for a, b in zip(bounds, bounds[1:]):
        kept.update(a + k for k in split_keep(
            b - a + 1, lambda x, y, z, a=a: timed_excess(times, positions, a + x, a + y, a + z), tolerance))
    return sorted(kept) if len(times) > 1 else list(range(len(times)))



def split_long(positions: Sequence[Sequence[float]], kept: Sequence[int], max_step: float,
               reaches: Optional[Callable[[Sequence[float], Sequence[float]], bool]] = None,
               times: Optional[Sequence[float]] = None, skip_tolerance: float = 0.0) -> List[int]:
    """``kept`` with planned points added between two kept ones whose joints differ by more than
    ``max_step`` [rad] (any joint), or -- with ``reaches`` (a Cartesian protocol: would the
    controller, after a target at the first joints, solve the pose of the second onto them?) --
    where the controller would not reach the next kept point from the one before: from each kept
    point the farthest planned point still within ``max_step`` of it and reached from it, until the
    next kept one is.

    Where not even the next planned point is reached (across the elbow's stretch the controller
    solves a pose just past it onto the branch it is on: the other branch's solution lies farther
    from the previous target than its mirror does) a point farther on may be -- the farther past the
    stretch, the nearer the planned branch -- and with ``times`` the stream skips to the first one
    that is, provided the straight move there at constant speed stays within ``skip_tolerance``
    [rad, every joint] of each planned point it skips at its planned time (:func:`thin_timed`'s
    rule), and no pause of the plan lies among them. Else the planned step stays, and the stream
    check says why."""
    def near(a: int, b: int) -> bool:
        return max(abs(x - y) for x, y in zip(positions[a], positions[b])) <= max_step and (
            reaches is None or reaches(positions[a], positions[b]))

    def skip_to(a: int, b: int) -> Optional[int]:
        if reaches is None or times is None or skip_tolerance <= 0.0:
            return None
        for m in range(a + 2, b + 1):
            if paused(positions, m - 1) or paused(positions, m) or \
                    max(abs(x - y) for x, y in zip(positions[a], positions[m])) > max_step:
                return None
            if any(timed_excess(times, positions, a, m, k) > skip_tolerance for k in range(a + 1, m)):
                return None
            if reaches(positions[a], positions[m]):
                return m
        return None

    out = [kept[0]]
    i = 1
    while i < len(kept):
        a, b = out[-1], kept[i]
        if near(a, b):
            out.append(b)
            i += 1
            continue
        if not near(a, a + 1):
            # not even the next planned point: skip to the first one that is, dropping kept ones
            m = skip_to(a, kept[-1])
            if m is not None:
                out.append(m)
                while i < len(kept) and kept[i] <= m:
                    i += 1
                continue
        j = a + 1
        while j + 1 < b and near(a, j + 1):
            j += 1
        if j >= b:              # a planned step the controller would not take: the stream check says why
            out.append(b)
            i += 1
            continue
        out.append(j)
    return out

