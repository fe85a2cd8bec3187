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
