"""vr_driver.kinematics.planner: collision-aware planning (OMPL), timing (TOPP-RA), the checks of the
result, and the driver's own trajectory validation of what it plans. Skipped, with the reason,
where OMPL or TOPP-RA is missing (the cell test also needs pinocchio and coal)."""
from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from vr_driver.driver.motion.trajectories import TrajectoryGoal, segment_speeds, validate
from vr_driver.errors import MissingDependency, MotionError
from vr_driver.kinematics import deps
from vr_driver.kinematics.planner import PLANNERS, Planner, PlanningError

_MISSING = deps.missing_dependencies(("ompl", "toppra"))
pytestmark = pytest.mark.skipif(bool(_MISSING), reason="; ".join(r for _, r in _MISSING))

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
REPO = os.path.dirname(os.path.dirname(SRC))
CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")

START = (-1.0, 0.3, -0.3, 0.0, 0.4, 0.0)
GOAL = (1.0, 0.3, -0.3, 0.0, 0.4, 0.0)


def wall(q):
    """A joint-space obstacle between START and GOAL: joint_1 in (-0.3, 0.3) with joint_2 below 1.2
    rad (the arm must lift its upper arm to pass)."""
    return not (-0.3 < q[0] < 0.3 and q[1] < 1.2)


def chords_valid(plan, is_valid, step=math.radians(0.1)):
    """Every sample and every point of the straight chords between samples, 0.1 deg apart (finer
    than the planner's own checks): the first invalid configuration, or None."""
    for a, b in zip(plan.positions, plan.positions[1:]):
        n = max(1, int(math.ceil(max(abs(x - y) for x, y in zip(a, b)) / step)))
        for k in range(n + 1):
            q = tuple(x + (y - x) * k / n for x, y in zip(a, b))
            if not is_valid(q):
                return q
    return None


@pytest.fixture(scope="module")
def walled(kin):
    return Planner(kin, wall, seed=7)


@pytest.fixture(scope="module")
def around(walled):
    return walled.plan(START, GOAL)


# ------------------------------------------------------------------------------------------ paths

def test_plans_around_a_joint_space_obstacle(walled, around):
    assert walled.motion_valid(START, GOAL) is not None          # the straight move crosses the wall
    assert around.positions[0] == START and around.positions[-1] == GOAL
    assert around.times[0] == 0.0 and around.duration > 0.9      # 2 rad of joint_1 at <= 2.09 rad/s
    assert chords_valid(around, wall) is None
    assert max(q[1] for q in around.positions) >= 1.2            # it went over the wall
    assert around.planner == "RRTConnect" and around.timings["plan"] > 0.0


def test_the_sampled_result_keeps_the_limits(kin, around):
    lim = kin.limits
    vmax, amax = np.array(lim.velocity), np.array(lim.acceleration)
    pos, vel, acc = np.array(around.positions), np.array(around.velocities), np.array(around.accelerations)
    times = np.array(around.times)
    assert np.all(pos >= np.array(lim.lower) - 1e-9) and np.all(pos <= np.array(lim.upper) + 1e-9)
    assert np.all(np.abs(vel) <= vmax * (1 + 1e-6)) and np.all(np.abs(acc) <= amax * (1 + 1e-6))
    dt = np.diff(times)
    assert np.all(dt > 0) and dt.max() <= 0.05 + 1e-12
    assert np.all(np.abs(np.diff(pos, axis=0)) <= dt[:, None] * vmax * (1 + 1e-9))
    # finite differences agree with the reported velocities (the samples are one trajectory)
    mid = (pos[2:] - pos[:-2]) / (times[2:] - times[:-2])[:, None]
    assert np.max(np.abs(mid - vel[1:-1])) < 0.1 * vmax.max()
    assert np.all(vel[0] == 0.0) and np.all(vel[-1] == 0.0)
    # time-optimal: some joint reaches (nearly) its speed or acceleration limit
    assert max(np.max(np.abs(vel) / vmax), np.max(np.abs(acc) / amax)) > 0.9


def test_velocity_scaling_slows_the_plan_within_the_scaled_limits(kin, walled, around):
    slow = walled.plan(START, GOAL, velocity_scaling=0.5)
    vmax = np.array(kin.limits.velocity)
    assert np.all(np.abs(np.array(slow.velocities)) <= 0.5 * vmax * (1 + 1e-6))
    assert slow.duration > 1.5 * around.duration
    assert chords_valid(slow, wall) is None


def test_a_seed_gives_one_plan_and_another_seed_another(kin, walled, around):
    again = Planner(kin, wall, seed=7).plan(START, GOAL)
    assert again.positions == around.positions and again.times == around.times
    assert walled.plan(START, GOAL).path == around.path
    other = [walled.plan(START, GOAL, seed=s).path for s in (1, 2, 3)]
    assert any(p != around.path for p in other)


def test_a_free_straight_move_is_one_segment(kin):
    plan = Planner(kin, None, seed=1).plan(START, GOAL)
    assert plan.path == (START, GOAL)
    for q in plan.positions:                                     # on the straight line
        f = (q[0] - START[0]) / (GOAL[0] - START[0])
        assert max(abs(a + f * (b - a) - v) for a, b, v in zip(START, GOAL, q)) < 1e-6


