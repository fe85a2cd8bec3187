"""How closely any arm can follow a plan, judged as the driver and the bench judge it (ROS-free,
no I/O): the plan's points joined by straight lines (constant joint speed between two points), the
arm compared with it at the same time less one start delay of its choosing.

A plan's points joined by straight lines change each joint's speed at once at every point; an arm
whose joint accelerates at most ``a`` cannot. Two lower bounds on the largest deviation, for every
start delay and every way of moving the joint (any controller, any ramp shape):

- **A corner** (the speed changes by ``dv`` at a point, the straight pieces on either side lasting
  at least ``|dv| / (2 a)``): ``dv**2 / (16 a)``. The error's slope changes by ``dv`` at the corner;
  on one side it leaves at ``|dv| / 2`` or more, and within that piece the error then changes by
  ``(dv / 2)**2 / (2 a)`` or more: twice the largest error at least.
- **A start or an end at rest** (the plan leaves its first point or reaches its last at speed
  ``v``): ``(3 - 2 sqrt 2) v**2 / (2 a)``, about ``v**2 / (11.7 a)``, for an arm that does not
  overshoot the point it rests at (a controller's move to a target -- the G2's MOVEP, the virtual
  G2's trapezoid -- does not), so it cannot share the error as at a corner. With the largest error
  ``E``, the arm is at most ``E`` short of the point when the plan gets there, so it moves at most
  ``sqrt(2 a E)`` then, and at most ``w sqrt(2 a E) + a w**2 / 2`` in the time ``w`` before; the
  plan moves ``v w``, which leaves ``2 E`` at most. True for every ``w`` only if
  ``E >= (3 - 2 sqrt 2) v**2 / (2 a)`` (the worst ``w`` is ``(2 - sqrt 2) v / a``, the piece it needs).

Within the wrist band (joint_5 near 0, where a pose fixes only joint_4 + sign joint_6) the sum is
judged instead of the two joints, its acceleration the sum of theirs (a bound, not a reach).

:func:`following_floor` gives the largest of these bounds over a plan: a deviation target below it
cannot be met by any arm that keeps those accelerations. (The virtual G2's arm does not quite:
its blend windows and its moves shorter than its ramp change speed faster, by its documented
model, :mod:`vr_driver.controller.stream_arm`; a sampled figure may also miss the moment.) The
bench prints it beside every goal's deviation (bench/trajectory.py), the trajectory action's result
says it (:class:`~vr_driver.driver.joints.supervision.TrajectorySupervisor`), and the stepped test of the
wrist goals asserts it where it says a target is out of reach.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

from .resolution import WRIST

__all__ = ["REST_FACTOR", "CORNER_FACTOR", "CORNER_REACH", "REST_REACH", "following_floor"]

#: the floor of a start or an end at rest, times v**2 / a
REST_FACTOR = (3.0 - 2.0 * math.sqrt(2.0)) / 2.0
#: the floor of a corner, times dv**2 / a
CORNER_FACTOR = 1.0 / 16.0
#: the straight piece the bound of a corner needs on either side of it, times |dv| / a
CORNER_REACH = 0.5
#: ... and of an end (or a start) before (after) it, times v / a
REST_REACH = 2.0 - math.sqrt(2.0)


def following_floor(times: Sequence[float], points: Sequence[Sequence[float]], accelerations: Sequence[float],
                    band: Optional[float] = None, sign: float = 1.0,
                    names: Optional[Sequence[str]] = None) -> Tuple[float, str]:
    """(floor [rad], where in words): the least largest deviation from the plan (``points`` at
    ``times``, joined by straight lines, at rest before the first and after the last) that an arm
    whose joints accelerate at most ``accelerations`` [rad/s^2] and that does not overshoot the
    first and last points can reach, for any start delay (module text). ``band`` [rad]: where
    |joint_5| at a point is under it, joint_4 and joint_6 count there by ``joint_4 + sign *
    joint_6`` (None: every joint by itself). (0.0, "") for a plan that does not
    move, or whose every speed change lies too near the next one for a bound. ``names``: the joints'
    names in the words (default joint_1 ...)."""
    n = len(times)
    if n != len(points) or n < 2:
        return 0.0, ""
    if any(not (b > a) for a, b in zip(times, times[1:])):
        raise ValueError("the plan's times must increase")
    dt = [b - a for a, b in zip(times, times[1:])]

    def in_band(k: int) -> bool:
        return band is not None and abs(points[k][WRIST[1]]) < band

    label = list(names) if names is not None else ["joint_%d" % (j + 1) for j in range(len(accelerations))]
    series = [(label[j], (lambda q, j=j: q[j]), accelerations[j],
               (lambda k, j=j: not (j in (WRIST[0], WRIST[2]) and in_band(k))))
              for j in range(len(accelerations))]
    if band is not None:
        series.append(("%s %s %s" % (label[WRIST[0]], "+" if sign > 0 else "-", label[WRIST[2]]),
                       lambda q: q[WRIST[0]] + sign * q[WRIST[2]],
                       accelerations[WRIST[0]] + accelerations[WRIST[2]], in_band))
    best, where = 0.0, ""
    for name, value, a, judged in series:
        if not a > 0.0:
            continue
        # the speed of each straight piece, at rest before the first point and after the last
        speeds = [0.0] + [(value(points[k + 1]) - value(points[k])) / dt[k] for k in range(n - 1)] + [0.0]
        for k in range(n):
            if not judged(k):
                continue
            dv = speeds[k + 1] - speeds[k]
            # the straight pieces the bound's argument uses: a corner's on both sides, an end's before it
            need = (REST_REACH if k in (0, n - 1) else CORNER_REACH) * abs(dv) / a
            before = dt[k - 1] if k > 0 else math.inf
            after = dt[k] if k < n - 1 else math.inf
            if before < need or after < need:
                continue
            factor = REST_FACTOR if k in (0, n - 1) else CORNER_FACTOR
            floor = factor * dv * dv / a
            if floor > best:
                best = floor
                where = "%s at point %d of %d (%s %.0f deg/s)" % (
                    name, k, n - 1, "starts at" if k == 0 else "stops from" if k == n - 1 else "changes by",
                    math.degrees(abs(dv)))
    return best, where
