"""driver.checks.wire_targets: the wire pose of a v3 stream target chosen among the 3^6 neighbours of its
rounding so that the controller's IK of it lands on the planned joints -- near joint_5 = 0, where
the plain rounding swings the wrist by degrees."""
from __future__ import annotations

import itertools
import math
import random

import pytest

from vr_driver.driver.checks.wire_targets import FINE, GOOD_ENOUGH, MODEL_MARGIN, GridModel, WireTarget, wire_target
from vr_driver.errors import VrDriverError
from vr_driver.poses import ControllerPose
from vr_driver.protocol import registry

DEG = math.pi / 180.0
V3 = registry.get("v3")


def off(kin, pose, seed, planned):
    """What the controller does with ``pose``: its IK seeded as it seeds it, against the plan."""
    q = kin.ik_pose(pose, seed=seed)
    return max(abs(a - b) for a, b in zip(q, planned))


def on_grid(pose, wire):
    return wire.wire_pose(pose).as_tuple() == pytest.approx(pose.as_tuple(), abs=1e-9)


def within_one_step(pose, base, wire):
    mm, deg = wire.pose_resolution
    return all(abs(a - b) <= s * 1.0001 for a, b, s in zip(pose.as_tuple(), base.as_tuple(), (mm,) * 3 + (deg,) * 3))


def test_away_from_the_singularity_the_plain_rounding_is_kept(kin):
    q = (0.2, 0.6, -0.3, 0.4, 0.8, -0.5)
    t = wire_target(kin, V3, q, q)
    assert isinstance(t, WireTarget)
    assert t.steps == (0,) * 6 and t.solved == 1
    assert t.pose == V3.wire_pose(kin.fk_pose(q))
    assert t.error <= FINE


@pytest.mark.parametrize("j5_deg", [2.0, 0.8, 0.3, 0.1, -0.05])
def test_near_the_singularity_the_chosen_pose_lands_on_the_plan(kin, j5_deg):
    q = (0.0, 0.65, -0.28, 20 * DEG, j5_deg * DEG, -30 * DEG)
    base = V3.wire_pose(kin.fk_pose(q))
    plain = off(kin, base, q, q)
    t = wire_target(kin, V3, q, q)
    assert on_grid(t.pose, V3) and within_one_step(t.pose, base, V3)
    # the controller's solution of the chosen pose: what wire_target says, and near the plan
    assert off(kin, t.pose, q, q) == pytest.approx(t.error, abs=1e-12)
    # (within 0.1 deg of joint_5 = 0 even the best of the 729 grid poses is a few tenths off)
    assert t.error <= min(plain, (0.05 if abs(j5_deg) >= 0.3 else 0.3) * DEG), (plain / DEG, t.error / DEG, t.steps)
    if plain > FINE:
        assert t.steps != (0,) * 6


def test_random_wrists_near_the_singularity_land_within_half_a_degree(kin):
    rng = random.Random(7)
    worst_plain = worst = 0.0
    for _ in range(25):
        q = (rng.uniform(-1, 1), rng.uniform(0.2, 0.9), rng.uniform(-0.6, 0.2), rng.uniform(-1.5, 1.5),
             rng.uniform(-3, 3) * DEG, rng.uniform(-1.5, 1.5))
        t = wire_target(kin, V3, q, q)
        worst_plain = max(worst_plain, off(kin, V3.wire_pose(kin.fk_pose(q)), q, q))
        worst = max(worst, t.error)
        assert t.error <= off(kin, V3.wire_pose(kin.fk_pose(q)), q, q)
    assert worst <= 0.5 * DEG < worst_plain, (worst / DEG, worst_plain / DEG)


def test_the_seed_is_the_controllers(kin):
    """Seeded from another wrist split, the controller solves the same pose onto that split: the
    search measures against the plan and reports how far that lands."""
    q = (0.0, 0.65, -0.28, 20 * DEG, 0.0, -30 * DEG)      # on the singularity: the pose fixes the sum
    other = (0.0, 0.65, -0.28, 30 * DEG, 0.0, -40 * DEG)
    t = wire_target(kin, V3, q, other)
    assert off(kin, t.pose, other, q) == pytest.approx(t.error, abs=1e-12)