def chord_distance(positions, q):
    """[rad] how near the straight chords between ``positions`` come to ``q`` (the largest joint
    difference at the point of each chord nearest it)."""
    best = math.inf
    for a, b in zip(positions, positions[1:]):
        d = [y - x for x, y in zip(a, b)]
        norm = sum(v * v for v in d)
        f = 0.0 if norm == 0.0 else min(1.0, max(0.0, sum((c - x) * v for c, x, v in zip(q, a, d)) / norm))
        best = min(best, max(abs(x + f * v - c) for x, v, c in zip(a, d, q)))
    return best


def test_a_plan_through_waypoints_passes_each_in_order(kin):
    """``via``: the path goes through each waypoint in turn (each leg planned, here straight), the
    timing through them too; a waypoint in collision or outside the limits is refused naming it."""
    mid = tuple((a + b) / 2.0 + (0.3 if i == 1 else 0.0) for i, (a, b) in enumerate(zip(START, GOAL)))
    plan = Planner(kin, None, seed=1).plan(START, GOAL, via=[mid])
    assert plan.path == (START, mid, GOAL)
    # what the driver runs, the chords between the samples, passes the waypoint (a sample need not
    # fall on it: the timing passes the corner at speed, its chord cuts it by a fraction of a degree)
    assert chord_distance(plan.positions, mid) < math.radians(0.5)
    assert max(q[1] for q in plan.positions) >= mid[1] - math.radians(0.5)     # not the straight line
    # around the wall: the legs are planned, the waypoint on the far side of it is passed
    over = (START[0] / 2.0, 1.3) + tuple(START[2:])
    plan = Planner(kin, wall, seed=7).plan(START, GOAL, via=[over])
    assert over in plan.path and chords_valid(plan, wall) is None
    with pytest.raises(PlanningError, match=r"waypoint 1 \(0\.0, .*\) deg is in collision") as info:
        Planner(kin, wall).plan(START, GOAL, via=[(0.0, 0.3, -0.3, 0.0, 0.4, 0.0)])
    assert info.value.step == "plan"
    with pytest.raises(PlanningError, match=r"waypoint 2 .* outside the joint limits"):
        Planner(kin, wall).plan(START, GOAL, via=[over, (-1.0, 0.3, 2.0, 0.0, 0.4, 0.0)])


def test_two_plans_joined_with_a_hold(kin):
    """PlannedTrajectory.then: the first at rest at its end for ``hold`` (its end's sample again),
    then the second, which must start there."""
    planner = Planner(kin, None, seed=1)
    mid = tuple((a + b) / 2.0 for a, b in zip(START, GOAL))
    first, second = planner.plan(START, mid), planner.plan(mid, GOAL)
    both = first.then(second, 0.25)
    n = len(first.times)
    assert both.positions == first.positions + second.positions
    assert both.times[:n] == first.times and both.times[n] == pytest.approx(first.duration + 0.25)
    assert both.duration == pytest.approx(first.duration + 0.25 + second.duration)
    assert both.path == first.path + second.path[1:] and both.goal == GOAL
    with pytest.raises(ValueError, match="not where the first ends"):
        first.then(first, 0.25)
    with pytest.raises(ValueError, match="hold must be > 0"):
        first.then(second, 0.0)


def test_start_equal_to_goal_is_one_point(kin):
    plan = Planner(kin, wall, seed=1).plan(START, START)
    assert plan.positions == (START,) and plan.times == (0.0,) and plan.duration == 0.0


@pytest.mark.parametrize("eps", [4e-7, 3e-6, 5e-5])
def test_a_tiny_move_is_timed_rest_to_rest_within_the_limits(kin, eps):
    """TOPP-RA's grid finds no timing for a move of 1e-6 .. 1e-5 rad (an arm reported at home is
    4e-7 rad from the SRDF's home): such a move is timed in closed form."""
    start = tuple(v + eps for v in kin.named_states["home"])
    plan = Planner(kin, None, seed=1).plan(start, "home")
    assert plan.positions[0] == start and plan.positions[-1] == tuple(kin.named_states["home"])
    assert plan.velocities[0] == plan.velocities[-1] == (0.0,) * 6
    lim = kin.limits
    for v, a in zip(plan.velocities, plan.accelerations):
        assert all(abs(x) <= m + 1e-12 for x, m in zip(v, lim.velocity))
        assert all(abs(x) <= m * (1 + 1e-9) for x, m in zip(a, lim.acceleration))
    assert list(plan.times) == sorted(plan.times) and plan.duration > 0.0


# ---------------------------------------------------------------------------------------- goals

def test_named_state_goal_ends_at_the_srdf_state(kin):
    plan = Planner(kin, lambda q: q[0] < 0.5, seed=1).plan(START, "home")
    assert plan.goal == tuple(kin.named_states["home"])
    with pytest.raises(PlanningError, match=r"unknown named state 'nowhere'.*home.*zero"):
        Planner(kin, wall).plan(START, "nowhere")


