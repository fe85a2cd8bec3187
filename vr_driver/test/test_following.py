"""driver.joints.following: the least deviation any arm with given accelerations can have from a plan's
points joined by straight lines -- checked against arms simulated finely (the bound must never be
beaten, and the best arm must come close to it)."""
from __future__ import annotations

import math

import pytest

from vr_driver.driver.joints.following import CORNER_FACTOR, REST_FACTOR, following_floor


def linear(times, values, t):
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    for (t0, v0), (t1, v1) in zip(zip(times, values), zip(times[1:], values[1:])):
        if t <= t1:
            return v0 + (v1 - v0) * (t - t0) / (t1 - t0)
    return values[-1]


def trapezoid(distance, speed, a, t):
    """A move from rest to rest over ``distance`` at ``speed``, accelerating at ``a``: its position at t."""
    ramp = speed / a
    cruise = distance / speed - ramp
    assert cruise >= 0.0
    if t <= 0.0:
        return 0.0
    if t <= ramp:
        return a * t * t / 2.0
    if t <= ramp + cruise:
        return a * ramp * ramp / 2.0 + speed * (t - ramp)
    if t <= 2 * ramp + cruise:
        u = 2 * ramp + cruise - t
        return distance - a * u * u / 2.0
    return distance


def best_deviation(arm, times, values, span):
    """The smallest, over start delays, largest |arm(t) - plan(t - delay)|, sampled every 0.1 ms."""
    best = math.inf
    for lag in [i * 0.0005 for i in range(-200, 400)]:
        worst = max(abs(arm(i * 1e-4) - linear(times, values, i * 1e-4 - lag)) for i in range(0, int(span * 1e4)))
        best = min(best, worst)
    return best


def test_a_move_from_rest_to_rest():
    a, v, d = 50.0, 2.0, 1.0
    floor, where = following_floor([0.0, d / v], [(0.0,), (d,)], (a,))
    assert floor == pytest.approx(REST_FACTOR * v * v / a)
    assert "joint_1" in where
    # the trapezoid at the plan's speed: no start delay makes it beat the floor; it comes within 1.5 x
    got = best_deviation(lambda t: trapezoid(d, v, a, t), [0.0, d / v], [0.0, d], d / v + 0.3)
    assert floor <= got <= 1.5 * floor, (got, floor)


def test_a_corner_and_the_ends():
    a = 20.0
    # 1, 2, 1 rad/s: the ends (1 rad/s from and to rest) outweigh the corners (1 rad/s changes)
    floor, where = following_floor([0.0, 0.5, 1.0, 1.5], [(0.0,), (0.5,), (1.5,), (2.0,)], (a,))
    assert floor == pytest.approx(REST_FACTOR * 1.0 / a) and "point 0 of 3" in where
    # 0.2, 3, 0.2 rad/s: the corners' 2.8 rad/s changes outweigh the ends
    floor, where = following_floor([0.0, 1.0, 2.0, 3.0], [(0.0,), (0.2,), (3.2,), (3.4,)], (a,))
    assert floor == pytest.approx(CORNER_FACTOR * 2.8 ** 2 / a) and "changes by" in where


def test_the_floor_is_never_beaten_by_a_simulated_arm():
    # a coarse simulation of the best arm for a corner: the speed changes at a, centred on the point
    a = 10.0
    times, values = [0.0, 0.4, 0.8], [0.0, 0.4, 1.2]          # 1 then 2 rad/s
    floor, _ = following_floor(times, [(v,) for v in values], (a,))
    step = 5e-4
    for start_early in (0.0, 0.02, 0.05):
        path, v, x, t = [], 0.0, 0.0, -0.2
        while t < 1.4:
            want = 0.0 if t < -start_early else 1.0 if t < 0.4 - 0.05 else 2.0 if t < 0.8 - 0.1 else 0.0
            v += max(-a * step, min(a * step, want - v))
            x = min(x + v * step, 1.2)       # it stops at the last point, no overshoot
            if x >= 1.2:
                v = 0.0
            path.append((t, x))
            t += step
        got = min(max(abs(x - linear(times, values, t - lag)) for t, x in path)
                  for lag in [i * 0.002 for i in range(-50, 100)])
        assert got >= floor * 0.98, (start_early, got, floor)


def test_in_the_wrist_band_the_sum_is_judged():
    a = (20.0,) * 6
    band = math.radians(5.0)
    # joint_4 and joint_6 turn fast and opposite at joint_5 = 0: their sum stands still
    times = [0.0, 0.5]
    points = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0, 0.0, -1.0)]
    floor, where = following_floor(times, points, a, band=band, sign=1.0)
    assert floor == 0.0 and where == ""
    # outside the band the same motion has a floor
    lifted = [tuple(q[:4]) + (0.5,) + tuple(q[5:]) for q in points]
    floor, where = following_floor(times, lifted, a, band=band, sign=1.0)
    assert floor == pytest.approx(REST_FACTOR * 4.0 / 20.0) and "joint_4" in where


def test_no_bound_where_the_pieces_are_too_short():
    # a speed change of 10 rad/s at 1 rad/s^2 needs 10 s pieces: a 0.1 s plan claims nothing
    floor, where = following_floor([0.0, 0.1], [(0.0,), (1.0,)], (1.0,))
    assert floor == 0.0 and where == ""


def test_bad_plans_are_refused_in_words():
    with pytest.raises(ValueError, match="increase"):
        following_floor([0.0, 0.0], [(0.0,), (1.0,)], (1.0,))
    assert following_floor([0.0], [(0.0,)], (1.0,)) == (0.0, "")