def test_an_unreachable_pose_raises(kin):
    q = (0.0, 0.0, 0.0, 0.0, 0.5, 0.0)
    far = (0.0, -2.5, 2.0, 0.0, 0.5, 0.0)

    class Far:
        """A protocol whose rounding moves the pose 5 m out: nothing can solve it."""
        pose_resolution = V3.pose_resolution

        def wire_pose(self, pose):
            return V3.wire_pose(type(pose)(pose.x + 5000.0, pose.y, pose.z, pose.rx, pose.ry, pose.rz))
    with pytest.raises(VrDriverError):
        wire_target(kin, Far(), q, far)


def test_a_rounding_past_the_stretched_arms_reach_is_replaced_by_a_neighbour_inside_it(kin):
    """The arm stretched out (joint_3 at the stretch): the plain rounding may push the pose 0.05 mm
    past its reach, where the G2 has no solution; a neighbour rounded the other way has one, near
    the plan."""
    from vr_driver.kinematics.solver import stretched_elbow
    q = (0.0, 0.5, stretched_elbow(kin), 0.2, 0.6, 0.1)
    with pytest.raises(VrDriverError):
        kin.ik_pose(V3.wire_pose(kin.fk_pose(q)), seed=q)
    t = wire_target(kin, V3, q, q)
    assert any(t.steps) and V3.wire_pose(t.pose) == t.pose
    assert off(kin, t.pose, q, q) == pytest.approx(t.error, abs=1e-12)
    assert t.error <= 0.5 * DEG


def test_further_seeds_count_by_the_worst_and_change_nothing_where_they_agree(kin):
    """``also`` (a controller at current_joints: the arm anywhere on a stretch of the plan when it
    takes the target): the pose's error is the worst over every seed, and its joints are that
    seed's solution. Away from any other branch the seeds agree: the same pose as from one seed.
    With joint_6 a turn on, the seed at the start solves the target's pose half a turn back: the
    error says so."""
    q = (0.2, 0.6, -0.3, 0.4, 0.8, -0.5)
    near = [tuple(v - d for v, d in zip(q, (0.05, 0.02, 0.0, 0.1, 0.05, 0.2)))]
    one = wire_target(kin, V3, q, q)
    many = wire_target(kin, V3, q, q, also=near + [q])
    assert (many.pose, many.error, many.steps) == (one.pose, one.error, one.steps)
    assert many.solved == 2 * one.solved                  # (the duplicate seed is not solved again)
    turned = q[:5] + (q[5] + 240 * DEG,)
    before = q[:5] + (q[5] + 160 * DEG,)
    t = wire_target(kin, V3, turned, before)
    assert t.error <= FINE
    t = wire_target(kin, V3, turned, before, also=[q])
    assert t.error == pytest.approx(2 * math.pi, abs=0.01)          # the start's solution: a turn off
    assert t.joints[5] == pytest.approx(turned[5] - 2 * math.pi, abs=0.01)
    assert off(kin, t.pose, q, turned) == pytest.approx(t.error, abs=1e-12)


def grid_best(kin, q, seed):
    """The best of all 729 one-step neighbours of the plain rounding, solved as the controller does."""
    base = V3.wire_pose(kin.fk_pose(q))
    mm, deg = V3.pose_resolution
    best = math.inf
    for steps in itertools.product((-1, 0, 1), repeat=6):
        pose = V3.wire_pose(ControllerPose(*(v + s * d for v, s, d in zip(base.as_tuple(), steps, (mm,) * 3 + (deg,) * 3))))
        try:
            best = min(best, off(kin, pose, seed, q))
        except VrDriverError:
            pass
    return best


