"""vr_driver.driver.motion.trajectories: goal validation with control_msgs' error codes, the speed each
segment needs for the planned timing, and thinning for the v1 program."""
from __future__ import annotations

import math
import random

import pytest

from vr_driver.driver.motion.trajectories import (INVALID_GOAL, INVALID_JOINTS, OLD_HEADER_TIMESTAMP,
                                           TrajectoryError, TrajectoryGoal, segment_speeds, thin,
                                           validate)

NAMES = tuple("joint_%d" % i for i in range(1, 7))
LOWER = (-2.705, -1.745, -3.0, -3.316, -4.712, -6.28)
UPPER = (2.705, 2.618, 1.3, 4.712, 4.712, 6.28)
VMAX = (2.09, 2.09, 2.09, 2.09, 5.23, 5.23)
HOME = (0.0, 0.6, -0.3, 0.0, 0.4, 0.0)
NOW = 100.0


def goal(points, times, names=NAMES, **kw):
    return TrajectoryGoal(tuple(names), tuple(tuple(p) for p in points), tuple(times), **kw)


def check(g, current=HOME, **kw):
    return validate(g, NAMES, current, LOWER, UPPER, NOW, **kw)


def test_a_good_goal_in_another_joint_order_comes_out_in_the_controllers_order():
    names = tuple(reversed(NAMES))
    p1 = [0.1, 0.7, -0.2, 0.1, 0.5, 0.2]
    traj = check(goal([list(reversed(p1))], [1.0], names=names))
    assert traj.positions == (HOME, tuple(p1))          # starts where the arm is
    assert traj.times == (0.0, 1.0) and traj.delay == 0.0
    assert traj.sample(0.5) == pytest.approx(tuple((a + b) / 2 for a, b in zip(HOME, p1)))


@pytest.mark.parametrize("names, words", [
    (NAMES[:5], "missing joint_6"),
    (NAMES[:5] + ("joint_x",), "unknown joint_x"),
    (NAMES[:5] + ("joint_1",), "duplicate"),
    ((), "missing"),
])
def test_wrong_joint_names_are_invalid_joints(names, words):
    with pytest.raises(TrajectoryError) as err:
        check(goal([[0.0] * len(names)], [1.0], names=names))
    assert err.value.code == INVALID_JOINTS and words in str(err.value)


@pytest.mark.parametrize("points, times, words", [
    ([], [], "no points"),
    ([HOME[:5]], [1.0], "5 positions for 6 joints"),
    ([HOME[:2] + (float("nan"),) + HOME[3:]], [1.0], "joint_3 is not finite"),
    ([HOME[:5] + (7.0,)], [1.0], "joint_6 = 7.0000 rad is outside its limits"),
    ([HOME, HOME], [1.0, 1.0], "point 1: time_from_start 1.000 s does not increase"),
    ([HOME, HOME], [2.0, 1.0], "does not increase"),
    ([HOME], [-1.0], "negative"),
    ([HOME], [float("inf")], "not finite"),
    ([(0.5,) + HOME[1:]], [0.0], "point 0 (time 0) is not where the arm is: joint_1 is 28.65 deg away"),
])
def test_bad_points_and_times_are_invalid_goals(points, times, words):
    with pytest.raises(TrajectoryError) as err:
        check(goal(points, times))
    assert err.value.code == INVALID_GOAL and words in str(err.value), str(err.value)


def test_header_stamps():
    assert check(goal([HOME], [1.0], start_time=NOW + 2.0)).delay == pytest.approx(2.0)
    assert check(goal([HOME], [1.0], start_time=NOW - 0.2)).delay == 0.0      # a little late: now
    with pytest.raises(TrajectoryError) as err:
        check(goal([HOME], [1.0], start_time=NOW - 3.0))
    assert err.value.code == OLD_HEADER_TIMESTAMP and "ended" in str(err.value)
    with pytest.raises(TrajectoryError) as err:
        check(goal([HOME, HOME], [1.0, 9.0], start_time=NOW - 3.0))
    assert err.value.code == OLD_HEADER_TIMESTAMP and "cannot be run as planned" in str(err.value)