def test_pose_goal_takes_the_nearest_ik_branch(kin):
    q_goal = (0.4, 0.6, -0.5, 0.8, 0.7, -0.3)
    target = kin.fk(q_goal)
    plan = Planner(kin, None, seed=1).plan(START, target)
    assert np.allclose(plan.goal, q_goal, atol=1e-6)             # the branch nearest the start
    assert np.allclose(kin.fk(plan.goal), target, atol=1e-6)
    # the same goal as a controller pose (mm / deg) and as position + quaternion
    pose = kin.fk_pose(q_goal)
    assert np.allclose(Planner(kin, None, seed=1).plan(START, pose).goal, q_goal, atol=1e-4)
    from vr_driver.poses import matrix_to_ros
    assert np.allclose(Planner(kin, None, seed=1).plan(START, matrix_to_ros(target)).goal, q_goal, atol=1e-6)


def test_pose_goal_skips_branches_in_collision_for_the_nearest_valid_one(kin):
    q_goal = (0.4, 0.6, -0.5, 0.8, 0.7, -0.3)
    target = kin.fk(q_goal)
    branches = kin.ik_solutions(target, seed=START)

    def not_near_goal(q):                                        # the nearest branch is blocked
        return max(abs(a - b) for a, b in zip(q, q_goal)) > 0.2

    planner = Planner(kin, not_near_goal, seed=1)
    plan = planner.plan(START, target)
    valid = [q for q in branches if not_near_goal(q)]
    nearest = min(valid, key=lambda q: max(abs(a - b) / v for a, b, v in zip(START, q, kin.limits.velocity)))
    assert np.allclose(plan.goal, nearest, atol=1e-9)
    assert np.allclose(kin.fk(plan.goal), target, atol=1e-6)
    assert chords_valid(plan, not_near_goal) is None


def test_ik_solutions_are_every_branch_and_wrist_turn(kin):
    q = (0.3, 0.5, -0.4, 0.7, 0.8, -0.2)
    sols = kin.ik_solutions(kin.fk(q), seed=q)
    assert np.allclose(sols[0], q, atol=1e-9)                    # the seed's own branch first
    assert len(sols) > 8                                         # 8 branches, and wrist turns
    assert len({tuple(np.round(s, 6)) for s in sols}) == len(sols)
    for s in sols:
        assert not kin.limit_violations(s)
        assert np.allclose(kin.fk(s), kin.fk(q), atol=1e-6)
    dist = [sum((a - b) ** 2 for a, b in zip(s, q)) for s in sols]
    assert dist == sorted(dist)
    # joint_6 spans 4 pi: its other full turn is among them
    assert any(abs(s[5] - (q[5] + 2 * math.pi)) < 1e-6 and np.allclose(s[:5], q[:5]) for s in sols)


def test_joint_weights_bound_how_far_the_arm_moves(kin):
    """The motion-check resolution rests on it: a joint move dq moves tool0 (and any point of the
    arm) by at most sum_i w_i |dq_i|."""
    import random
    from vr_driver.kinematics.planner import joint_weights
    w = joint_weights(kin)
    assert len(w) == 6 and w[0] > w[1] > w[2] > w[3] > w[4] == w[5] > 0.3
    rng = random.Random(4)
    worst = 0.0
    for _ in range(300):
        q = kin.random_joints(rng)
        dq = [rng.uniform(-0.05, 0.05) for _ in range(6)]
        moved = np.linalg.norm(kin.fk([a + b for a, b in zip(q, dq)])[:3, 3] - kin.fk(q)[:3, 3])
        worst = max(worst, moved / sum(wi * abs(d) for wi, d in zip(w, dq)))
    assert 0.2 < worst < 1.0


# --------------------------------------------------------------------------------------- errors

def test_start_in_collision_is_refused(kin):
    with pytest.raises(PlanningError, match=r"start \(0\.0, .*\) deg is in collision") as info:
        Planner(kin, wall).plan((0.0, 0.3, -0.3, 0.0, 0.4, 0.0), GOAL)
    assert info.value.step == "start" and isinstance(info.value, MotionError)


def test_start_outside_the_limits_is_refused(kin):
    with pytest.raises(PlanningError, match=r"start .* outside the joint limits: joint_3 = 2\.0000"):
        Planner(kin, wall).plan((-1.0, 0.3, 2.0, 0.0, 0.4, 0.0), GOAL)


def test_goal_in_collision_is_refused(kin):
    with pytest.raises(PlanningError, match=r"goal \(0\.0, .*\) deg is in collision") as info:
        Planner(kin, wall).plan(START, (0.0, 0.3, -0.3, 0.0, 0.4, 0.0))
    assert info.value.step == "goal"


def test_pose_goal_all_in_collision_or_unreachable_is_refused(kin):
    target = kin.fk((0.4, 0.6, -0.5, 0.8, 0.7, -0.3))
    branches = kin.ik_solutions(target)

    def blocked(q):                                              # every branch, and near it
        return min(max(abs(a - b) for a, b in zip(q, s)) for s in branches) > 0.1

    with pytest.raises(PlanningError, match=r"all %d joint solutions of the goal pose are in collision; the "
                       r"nearest, \(" % len(branches)):
        Planner(kin, blocked).plan(START, target)
    far = np.eye(4)
    far[:3, 3] = (3.0, 0.0, 0.5)
    with pytest.raises(PlanningError, match="goal pose unreachable"):
        Planner(kin, wall).plan(START, far)