def test_the_grid_search_tries_the_predicted_best_first_and_stops(kin):
    """Within FULL_SEARCH_BAND the grid is tried in the order a linear model predicts (GridModel),
    until one lands within FINE, or after SEARCH_LIMIT poses one within GOOD_ENOUGH, or the model
    says nothing left can land nearer than the best found (all 729 cost up to 0.27 s a target, which
    a goal ending near the singularity spent before its arm moved). Against all 729, solved here: it
    keeps the best of the grid (within 0.005 deg), or one within FINE, or one within GOOD_ENOUGH
    after at most a third of the grid; never worse than the plain rounding; and never all 729 for a
    wrist the model holds for."""
    rng = random.Random(11)
    early = 0
    for _ in range(10):
        q = (rng.uniform(-1, 1), rng.uniform(0.2, 0.9), rng.uniform(-0.6, 0.2), rng.uniform(-1.5, 1.5),
             rng.uniform(-0.4, 0.4) * DEG, rng.uniform(-1.5, 1.5))
        t = wire_target(kin, V3, q, q)
        assert t.error <= off(kin, V3.wire_pose(kin.fk_pose(q)), q, q)
        best = grid_best(kin, q, q)
        if t.error > GOOD_ENOUGH:                # nothing good enough: the best of the grid, found early
            assert t.error <= best + 0.005 * DEG, (t.solved, t.error / DEG, best / DEG)
            assert t.solved < 729
        elif t.error > max(FINE, best + 0.005 * DEG):
            assert t.solved <= 250, t.solved     # the coordinate search, the model's 13, SEARCH_LIMIT of the grid
        early += t.solved <= 250
    assert early >= 8, early


def test_the_model_predicts_the_solution_through_the_singularity(kin):
    """In wrist_features the controller's solution is linear in the wire pose at joint_5 = 0 too: over
    all 729 poses the predicted error is within MODEL_MARGIN of the solution's, and the best pose is
    among the first two predicted (random wrists, joint_5 from 0 to 0.45 deg)."""
    rng = random.Random(3)
    for bend in (0.0, 0.03, 0.45):
        q = (rng.uniform(-1, 1), rng.uniform(0.2, 0.9), rng.uniform(-0.6, 0.2), rng.uniform(-1.5, 1.5),
             bend * DEG, rng.uniform(-1.5, 1.5))
        base = V3.wire_pose(kin.fk_pose(q))
        mm, deg = V3.pose_resolution

        def solve(steps):
            pose = V3.wire_pose(ControllerPose(*(v + s * d for v, s, d in zip(base.as_tuple(), steps, (mm,) * 3 + (deg,) * 3))))
            return tuple(kin.ik_pose(pose, seed=q))
        model = GridModel(q, solve((0,) * 6), solve, q)
        assert model.trusted
        actual = [max(abs(a - b) for a, b in zip(solve(steps), q)) for steps, _p in model.order]
        misses = [abs(a - p) for a, (_s, p) in zip(actual, model.order)]
        assert max(misses) <= MODEL_MARGIN, (bend, max(misses) / DEG)
        assert actual.index(min(actual)) <= 1


def test_on_the_singularity_the_best_of_the_grid_is_found_without_solving_it_all(kin):
    """Exactly on joint_5 = 0 the pose does not fix joint_4 - joint_6: the best of the grid is kept,
    found by the model in a few dozen solutions instead of 729 (0.6 s: the bench's goal ending on
    joint_5 = 0 waited that long before its arm moved)."""
    for q in ((0.4, 0.5, -0.3, 0.5, 0.0, -0.7), (-0.5, 0.6, -0.3, 0.3, 0.0, 0.4)):
        t = wire_target(kin, V3, q, q)
        assert t.solved < 150
        assert t.error <= grid_best(kin, q, q) + 0.005 * DEG


def test_near_another_branch_the_model_is_not_trusted_and_the_whole_grid_is_searched(kin):
    """On joint_5 = 0 where some roundings land on another elbow (the nearest solution changes
    branch): no linear model holds, every pose of the grid is tried and the best kept."""
    q = (0.3, -0.2, -0.9, 0.5, 0.0, -0.7)
    t = wire_target(kin, V3, q, q)
    assert t.error > GOOD_ENOUGH and t.solved >= 729
    assert t.error == pytest.approx(grid_best(kin, q, q), abs=1e-12)
