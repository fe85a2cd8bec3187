"""The timing of a planned joint path, step 5 of :mod:`vr_driver.kinematics.planner`: a cubic spline
through the path (resampled densely, so that it stays on the checked path), TOPP-RA time-optimal
under the joint speed and acceleration limits (less :data:`TOPP_MARGIN`, on a grid through the
spline's knots: :func:`topp_grid`), from rest to rest, sampled evenly every ``dt`` at most; a move shorter than :data:`TINY_MOVE`, and one straight joint move (a
path of two points: the same limits, TOPP-RA's optimum without its grid), in closed form.

    timing = PathTiming(toppra, velocity_limits, acceleration_limits)   # the module, rad/s, rad/s^2
    times, positions, velocities, accelerations = timing.time(path, vs, acs, spline_step, dt)

ROS-free. The TOPP-RA module is handed in by the planner, which imports it (``kinematics.deps``);
this module imports no optional library. Checking the result (validity, the chords between the
samples) is the planner's: :data:`TIMING_ATTEMPTS` are the finer tries it makes when a check fails.
"""
from __future__ import annotations

import math
from typing import Any, Sequence, Tuple

import numpy as np

from ..errors import MotionError

__all__ = ["PathTiming", "TimingError", "Samples", "TOPP_MARGIN", "TINY_MOVE", "TIMING_ATTEMPTS", "topp_grid"]

#: the fraction of each speed and acceleration limit TOPP-RA plans to: its constraints hold at its
#: grid points, the spline between them may exceed them slightly; the sampled result is checked
#: against the full limits
TOPP_MARGIN = 0.97
#: [rad] a path whose joints move less than this is timed in closed form (TOPP-RA's grid finds no
#: timing for moves of 1e-6 .. 1e-5 rad: an arm reported at home is 4e-7 rad from the SRDF's home)
TINY_MOVE = 1e-4
#: the timing's tries: ([rad] the largest joint step between two points of the path the timing
#: spline goes through, the sample spacing as a fraction of ``dt``). The spline overshoots a corner of
#: the path a little, and the straight chord between two samples cuts a curve by its sag: where the
#: path runs along an obstacle, that can touch it. Closer spline points shrink the overshoot and
#: half the spacing quarters the sag; the result is the first try that passes every check.
TIMING_ATTEMPTS = ((0.05, 1.0), (0.01, 0.5), (0.002, 0.25))
#: TOPP-RA's grid (:func:`topp_grid`): points a span between two spline knots, and the fewest and
#: most points in all
GRID_PER_SPAN = 4
GRID_LEAST = 100
GRID_MOST = 2000

#: a timed trajectory: (times [s], positions [rad], velocities [rad/s], accelerations [rad/s^2])
Samples = Tuple[Tuple[float, ...], Tuple[Tuple[float, ...], ...], Tuple[Tuple[float, ...], ...],
                Tuple[Tuple[float, ...], ...]]


class TimingError(MotionError):
    """TOPP-RA found no timing of the path, or the timed path keeps exceeding the limits (the
    planner reports it as its PlanningError, step "time")."""


def _on_line(ts: np.ndarray, a: np.ndarray, b: np.ndarray, s: np.ndarray, sd: np.ndarray, sdd: np.ndarray) -> Samples:
    """The samples at ``ts`` of the straight joint move from ``a`` to ``b`` along the path parameter
    ``s`` (0..1) with its first and second derivatives ``sd``, ``sdd``; at rest, exactly at both ends."""
    d = b - a
    pos = a[None, :] + s[:, None] * d[None, :]
    vel = sd[:, None] * d[None, :]
    acc = sdd[:, None] * d[None, :]
    pos[0], pos[-1] = a, b
    vel[0] = vel[-1] = 0.0
    return _samples(ts, pos, vel, acc)