def test_no_path_within_the_budget_is_refused(kin):
    def caged(q):                                                # the goal is valid, enclosed by a shell
        d = max(abs(a - b) for a, b in zip(q, GOAL))
        return not 0.05 < d < 0.15

    with pytest.raises(PlanningError, match=r"RRTConnect found no path within 0\.2 s") as info:
        Planner(kin, caged, time_budget=0.2, seed=1).plan(START, GOAL)
    assert info.value.step == "plan"
    # through a waypoint the first leg reaches straight: the last leg searches for what it left of
    # the budget (nearly all), not for a fixed half of it
    mid = tuple(a + 0.2 * (b - a) for a, b in zip(START, GOAL))
    with pytest.raises(PlanningError, match=r"RRTConnect found no path within 0\.(39|4)\d* s"):
        Planner(kin, caged, time_budget=0.4, seed=1).plan(START, GOAL, via=[mid])
    # the first leg the only one to search (into the cage; on from there straight): all of the budget
    inside = [tuple(g + d * (1 if i == 1 else 0) for i, g in enumerate(GOAL)) for d in (0.03, -0.03)]
    with pytest.raises(PlanningError, match=r"RRTConnect found no path within 0\.(39|4)\d* s .* to \(%.1f, %.1f"
                       % tuple(math.degrees(v) for v in inside[0][:2])):
        Planner(kin, caged, time_budget=0.4, seed=1).plan(START, GOAL, via=inside)


def test_bad_parameters_are_refused(kin):
    with pytest.raises(PlanningError, match="unknown planner 'RRTFast': the planners are RRTConnect, RRT, "):
        Planner(kin, wall, planner="RRTFast")
    with pytest.raises(ValueError, match="velocity_scaling"):
        Planner(kin, wall, velocity_scaling=1.5)
    with pytest.raises(ValueError, match="time_budget"):
        Planner(kin, wall, time_budget=0)
    with pytest.raises(TypeError, match="validity must be"):
        Planner(kin, 42)


@pytest.mark.parametrize("name", ["RRT", "BKPIECE1"])
def test_other_planners_by_name(kin, name):
    plan = Planner(kin, wall, planner=name, time_budget=2.0, seed=3).plan(START, GOAL)
    assert plan.planner == name and chords_valid(plan, wall) is None
    assert set(PLANNERS) >= {"RRTConnect", name}


# ------------------------------------------------------------------------- the driver's own checks

def test_the_driver_validation_accepts_the_plan(kin, around):
    traj = validate(TrajectoryGoal.of(around), kin.joint_names, around.start, kin.limits.lower, kin.limits.upper, now=0.0)
    assert traj.positions == around.positions and traj.times == around.times
    speeds = segment_speeds(traj, kin.limits.velocity, kin.joint_names)
    assert max(speeds) <= 1.0 and max(speeds) > 0.5


def test_converts_to_a_joint_trajectory_message(around):
    class Msg:
        def __init__(self, **kw):
            self.__dict__.update(kw)

    msg = around.to_msg(Msg, Msg, lambda t: ("dur", t))
    assert msg.joint_names == list(around.joint_names)
    assert len(msg.points) == len(around.times)
    last = msg.points[-1]
    assert last.positions == list(around.goal) and last.time_from_start == ("dur", around.duration)
    assert last.velocities == [0.0] * 6 and len(last.accelerations) == 6


def test_converts_to_a_real_joint_trajectory_message(around):
    msgs = pytest.importorskip("trajectory_msgs.msg")
    genpy = pytest.importorskip("genpy")
    import io
    msg = around.to_msg(msgs.JointTrajectory, msgs.JointTrajectoryPoint, genpy.Duration.from_sec)
    buf = io.BytesIO()
    msg.serialize(buf)                                           # the types are right
    back = msgs.JointTrajectory().deserialize(buf.getvalue())
    assert tuple(back.joint_names) == around.joint_names
    assert [p.time_from_start.to_sec() for p in back.points] == pytest.approx(around.times, abs=1e-9)
    assert tuple(back.points[-1].positions) == around.goal


# ------------------------------------------------------------- the parts: OMPL's search, the timing

def test_the_ompl_search_alone_finds_one_path_a_seed_and_says_why_it_found_none(kin):
    """kinematics.plan_search: a seeded search around the wall gives one valid path from START to
    GOAL (in joints); a search that cannot finish in time returns None with OMPL's status."""
    import importlib
    from vr_driver.kinematics.plan_search import OmplSearch
    from vr_driver.kinematics.planner import joint_weights
    ompl = tuple(importlib.import_module(m) for m in ("ompl.base", "ompl.geometric", "ompl.util"))
    lim = kin.limits

    def search(validity, seed):
        return OmplSearch(ompl, joint_weights(kin), lim.lower, lim.upper, 0.02, validity, seed)

    first = search(wall, 7)
    path = first.simplified(first.solve("RRTConnect", START, [GOAL], 5.0))
    assert np.allclose(path[0], START, atol=1e-12) and np.allclose(path[-1], GOAL, atol=1e-12)
    assert len(path) > 2 and max(q[1] for q in path) >= 1.2      # over the wall, not through it
    again = search(wall, 7)
    assert again.simplified(again.solve("RRTConnect", START, [GOAL], 5.0)) == path

    def caged(q):                                                # the goal is valid, enclosed by a shell
        return not 0.05 < max(abs(a - b) for a, b in zip(q, GOAL)) < 0.15

    walled_in = search(caged, 1)
    assert walled_in.solve("RRTConnect", START, [GOAL], 0.05) is None
    assert walled_in.status in ("Approximate solution", "Timeout")   # no exact one: none


