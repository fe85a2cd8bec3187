"""Protocol v3 targets near the wrist singularity, stepped with a fake clock in one thread
(_world.World: DriverCore, our DP master, the in-memory link, the virtual G2's v3 program with its
own IK, the streaming arm). A target within a few hundredths of a degree of joint_5 = 0, whose plain
rounding the G2 would solve tens of degrees off the plan (the pose hardly fixes joint_4 - joint_6
there), goes out as the one-step neighbour of that rounding the G2 solves on the plan
(driver.checks.wire_targets): the stream is no longer refused, and the arm ends on the planned wrist."""
from __future__ import annotations

import math

import pytest

from vr_driver.driver.motion.jobs import StreamPoint
from vr_driver.driver.checks.stream_prep import CONFIGURATION_TOLERANCE
from vr_driver.kinematics.deps import missing_dependencies
from vr_driver.protocol.registry import get

from _world import World
from test_streaming_stepped import record, trajectory

DEG = math.pi / 180.0
V3 = get("v3")
START = (0.1, 0.6, -0.25, 20 * DEG, 24 * DEG, -30 * DEG)
#: joint_5 0.01 deg: the plain rounding of its pose, solved by the G2 from here, is 34 deg off
NEAR = (0.1, 0.6, -0.25, 30 * DEG, 0.01 * DEG, -10 * DEG)


def plain_error(kin, q, seed):
    s = kin.ik_pose(V3.wire_pose(kin.fk_pose(q)), seed=seed)
    return max(abs(a - b) for a, b in zip(s, q))


@pytest.fixture
def world(kin):
    w = World(kin, protocol="v3", initial_pose=kin.fk_pose(START))
    w.ready()
    return w


def test_a_target_at_the_singularity_goes_out_where_the_controller_lands_on_the_plan(world, kin):
    assert plain_error(kin, NEAR, START) > CONFIGURATION_TOLERANCE         # the plain rounding: refused
    point, = world.core.cartesian_points(START, [StreamPoint(NEAR, 100, 0, 1.0, 1)])
    # on the wire's grid, one step at most from the plain rounding in each number
    plain = V3.wire_pose(kin.fk_pose(NEAR))
    assert V3.wire_pose(point.pose) == point.pose
    assert all(abs(a - b) <= u * 1.0001 for a, b, u in zip(point.pose.as_tuple(), plain.as_tuple(), (0.1,) * 3 + (0.01,) * 3))
    solved = kin.ik_pose(point.pose, seed=START)
    assert max(abs(a - b) for a, b in zip(solved, NEAR)) <= 0.3 * DEG


@pytest.mark.parametrize("rule", ["previous_target", "current_joints"])
def test_a_goal_at_the_singularity_ends_on_the_planned_wrist(kin, rule):
    """A planned move from joint_5 = 24 deg to 0.01 deg (joint_4 / joint_6 turning on the way): it
    runs, each target once, and the arm ends on the plan's split of joint_4 / joint_6 -- not only on
    their sum, which is all the pose fixes there. With the G2 and the driver at either configuration
    rule (current_joints: each wire pose chosen to land on the plan from every point the arm may be
    at when the G2 takes it)."""
    from vr_driver.kinematics.solver import ConfigurationRule
    world = World(kin, {"controller": {"configuration": rule}}, protocol="v3", initial_pose=kin.fk_pose(START))
    world.arm.configuration = ConfigurationRule.parse(rule)
    world.ready()
    n = 20
    times, points = [], []
    for k in range(1, n + 1):
        u = k / n
        s = u * u * (3.0 - 2.0 * u)
        points.append(tuple(a + s * (b - a) for a, b in zip(START, NEAR)))
        times.append(3.0 * u)
    traj = trajectory(world, times, points)
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    record(world, job)
    assert job.result.success, job.result.reason
    entries = world.log.entries()
    assert [e.seq for e in entries] == job.seqs
    off = [abs(a - b) for a, b in zip(world.arm.joints, NEAR)]
    assert max(off) <= 0.3 * DEG, [round(v / DEG, 3) for v in off]


def _paths(kin, rng, n):
    """``n`` planner-like paths (times, positions): straight joint lines at smoothstep timing between
    random joints, every third across joint_5 = 0 (the wire pose's search) and every third near it at
    both ends (the grid search), 20-50 samples each."""
    lo, hi = kin.limits.lower, kin.limits.upper
    out = []
    for i in range(n):
        a = [rng.uniform(l * 0.8, h * 0.8) for l, h in zip(lo, hi)]
        b = [rng.uniform(l * 0.8, h * 0.8) for l, h in zip(lo, hi)]
        if i % 3 == 0:
            a[4], b[4] = rng.uniform(3, 30) * DEG, -rng.uniform(3, 30) * DEG
        elif i % 3 == 1:
            a[4], b[4] = rng.uniform(-0.5, 0.5) * DEG, rng.uniform(-0.4, 0.4) * DEG
        else:
            a[4], b[4] = rng.uniform(-100, 100) * DEG, rng.uniform(-100, 100) * DEG
        m = rng.randint(20, 50)
        times, positions = [], []
        for k in range(m + 1):
            u = k / m
            s = u * u * (3.0 - 2.0 * u)
            positions.append(tuple(x + s * (y - x) for x, y in zip(a, b)))
            times.append(3.0 * u)
        out.append((times, positions))
    return out


