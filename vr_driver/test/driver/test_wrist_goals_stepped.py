"""The trajectory bench's wrist goals (``bench/trajectory.py --set wrist``, seed 1: a real planner's
paths across and onto joint_5 = 0, TOPP-RA timed with the accelerations matched to the arm's ramp,
0.1 s samples; their plans kept in data/wrist_goals_seed1.json) run on v3 on the thesis' line
(19.2 kbit/s with the I/O island, look-ahead 1) in the stepped world (_paced.PacedWorld: the fake
clock, one thread), at the model's 0.1 s ramp and at a 0.5 s ramp, against issue 32's targets --
SUCCESSFUL with empty tolerances, no gap in the stream, within 1.10 x the plan + 0.3 s, within 0.5
deg of the plan at the same time by the driver's own stamps (joint_4 / joint_6 by their sum in the
wrist band), at most 0.05 deg from the goal at the end (the same rule).

This is the driver's part of those figures with the timing of every process exact (the bench runs
the same goals in real time: real processes, ptys, the virtual line; bench/README.md). Ten of the
twelve meet every target. Two ask what no arm that keeps its accelerations can do: the shortest
goal's plan (0.32 s, joint_6 at up to 300 deg/s) joined by straight lines stops joint_6 from 162
deg/s at once at its last point, and no arm within the model's accelerations comes within 0.75 deg
of that at any start delay (:mod:`vr_driver.driver.joints.following`); at the 0.5 s ramp its corners keep
any such arm 0.51 deg away. (The virtual arm is not quite such an arm: its blends and its moves
shorter than its ramp change speed faster than its ramp, as documented in
:mod:`vr_driver.controller.stream_arm`.) For those two the deviation is held to FLOOR_FACTOR times
that floor, and the test says so if the floor drops under the target. Goal 5 (onto joint_5 = 0)
was 0.51 deg at the model's ramp while the stream's feed shifted every point as needed from the first
(0.52 -> 0.42 deg since the stream holds at its start and then keeps the plan's timing:
stream_points.fed_schedule; the twelve 0.28-1.15 -> 0.26-0.93 deg).
Which records the driver sees (a 55 ms bus cycle) decides how much of a deviation shows: the same
runs started 30 ms later measured 0.76 deg for the first."""
from __future__ import annotations

import json
import math
import os

import pytest

from vr_driver.driver.joints.following import following_floor
from vr_driver.driver.joints.supervision import SUCCEEDED
from vr_driver.driver.motion.trajectories import SUCCESSFUL

from _paced import PacedWorld
from test_wire_supervision_stepped import supervise, validated

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "wrist_goals_seed1.json")
DEG = math.pi / 180.0
MAX_DEVIATION = 0.5 * DEG
MAX_FINAL = 0.05 * DEG
TIME_FACTOR, TIME_SLACK = 1.10, 0.3
#: the bench's configurations: the arm's ramp [s] (None: the model's)
RAMPS = {"v3-paced": None, "v3-paced-ramp05": 0.5}


def goal_sets():
    with open(DATA, encoding="utf-8") as fh:
        doc = json.load(fh)
    return [(s["configuration"], g) for s in doc["sets"] for g in s["goals"]]


def final_error(rule, q, goal) -> float:
    """The largest joint error at the end; where ``rule`` (the trajectory's per-configuration
    tolerances, as the driver judges) puts the arm or the goal in the wrist band, joint_4 and
    joint_6 by the sum the pose fixes."""
    errors = [abs(a - b) for a, b in zip(q, goal)]
    if rule.in_band(goal) or rule.in_band(q):
        four, _bend, six = rule.wrist
        errors[four] = errors[six] = abs(rule.sum_of(q) - rule.sum_of(goal))
    return max(errors)


def run_goal(kin, configuration, goal, **world_options):
    times, points = goal["times"], [tuple(p) for p in goal["points"]]
    world = PacedWorld(kin, protocol="v3", initial_pose=kin.fk_pose(points[0]),
                       ramp_time=RAMPS[configuration], **world_options)
    world.ready()
    world.run_for(0.5)
    traj = validated(world, times[1:], points[1:])
    sup, out = supervise(world, traj)
    return world, traj, sup.run.jobs[0], out


#: (configuration, goal): why it misses a target today (the deviation: see the module docstring)
KNOWN_GAPS: dict = {}
#: (configuration, goal) whose plan no arm with the arm's accelerations follows within MAX_DEVIATION
#: (driver.joints.following.following_floor): their deviation is held to FLOOR_FACTOR x that floor
BEYOND_ANY_ARM = {("v3-paced", 1), ("v3-paced-ramp05", 1)}
FLOOR_FACTOR = 1.6


def floor_of(kin, configuration, goal, traj):
    """(floor [rad], where): the least deviation any arm with the configuration's accelerations can
    have from the goal's plan, judged by the driver's band rule."""
    ramp = RAMPS[configuration]
    acc = kin.limits.acceleration if ramp is None else [v / ramp for v in kin.limits.velocity]
    tolerances = traj.per_configuration
    return following_floor(goal["times"], goal["points"], acc, band=tolerances.band, sign=tolerances.sign)


def cases():
    out = []
    for c, g in goal_sets():
        gap = KNOWN_GAPS.get((c, g["index"]))
        marks = [pytest.mark.xfail(reason=gap, strict=True)] if gap else []
        out.append(pytest.param(c, g, id="%s-%d" % (c, g["index"]), marks=marks))
    return out


@pytest.mark.parametrize("configuration, goal", cases())
def test_the_bench_wrist_goal_meets_the_targets(kin, configuration, goal):
    world, traj, job, out = run_goal(kin, configuration, goal)
    assert (out.state, out.error_code) == (SUCCEEDED, SUCCESSFUL), out.error_string
    assert job.gaps == 0, "the look-ahead ran dry %d times" % job.gaps
    assert out.elapsed <= TIME_FACTOR * traj.duration + TIME_SLACK, (out.elapsed, traj.duration)
    floor, where = floor_of(kin, configuration, goal, traj)
    limit = MAX_DEVIATION
    if (configuration, goal["index"]) in BEYOND_ANY_ARM:
        assert floor > MAX_DEVIATION, (
            "the plan's floor is %.3f deg (%s): under the target, judge this goal by it again"
            % (math.degrees(floor), where))
        limit = FLOOR_FACTOR * floor
    assert out.max_delayed_deviation <= limit, (
        "%.3f deg from the plan at the same time (start delay %.3f s; no arm comes closer than %.3f deg: %s)"
        % (math.degrees(out.max_delayed_deviation), out.start_delay, math.degrees(floor), where))
    end = final_error(traj.per_configuration, world.status().joints, goal["points"][-1])
    assert end <= MAX_FINAL, "%.4f deg from the goal at the end" % math.degrees(end)


def test_the_checks_can_fail_a_g2_without_look_ahead(kin):
    """The same goal on a G2 whose interpreter reads no MOVE ahead stops at every point: the time or
    the deviation above says so."""
    configuration, goal = next((c, g) for c, g in goal_sets() if c == "v3-paced" and g["index"] == 2)
    _world, traj, _job, out = run_goal(kin, configuration, goal, interpreter_lookahead=0)
    assert out.max_delayed_deviation > MAX_DEVIATION or out.elapsed > TIME_FACTOR * traj.duration + TIME_SLACK, \
        (math.degrees(out.max_delayed_deviation), out.elapsed)