def test_bisection_order_visits_each_inner_step_once_middle_first():
    from vr_driver.kinematics.plan_search import bisection_order
    for n in range(0, 40):
        order = bisection_order(n)
        assert sorted(order) == list(range(1, n)), n
    assert bisection_order(8)[:3] == (4, 2, 6)


def test_bisection_order_and_the_motion_fractions_are_the_span_by_span_bisection():
    """The numpy bisection (a level at a time) visits in the order of the span-by-span one, and a
    motion's fractions are the end, then k / n in that order, the same floats."""
    from vr_driver.kinematics.plan_search import bisection_order, motion_fractions

    def by_spans(n):
        out, spans = [], [(0, n)]
        while spans:
            later = []
            for lo, hi in spans:
                if hi - lo >= 2:
                    mid = (lo + hi) // 2
                    out.append(mid)
                    later += [(lo, mid), (mid, hi)]
            spans = later
        return tuple(out)
    for n in list(range(0, 300)) + [1023, 1024, 1025, 4097]:
        assert bisection_order(n) == by_spans(n), n
        assert motion_fractions(n).tolist() == [1.0] + [k / n for k in by_spans(n)], n
    assert not motion_fractions(5).flags.writeable


def test_the_rope_shortcut_pulls_the_path_over_the_wall_tighter(kin, monkeypatch):
    """OmplSearch.simplified with the rope shortcut (ROPE_SPACING): the paths over the wall of ten
    seeded searches are valid (their vertices) and, in the scaled space the planner measures in, shorter than the
    rounds of vertex and partial shortcuts leave them without it -- nearer the shortest way, over
    the wall's two corners (joint_1 -0.3 and 0.3 at joint_2 1.2)."""
    import importlib
    from vr_driver.kinematics import plan_search
    from vr_driver.kinematics.plan_search import OmplSearch
    from vr_driver.kinematics.planner import joint_weights
    ompl = tuple(importlib.import_module(m) for m in ("ompl.base", "ompl.geometric", "ompl.util"))
    lim, w = kin.limits, np.array(joint_weights(kin))

    def length(path):
        return sum(float(np.linalg.norm((np.array(b) - np.array(a)) * w)) for a, b in zip(path, path[1:]))
    shortest = length([START, (-0.3, 1.2) + START[2:], (0.3, 1.2) + START[2:], GOAL])

    def lengths():
        out = []
        for seed in range(1, 11):
            search = OmplSearch(ompl, w, lim.lower, lim.upper, 0.02, wall, seed, sweep_motions=True)
            path = search.simplified(search.solve("RRTConnect", START, [GOAL], 5.0))
            # (its motions are valid at the sweep validator's resolution: pulled tight along the
            # wall's corner, one may cut it by less than that between two checked states -- what
            # the planner's clearance is for)
            assert all(wall(q) for q in path)
            out.append(length(path) / shortest)
        return out
    roped = lengths()
    monkeypatch.setattr(plan_search, "ROPE_SPACING", None)
    plain = lengths()
    assert min(roped) >= 1.0 - 1e-9
    assert sum(roped) < 0.95 * sum(plain), (roped, plain)
    assert float(np.median(roped)) < float(np.median(plain))


def test_the_sweep_validator_checks_each_motion_at_the_sweep_and_fewer_states(kin):
    """OmplSearch with ``sweep_motions``: every motion OMPL asks about (search and simplification)
    is checked at states whose sweep bound sum_i w_i |dq_i| is at most max_sweep apart -- never more
    (the guarantee), and about the bound itself, not sqrt(n) times finer as OMPL's resolution --
    and the path found around the wall is valid; OMPL's own validator asks for more states."""
    import importlib
    from vr_driver.kinematics.plan_search import OmplSearch
    from vr_driver.kinematics.planner import joint_weights
    ompl = tuple(importlib.import_module(m) for m in ("ompl.base", "ompl.geometric", "ompl.util"))
    lim, w = kin.limits, joint_weights(kin)
    seen = []

    def counted(q):
        seen.append(q)
        return wall(q)

    sweep = OmplSearch(ompl, w, lim.lower, lim.upper, 0.02, counted, 7, sweep_motions=True)
    assert sweep.sweep_motions
    path = sweep.simplified(sweep.solve("RRTConnect", START, [GOAL], 5.0))
    assert sweep.counts["motions"] > 0 and sweep.counts["states"] >= sweep.counts["motions"]
    for a, b in zip(path, path[1:]):              # the simplified path: valid at 0.1 deg
        n = max(1, int(math.ceil(max(abs(x - y) for x, y in zip(a, b)) / math.radians(0.1))))
        assert all(wall(tuple(x + (y - x) * k / n for x, y in zip(a, b))) for k in range(n + 1))
    checks_sweep = len(seen)
    # one motion by hand: the states checked lie at most max_sweep apart by the sweep bound
    seen.clear()
    si = sweep.si
    s1, s2 = sweep._state(START), sweep._state((-0.5, 0.6, -0.1, 0.3, 0.2, -0.4))
    assert si.checkMotion(s1, s2)
    f = sorted(sum(wi * abs(x - y) for wi, x, y in zip(w, q, START)) for q in seen)
    whole = sum(wi * abs(x - y) for wi, x, y in zip(w, START, (-0.5, 0.6, -0.1, 0.3, 0.2, -0.4)))
    gaps = [b - a for a, b in zip([0.0] + f, f)]
    assert max(gaps) <= 0.02 + 1e-12 and abs(f[-1] - whole) < 1e-9 and len(seen) == math.ceil(whole / 0.02)
    # OMPL's own resolution (|dx| <= max_sweep / sqrt(n)) asks for more states on the same search
    seen.clear()
    own = OmplSearch(ompl, w, lim.lower, lim.upper, 0.02, counted, 7)
    assert not own.sweep_motions
    own.simplified(own.solve("RRTConnect", START, [GOAL], 5.0))
    assert len(seen) > checks_sweep, (len(seen), checks_sweep)