def test_tolerances_default_negative_and_unknown():
    traj = check(goal([HOME], [1.0], path_tolerance={"joint_2": 0.01, "joint_3": -1.0}))
    assert traj.path_tolerance[1] == 0.01 and math.isinf(traj.path_tolerance[2])
    assert traj.path_tolerance[0] == pytest.approx(math.radians(1.0))
    with pytest.raises(TrajectoryError) as err:
        check(goal([HOME], [1.0], goal_tolerance={"joint_9": 0.1}))
    assert err.value.code == INVALID_JOINTS


def test_the_caller_names_the_default_tolerances():
    """A joint left at 0 (or not named) gets the caller's defaults, path and goal each its own; a
    given or negative tolerance is kept."""
    path, goal_default = math.radians(4.0), math.radians(3.0)
    traj = check(goal([HOME], [1.0], path_tolerance={"joint_2": 0.01, "joint_4": 0.0},
                      goal_tolerance={"joint_3": -1.0}),
                 default_path_tolerance=path, default_goal_tolerance=goal_default)
    assert traj.path_tolerance == pytest.approx((path, 0.01, path, path, path, path))
    assert math.isinf(traj.goal_tolerance[2])
    assert [traj.goal_tolerance[i] for i in (0, 1, 3, 4, 5)] == pytest.approx([goal_default] * 5)


def test_segment_speeds_keep_the_planned_timing_and_refuse_beyond_the_limits():
    p1 = list(HOME)
    p1[0] += 1.045                       # 1.045 rad of J1 in 1 s: half of 2.09 rad/s
    p2 = list(p1)
    p2[5] += 2.615                       # 2.615 rad of J6 in 1 s: half of 5.23 rad/s
    traj = check(goal([p1, p2], [1.0, 2.0]))
    assert segment_speeds(traj, VMAX, NAMES) == pytest.approx([0.5, 0.5])
    fast = check(goal([p1], [0.4]))      # 1.045 rad in 0.4 s: 125 %
    with pytest.raises(TrajectoryError) as err:
        segment_speeds(fast, VMAX, NAMES)
    assert err.value.code == INVALID_GOAL and "needs 125 % of joint_1's speed limit" in str(err.value)


def _path(n, rng, bend=0.0):
    """A smooth planner-like path from HOME: n points, optionally bending in joint 2."""
    pts = []
    for k in range(1, n + 1):
        s = k / n
        q = list(HOME)
        q[0] += 0.8 * s
        q[1] += bend * math.sin(math.pi * s)
        q[4] += 0.3 * s
        pts.append(q)
    return pts


def test_thinning_a_straight_joint_path_keeps_only_its_ends():
    traj = check(goal(_path(30, random.Random(1)), [0.1 * k for k in range(1, 31)]))
    assert thin(traj) == [0, 30]


def test_thinning_keeps_the_path_within_the_tolerance():
    rng = random.Random(7)
    tol = math.radians(3.0)
    traj = check(goal(_path(60, rng, bend=0.4), [0.05 * k for k in range(1, 61)],
                      path_tolerance={n: tol for n in NAMES}))
    kept = thin(traj, reserve=math.radians(1.5))
    assert kept[0] == 0 and kept[-1] == 60 and 2 < len(kept) < 20
    # every dropped point is within the tolerance less the reserve of the chord between kept ones
    allowed = tol - math.radians(1.5)
    for a, b in zip(kept, kept[1:]):
        for k in range(a + 1, b):
            f_best = min((abs(traj.positions[k][1] - (traj.positions[a][1] + f / 100 *
                                                      (traj.positions[b][1] - traj.positions[a][1]))), f)
                         for f in range(101))[0]
            assert f_best <= allowed + 1e-6
    # a tighter tolerance keeps more points
    tight = check(goal(_path(60, rng, bend=0.4), [0.05 * k for k in range(1, 61)],
                       path_tolerance={n: math.radians(1.7) for n in NAMES}))
    assert len(thin(tight, reserve=math.radians(1.5))) > len(kept)


def test_a_joint_without_path_tolerance_forces_no_point():
    traj = check(goal(_path(40, random.Random(3), bend=0.5), [0.05 * k for k in range(1, 41)],
                      path_tolerance={"joint_2": -1.0}))
    assert thin(traj) == [0, 40]