def _samples(ts: np.ndarray, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> Samples:
    """The arrays as tuples of floats (what PlannedTrajectory holds)."""
    return (tuple(float(t) for t in ts), tuple(tuple(float(v) for v in p) for p in pos),
            tuple(tuple(float(v) for v in p) for p in vel), tuple(tuple(float(v) for v in p) for p in acc))


def topp_grid(knots: np.ndarray) -> np.ndarray:
    """TOPP-RA's grid on the path parameter of a spline with ``knots`` (0 .. 1, increasing): every
    knot, each span between two cut into GRID_PER_SPAN equal parts (fewer where that would pass
    GRID_MOST points, more where it would stay below GRID_LEAST; for a spline of more than
    GRID_MOST spans, the timing's finer tries, an even grid of GRID_MOST points). A cubic spline's
    second derivative is linear between its knots, its extremes at them: a grid on the knots
    constrains the joints' accelerations where they peak. An even grid of as many points passed
    them between its points, and the timing was then slowed as a whole to bring the peak back
    within the limits -- by up to 8 % on the hood cell's searched paths (bench/README.md,
    "Planning", round 6)."""
    spans = len(knots) - 1
    if spans > GRID_MOST:
        return np.linspace(0.0, 1.0, GRID_MOST)
    per = max(1, min(GRID_PER_SPAN, GRID_MOST // spans), -(-GRID_LEAST // spans))
    inner = knots[:-1, None] + np.diff(knots)[:, None] * (np.arange(per) / per)[None, :]
    return np.concatenate((inner.ravel(), knots[-1:]))


class PathTiming:
    """Times joint paths from rest to rest under per-joint speed and acceleration limits (see the
    module text). ``toppra``: the TOPP-RA module (with its ``algorithm`` and ``constraint`` parts
    imported); ``velocity`` [rad/s] and ``acceleration`` [rad/s^2]: one finite limit > 0 a joint
    (the planner checks them)."""

    def __init__(self, toppra: Any, velocity: Sequence[float], acceleration: Sequence[float]) -> None:
        self._toppra = toppra
        self.velocity = np.array(velocity, dtype=float)
        self.acceleration = np.array(acceleration, dtype=float)

    def time(self, path: Sequence[Tuple[float, ...]], vs: float, acs: float, spline_step: float,
             dt: float) -> Samples:
        """TOPP-RA along a spline through the path, densified so that no joint steps more than
        ``spline_step`` [rad] between two of its points, at the limits times ``vs`` (speeds) and
        ``acs`` (accelerations); sampled evenly every <= ``dt`` [s]. A path that does not move is
        one sample at rest. TimingError when there is no timing."""
        ta = self._toppra
        dense = [path[0]]
        for a, b in zip(path, path[1:]):
            n = max(1, int(math.ceil(max(abs(x - y) for x, y in zip(a, b)) / spline_step)))
            dense.extend(tuple(x + (y - x) * k / n for x, y in zip(a, b)) for k in range(1, n + 1))
        wp = np.array(dense)
        seg = np.linalg.norm(np.diff(wp, axis=0), axis=1)
        keep = np.concatenate(([True], seg > 1e-9))
        wp = wp[keep]
        if len(wp) < 2:                       # start == goal: one point, at rest
            q = tuple(float(v) for v in path[0])
            zero = (0.0,) * len(q)
            return (0.0,), (q,), (zero,), (zero,)
        if float(np.max(np.abs(wp - wp[0]))) < TINY_MOVE:
            return self._time_tiny(wp[0], wp[-1], vs, acs, dt)
        if len(path) == 2:                    # one straight joint move: TOPP-RA's answer in closed form
            return self._time_straight(np.asarray(path[0], dtype=float), np.asarray(path[1], dtype=float),
                                       vs, acs, dt)
        s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1))))
        s = s / s[-1]
        curve = ta.SplineInterpolator(s, wp)
        vmax = self.velocity * vs * TOPP_MARGIN
        amax = self.acceleration * acs * TOPP_MARGIN
        constraints = [ta.constraint.JointVelocityConstraint(np.stack([-vmax, vmax], axis=1)),
                       ta.constraint.JointAccelerationConstraint(np.stack([-amax, amax], axis=1))]
        gridpoints = topp_grid(s)
        algo = ta.algorithm.TOPPRA(constraints, curve, gridpoints=gridpoints, parametrizer="ParametrizeConstAccel")
        timed = algo.compute_trajectory(0.0, 0.0)
        if timed is None:
            raise TimingError("TOPP-RA found no timing of the path under the speed and acceleration limits")
        duration = float(timed.duration)
        # TOPP-RA's limits hold at its grid points; between them the spline may exceed them a little:
        # where it does (checked on a grid 4 x finer than the samples), the whole timing is slowed
        # by the factor that brings it back (speeds / k, accelerations / k^2)
        vlim = self.velocity * vs
        alim = self.acceleration * acs

        def excess(u: np.ndarray, k: float) -> float:
            return max(float(np.max(np.abs(timed(u, 1)) / k / vlim)),
                       math.sqrt(float(np.max(np.abs(timed(u, 2)) / (k * k) / alim))))

        k = max(1.0, excess(np.linspace(0.0, duration, 4 * max(1, int(math.ceil(duration / dt))) + 1), 1.0))
        for _ in range(10):
            n = max(1, int(math.ceil(k * duration / dt - 1e-9)))
            ts = np.linspace(0.0, k * duration, n + 1)
            u = np.minimum(ts / k, duration)
            over = excess(u, k)
            if over <= 1.0:
                break
            k *= over * (1.0 + 1e-6)
        else:
            raise TimingError("the timed path keeps exceeding the speed or acceleration limits")
        pos, vel, acc = timed(u), timed(u, 1) / k, timed(u, 2) / (k * k)
        pos[0], pos[-1] = path[0], path[-1]
        vel[0] = vel[-1] = 0.0
        return _samples(ts, pos, vel, acc)

    def _time_straight(self, a: np.ndarray, b: np.ndarray, vs: float, acs: float, dt: float) -> Samples:
        """One straight joint move a -> b from rest to rest, time-optimal under the same limits as
        TOPP-RA's (the scaled limits less TOPP_MARGIN): along a straight line every joint moves in
        proportion, so the path parameter s (0..1) has one speed limit (the smallest v_i / |d_i|)
        and one acceleration limit (a_i / |d_i|): it accelerates at its limit, cruises at its
        speed limit if it reaches it, and brakes at its limit -- the profile TOPP-RA's grid
        approximates, without its grid (or its spline: the samples lie on the line itself)."""
        d = b - a
        moving = np.abs(d) > 0.0
        vmax = self.velocity * vs * TOPP_MARGIN
        amax = self.acceleration * acs * TOPP_MARGIN
        rate = float(np.min(vmax[moving] / np.abs(d[moving])))       # [1/s] ds/dt at most
        accel = float(np.min(amax[moving] / np.abs(d[moving])))      # [1/s^2] d2s/dt2 at most
        if rate * rate / accel >= 1.0:        # never at the speed limit: accelerate half way, brake
            ramp = math.sqrt(1.0 / accel)
            rate = accel * ramp
            cruise = 0.0
        else:
            ramp = rate / accel
            cruise = (1.0 - rate * ramp) / rate
        total = 2.0 * ramp + cruise
        n = max(1, int(math.ceil(total / dt - 1e-9)))
        ts = np.linspace(0.0, total, n + 1)
        braking = np.maximum(total - ts, 0.0)                         # [s] time left
        s = np.where(ts < ramp, 0.5 * accel * ts * ts,
                     np.where(braking < ramp, 1.0 - 0.5 * accel * braking * braking,
                              0.5 * rate * ramp + rate * (ts - ramp)))
        sd = np.where(ts < ramp, accel * ts, np.where(braking < ramp, accel * braking, rate))
        sdd = np.where(ts < ramp, accel, np.where(braking < ramp, -accel, 0.0))
        return _on_line(ts, a, b, np.clip(s, 0.0, 1.0), sd, sdd)

    def _time_tiny(self, a: np.ndarray, b: np.ndarray, vs: float, acs: float, dt: float) -> Samples:
        """A move shorter than TINY_MOVE (TOPP-RA's grid finds no timing for it): the straight move
        from rest to rest at the acceleration limits, accelerating for half its time and braking for
        the other half (at that length no joint comes near its speed limit)."""
        d = b - a
        amax = self.acceleration * acs
        vmax = self.velocity * vs
        total = max(float(np.max(2.0 * np.sqrt(np.abs(d) / amax))), float(np.max(2.0 * np.abs(d) / vmax)), 1e-3)
        n = max(2, int(math.ceil(total / dt)))
        ts = np.linspace(0.0, total, n + 1)
        u = ts / total
        shape = np.where(u < 0.5, 2.0 * u * u, 1.0 - 2.0 * (1.0 - u) ** 2)
        rate = np.where(u < 0.5, 4.0 * u, 4.0 * (1.0 - u)) / total
        curve = np.where(u < 0.5, 4.0, -4.0) / (total * total)
        return _on_line(ts, a, b, shape, rate, curve)