def test_a_retry_planners_motions_are_checked_at_the_sweep_bound_or_finer(kin):
    """LBKPIECE1 (the plan action's retry planner) is not in SWEEP_VALIDATED: it asks OMPL how far a
    motion is valid, which the sweep validator does not answer. OMPL's own validator, which it then
    uses, checks a motion at the resolution OmplSearch sets, |dx| <= max_sweep / sqrt(n) in the
    scaled space: on random motions the states it checks lie at most max_sweep apart by the sweep
    bound too (never fewer than the sweep validator's), the end included. And the planner checks every
    motion of the simplified path at the sweep bound itself (a LBKPIECE1 plan round the wall)."""
    import importlib
    from vr_driver.kinematics.plan_search import SWEEP_VALIDATED, OmplSearch
    from vr_driver.kinematics.planner import joint_weights
    assert "LBKPIECE1" not in SWEEP_VALIDATED
    ompl = tuple(importlib.import_module(m) for m in ("ompl.base", "ompl.geometric", "ompl.util"))
    lim, w = kin.limits, joint_weights(kin)
    seen = []

    def counted(q):
        seen.append(q)
        return True
    own = OmplSearch(ompl, w, lim.lower, lim.upper, 0.02, counted, 7)
    assert not own.sweep_motions
    rng = np.random.default_rng(4)
    lo, hi = np.array(lim.lower), np.array(lim.upper)
    for _ in range(40):
        a, b = lo + rng.random(6) * (hi - lo), lo + rng.random(6) * 0.3 * (hi - lo)
        seen.clear()
        assert own.si.checkMotion(own._state(a), own._state(b))
        whole = float(np.abs(b - a) @ w)
        f = sorted(float(np.abs(np.asarray(q) - a) @ w) for q in seen)
        assert max(y - x for x, y in zip([0.0] + f, f)) <= 0.02 + 1e-9 and abs(f[-1] - whole) < 1e-9
        assert len(seen) >= math.ceil(whole / 0.02)
    planner = Planner(kin, wall, planner="LBKPIECE1", seed=3, time_budget=5.0)
    plan = planner.plan(START, GOAL)
    assert len(plan.path) > 2 and all(planner.motion_valid(x, y) is None for x, y in zip(plan.path, plan.path[1:]))


def test_the_timing_alone_keeps_the_scaled_limits_from_rest_to_rest(kin):
    """kinematics.plan_timing: a path with a corner, timed at half speed and a quarter of the
    acceleration, sampled evenly every <= dt; it ends where the path ends, at rest."""
    import toppra
    from vr_driver.kinematics.plan_timing import PathTiming
    lim = kin.limits
    path = [START, (0.0, 1.3, -0.3, 0.0, 0.4, 0.0), GOAL]
    times, pos, vel, acc = PathTiming(toppra, lim.velocity, lim.acceleration).time(path, 0.5, 0.25, 0.05, 0.05)
    assert pos[0] == START and pos[-1] == GOAL and vel[0] == vel[-1] == (0.0,) * 6
    dt = np.diff(times)
    assert times[0] == 0.0 and dt.max() <= 0.05 + 1e-12 and np.allclose(dt, dt[0])
    vmax, amax = 0.5 * np.array(lim.velocity), 0.25 * np.array(lim.acceleration)
    assert np.all(np.abs(vel) <= vmax * (1 + 1e-9)) and np.all(np.abs(acc) <= amax * (1 + 1e-9))
    assert max(np.max(np.abs(vel) / vmax), np.max(np.abs(acc) / amax)) > 0.9     # time-optimal: near a limit