@pytest.mark.parametrize("rule, n", [("previous_target", 18), ("current_joints", 8)])
def test_the_stream_checks_shared_wire_poses_change_nothing(kin, rule, n):
    """One stream check computes each point's wire pose and the controller's solutions of it once
    (wire_targets.WireMemo, shared by the stream's thinning -- would the G2 reach the next point? --
    and the wire poses of the points kept): on ``n`` paths (a memo that ignored the seed fails the
    first rule's 18) (across joint_5 = 0, on it, anywhere), by
    either configuration rule, the points, their wire poses and the refusals' words are exactly
    those of each wire pose computed on its own (no memo shared between the calls)."""
    import random
    from vr_driver.driver.motion.stream_points import MAX_STREAM_TOLERANCE
    from vr_driver.errors import VrDriverError
    world = World(kin, {"controller": {"configuration": rule}}, protocol="v3")
    streams = world.core.streams
    rng = random.Random(46)

    tol = math.radians(world.core.params.stream_path_tolerance)

    def run(times, positions):
        try:     # (the part of the stream check the memo serves: its segments are checked after it)
            return streams.points(times, positions, tol, max(tol, MAX_STREAM_TOLERANCE))
        except VrDriverError as exc:
            return str(exc)
    shared = []
    alone = []
    paths = _paths(kin, rng, n)
    for times, positions in paths:
        shared.append(run(times, positions))
    streams.memo = lambda: None          # each wire_target call with a memo of its own: as before the memo
    for times, positions in paths:
        alone.append(run(times, positions))
    assert shared == alone
    # the paths ask for the parts that changed: thinned streams with searched wire poses, and refusals
    assert sum(isinstance(r, tuple) and len(r) > 1 for r in shared) >= 3
    assert any(isinstance(r, str) for r in shared)


@pytest.mark.skipif(bool(missing_dependencies(("pinocchio", "coal"))), reason="the cell check needs pinocchio and coal")
@pytest.mark.parametrize("rule, n", [("previous_target", 16), ("current_joints", 6)])
def test_the_stream_checks_fast_paths_change_nothing(kin, rule, n, monkeypatch):
    """The stream check's shortcuts -- a segment clearly inside the box passed without its timed
    preview (PathChecks._clearly_inside), the cell check of the chords in one call
    (scene_guard.first_in_collision), the wire poses' IK without kin.ik's wrapper
    (wire_targets._analytic_nearest) and the analytic solver's nearest candidate alone
    (AnalyticSolver.solve nearest=True) -- give the points, their wire poses and the refusals'
    words of the checks without them, on the trajectory bench's twelve wrist goals (real plans
    across and onto joint_5 = 0: data/wrist_goals_seed1.json) and ``n`` paths (across joint_5 = 0,
    on it, anywhere; many leave the box), by either configuration rule, in the example cell."""
    import json
    import os
    import random
    from vr_driver.driver.checks.path_checks import PathChecks
    from vr_driver.driver.checks import wire_targets
    from vr_driver.errors import VrDriverError
    from vr_driver.kinematics.analytic import AnalyticSolver
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    world = World(kin, {"controller": {"configuration": rule},
                        "scene": os.path.join(repo, "panasonic_vr006l_support", "config", "cell_example.yaml")},
                  protocol="v3")
    streams = world.core.streams
    data = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "wrist_goals_seed1.json")
    with open(data, encoding="utf-8") as fh:
        goals = [g for s in json.load(fh)["sets"] for g in s["goals"]]
    paths = [(g["times"], [tuple(q) for q in g["points"]]) for g in goals] + _paths(kin, random.Random(47), n)

    def run():
        out = []
        for times, positions in paths:
            try:
                out.append(streams.trajectory(times, positions))
            except VrDriverError as exc:
                out.append(str(exc))
        return out
    fast = run()
    solve = AnalyticSolver.solve
    from vr_driver.driver.checks import scene_guard
    monkeypatch.setattr(scene_guard, "first_in_collision",      # one configuration at a time
                        lambda checker, qs, every=0, pause=None: next(
                            (i for i, q in enumerate(qs) if checker.in_collision(q)), None))
    monkeypatch.setattr(PathChecks, "_clearly_inside", lambda self, start, end: False)
    monkeypatch.setattr(wire_targets, "_analytic_nearest", lambda kin: None)
    monkeypatch.setattr(AnalyticSolver, "solve", lambda self, r, p, seed, lower, upper, nearest=False:
                        solve(self, r, p, seed, lower, upper))
    assert run() == fast
    # the paths ask for every part: streams with searched wire poses, refusals by the box, the
    # cell and the configuration
    assert sum(isinstance(r, tuple) and len(r) > 1 for r in fast) >= 12
    for words in ("workspace", "collides", "configuration"):
        assert any(isinstance(r, str) and words in r for r in fast), words


def test_a_segment_past_a_joint_limit_is_refused_as_its_preview_refuses_it(kin, monkeypatch):
    """The segment check's fast path (PathChecks._clearly_inside) checks the joint limits of its
    samples and both ends in one vector check, by check_limits' rule: an end beyond a limit by more
    than its 1e-9 rad is refused with the preview's own words, one within it passes -- each the same
    with and without the fast path, the start or the end the one beyond."""
    from vr_driver.driver.checks.path_checks import PathChecks
    from vr_driver.errors import JointLimitError
    checks = World(kin, protocol="v3").core.checks
    hi = kin.limits.upper[5]                   # joint_6: its turn moves the TCP's position nowhere

    def at(q6):
        return START[:5] + (q6,)

    def outcome(a, b):
        try:
            checks.check_joint_move(a, b)
        except JointLimitError as exc:
            return str(exc)
        return "passed"
    cases = [(at(hi - 0.01), at(hi + 2e-9)), (at(hi + 2e-9), at(hi - 0.01)), (at(hi - 0.01), at(hi + 0.5e-9))]
    fast = [outcome(a, b) for a, b in cases]
    monkeypatch.setattr(PathChecks, "_clearly_inside", lambda self, start, end: False)
    assert [outcome(a, b) for a, b in cases] == fast
    assert "outside" in fast[0] and "outside" in fast[1] and fast[2] == "passed"