def test_a_straight_move_is_timed_in_closed_form_as_toppra_times_it(kin):
    """kinematics.plan_timing: a path of two points (one straight joint move) is timed in closed
    form -- within 0.5 % of TOPP-RA's duration for the same line (given as three collinear points,
    which go through TOPP-RA), every sample on the line and within the scaled limits, a limit
    reached (time-optimal), from rest to rest, samples every <= dt; short moves that never reach
    the speed limit (a triangle) and long ones (with a cruise) both occur."""
    import random
    import toppra
    from vr_driver.kinematics.plan_timing import PathTiming
    lim = kin.limits
    timing = PathTiming(toppra, lim.velocity, lim.acceleration)
    rng = random.Random(4)
    cruised = set()
    for k in range(30):
        a = np.array(kin.random_joints(rng))
        b = a + (np.array(kin.random_joints(rng)) - a) * (0.02 if k % 3 == 0 else 1.0)
        vs = rng.choice((1.0, 0.5, 0.1))
        times, pos, vel, acc = timing.time([tuple(a), tuple(b)], vs, vs, 0.05, 0.05)
        toppra_times = timing.time([tuple(a), tuple((a + b) / 2.0), tuple(b)], vs, vs, 0.05, 0.05)[0]
        assert times[-1] == pytest.approx(toppra_times[-1], rel=5e-3)
        assert pos[0] == tuple(a) and pos[-1] == tuple(b) and vel[0] == vel[-1] == (0.0,) * 6
        dt = np.diff(times)
        assert times[0] == 0.0 and dt.max() <= 0.05 + 1e-12 and np.allclose(dt, dt[0])
        along = (np.array(pos) - a) @ (b - a) / ((b - a) @ (b - a))
        assert np.allclose(np.array(pos), a + along[:, None] * (b - a), atol=1e-12)
        assert np.all(np.diff(along) > 0.0)
        vmax, amax = vs * np.array(lim.velocity), vs * np.array(lim.acceleration)
        assert np.all(np.abs(vel) <= vmax) and np.all(np.abs(acc) <= amax)
        assert max(np.max(np.abs(vel) / vmax), np.max(np.abs(acc) / amax)) > 0.96
        cruised.add(bool(np.any(np.all(np.array(acc) == 0.0, axis=1)[1:-1])))
    assert cruised == {True, False}


def test_a_timing_failure_is_the_planner_s_error_of_the_step_time(kin, monkeypatch):
    from vr_driver.kinematics.plan_timing import TimingError
    planner = Planner(kin, None, seed=1)

    def no_timing(*args):
        raise TimingError("TOPP-RA found no timing of the path under the speed and acceleration limits")

    monkeypatch.setattr(planner._timing, "time", no_timing)
    with pytest.raises(PlanningError, match="^TOPP-RA found no timing of the path") as info:
        planner.plan(START, GOAL)
    assert info.value.step == "time"


# ---------------------------------------------------------------------------- the example cell

@pytest.fixture(scope="module")
def cell_checker():
    missing = deps.missing_dependencies(("pinocchio", "coal"))
    if missing:
        pytest.skip("; ".join(r for _, r in missing))
    from vr_driver.kinematics.collision import CollisionChecker
    from vr_driver.kinematics.scene import load_scene
    return CollisionChecker.default(scene=load_scene(CELL), padding=0.0)


def test_plans_around_the_pillar_of_the_example_cell(kin, cell_checker):
    """Home, then joint_1 to the left with the arm stretched out: the pillar stands in the way."""
    home = tuple(kin.named_states["home"])
    start = (-0.3,) + home[1:]
    goal = (1.3,) + home[1:]
    planner = Planner(kin, cell_checker, seed=2)
    blocked = planner.motion_valid(start, goal)
    assert blocked is not None and any(c.other == "pillar" for c in cell_checker.contacts(blocked))
    plan = planner.plan(start, goal)
    dense = []
    for a, b in zip(plan.positions, plan.positions[1:]):
        dense.extend(tuple(x + (y - x) * k / 20 for x, y in zip(a, b)) for k in range(20))
    dense.append(plan.goal)
    assert cell_checker.check_path(dense) is None
    traj = validate(TrajectoryGoal.of(plan), kin.joint_names, start, kin.limits.lower, kin.limits.upper, now=0.0)
    assert max(segment_speeds(traj, kin.limits.velocity, kin.joint_names)) <= 1.0


def test_the_driver_collision_guard_accepts_a_plan_made_with_its_padding(kin, cell_checker):
    """The driver's own path check (driver.checks.scene_guard, collision_padding 10 mm, the cell as its
    scene) accepts what the planner plans with a checker of the same padding -- and refuses the
    straight move the planner went around."""
    import threading

    from vr_driver.driver.checks.scene_guard import SceneGuard
    from vr_driver.errors import CollisionError
    from vr_driver.kinematics.scene import load_scene
    guard = SceneGuard(kin, threading.Lock(), scene=load_scene(CELL), padding=0.01)
    padded = cell_checker.copy()
    padded.set_padding(0.01)
    home = tuple(kin.named_states["home"])
    start, goal = (-0.3,) + home[1:], (1.3,) + home[1:]
    # (a correctness test, not a speed one: the budget is wall time, and around the pillar RRTConnect
    # ran out of the default 1 s in a fresh clone beside other sessions' load)
    plan = Planner(kin, padded, seed=5, time_budget=10.0).plan(start, goal)
    guard.check_path(plan.positions, "trajectory", plan.times)
    with pytest.raises(CollisionError, match="pillar"):
        guard.check_path([start, goal], "PTP path")


def test_start_in_collision_with_the_cell_names_the_link_and_object(kin, cell_checker):
    into_table = (0.0, 1.2, -0.3, 0.0, 0.4, 0.0)                 # the arm reaching down into the table
    assert cell_checker.in_collision(into_table)
    with pytest.raises(PlanningError, match=r"start .* is in collision: link_\d with object table") as info:
        Planner(kin, cell_checker).plan(into_table, "home")
    assert any(c.other == "table" for c in info.value.contacts)


def _random_motions(kin, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    ends = lo + rng.random((n + 1, 6)) * (hi - lo)
    # long and short motions: across the cell, and 0.02 to 0.3 rad from a random configuration
    short = ends[:n] + rng.uniform(-0.3, 0.3, (n, 6))
    return [(tuple(a), tuple(b)) for a, b in zip(ends[:n], ends[1:])] + \
        [(tuple(a), tuple(np.clip(b, lo, hi))) for a, b in zip(ends[:n], short)]


def test_a_motion_checked_in_one_batch_is_checked_state_by_state(kin, cell_checker):
    """motion_valid and the planner's test (the clearance, and the escape zone near the ends) in
    one batch (the checker's first_collision) find the configuration the same test one state at a
    time finds, on random motions across the cell and short ones (brute force)."""
    from vr_driver.kinematics.plan_search import BatchValidity, SweepZone, first_invalid
    planner = Planner(kin, cell_checker)
    assert isinstance(planner.is_valid, BatchValidity) and isinstance(planner.planning_valid, BatchValidity)
    found = {"valid": 0, "planning": 0}
    for a, b in _random_motions(kin, 60, 4):
        planner.search_test.ends = SweepZone((a, b), planner.weights)
        for name, batch, one in (("valid", planner.is_valid, lambda q: not cell_checker.in_collision(q)),
                                 ("planning", planner.planning_valid, planner.search_test.valid)):
            n = max(1, int(math.ceil(planner.search_test.sweep(a, b) / planner.max_sweep)))
            states = [tuple(x + k / n * (y - x) for x, y in zip(a, b)) for k in range(1, n + 1)]
            expected = next((q for q in states if not one(q)), None)
            got = planner.motion_valid(a, b, batch)
            assert got == (None if expected is None else pytest.approx(expected, abs=1e-12)), name
            found[name] += got is not None
            assert first_invalid(one, states) == first_invalid(batch, np.array(states))
    assert 10 < found["planning"] < 120 and found["valid"] <= found["planning"]
    # the result's check: every chord of a sampled path in one batch, the first invalid state
    # the one chord after chord finds
    rng, outcomes = np.random.default_rng(8), set()
    for a, b in _random_motions(kin, 12, 9):
        path = [tuple(x + f * (y - x) + e for x, y, e in zip(a, b, rng.normal(0.0, 0.01, 6)))
                for f in np.linspace(0.0, 1.0, 25)]
        expected = next(((k, q) for k in range(1, len(path)) for q in [planner.motion_valid(path[k - 1], path[k])]
                         if q is not None), None)
        got = planner.chords_valid(path)
        assert (got is None) == (expected is None)
        assert got is None or (got[0] == expected[0] and got[1] == pytest.approx(expected[1], abs=1e-12))
        outcomes.add(got is None)
    assert outcomes == {True, False}


# ------------------------------------------------------------------------- without the libraries

def test_without_ompl_the_module_imports_and_the_planner_names_the_package():
    script = ("import sys; sys.modules['ompl'] = None; sys.modules['rospy'] = None; sys.path[:0] = %r\n"
              "import vr_driver.kinematics.planner as p\n"
              "from vr_driver.kinematics.solver import Kinematics\n"
              "try:\n    p.Planner(Kinematics.default(), None)\n"
              "except p.MissingDependency as exc:\n    print('missing', exc.package, '|', exc)\n"
              % ([SRC, os.path.join(REPO, "panasonic_vr006l_support", "src")],))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("missing ompl |") and "scripts/setup" in proc.stdout
    assert issubclass(MissingDependency, ImportError)


def test_the_escape_zone_in_numpy_is_the_sweep_bound_s(kin):
    """SearchTest.escapes (the sweeps to the start and every goal in numpy, :meth:`sweep`'s sums
    within 1e-9 of the bound) says what :meth:`sweep` of each end says, on random configurations
    around the ends, both ways, and at the bound itself."""
    import random
    from vr_driver.kinematics.plan_search import SweepZone
    from vr_driver.kinematics.planner import ESCAPE_SWEEP, Planner
    planner = Planner(kin, None)
    rng = random.Random(3)
    assert planner.search_test.ends.ends == () and not planner.search_test.escapes(kin.random_joints(rng))    # no plan made: no zone
    for ends in ([kin.random_joints(rng)], [kin.random_joints(rng) for _ in range(9)]):
        planner.search_test.ends = SweepZone(ends, planner.weights)
        seen = set()
        for _ in range(1500):
            e = rng.choice(ends)
            q = tuple(v + rng.uniform(-0.6, 0.6) for v in e)
            expected = any(planner.search_test.sweep(q, x) <= ESCAPE_SWEEP for x in ends) and planner.is_valid(q)
            assert planner.search_test.escapes(q) == expected
            seen.add(expected)
        assert seen == {True, False}
        # one joint of the first end turned to the bound exactly (as near as floats go)
        w = planner.weights[0]
        q = (ends[0][0] + ESCAPE_SWEEP / w,) + tuple(ends[0][1:])
        expected = any(planner.search_test.sweep(q, x) <= ESCAPE_SWEEP for x in ends) and planner.is_valid(q)
        assert planner.search_test.escapes(q) == expected
