"""The driver applies the G2's configuration rule (``controller/configuration``, as the commissioning
measures it) wherever it predicts the controller's joint solution of a Cartesian target, stepped
with a fake clock in one thread (_world.World: DriverCore, our DP master, the in-memory link, the
virtual G2 with its own IK and its ``configuration`` parameter, the simulated arm).

The two rules differ where the arm is not at the previous target when the G2 takes a target: v3's
ring takes targets ahead of the arm, v1 after a move stopped short. Told the G2's rule, the driver
streams, checks and tracks by it, and a move through a pose whose solutions differ ends on the
branch the G2 took, with ``joint_states`` on it all the way. Told another rule (the G2 at
``current_joints``, the driver at the documented ``previous_target``: a commissioning not applied),
what the code guarantees: ``joint_states`` follow the arm's own branch -- never the commanded
path's same pose a turn away -- with a warning naming the rule, and joint_trajectory_action's
supervision stops the run (PATH_TOLERANCE_VIOLATED) once the arm leaves the plan."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vr_driver.driver import DriverError, MoveRequest
from vr_driver.driver.motion.jobs import StreamPoint
from vr_driver.driver.checks.stream_prep import CARTESIAN_MAX_STEP, CONFIGURATION_TOLERANCE
from vr_driver.driver.joints.supervision import ABORTED
from vr_driver.driver.motion.trajectories import PATH_TOLERANCE_VIOLATED
from vr_driver.kinematics.solver import ConfigurationRule
from vr_driver.poses import ControllerPose, MoveType
from vr_driver.protocol.registry import get

from _world import World
from test_streaming_stepped import record, trajectory
from test_tracking_stepped import ACCURACY, Q_A, Truth, Verdict, make_world, published
from test_wire_supervision_stepped import succeeded, supervise, validated

DEG = math.pi / 180.0
V3 = get("v3")
#: a wrist whose flip (joint_4 and joint_6 + 180 deg, joint_5 negated: the same pose) is inside the
#: joint limits
Q_FLIP = (0.2, 0.3, -0.2, 0.3, 0.5, 0.4)


def flip_world(kin, rule, told):
    w = World(kin, {"controller": {"configuration": told}}, protocol="v3", initial_pose=kin.fk_pose(Q_FLIP))
    w.arm.configuration = ConfigurationRule.parse(rule)
    w.ready()
    assert max(abs(a - b) for a, b in zip(w.arm.joints, Q_FLIP)) < 1e-6
    return w


def flip_path(q0, n=21, duration=4.0):
    """A straight joint move from ``q0`` to its flipped wrist, through joint_5 = 0: its end pose is
    its start pose. (An odd ``n``: no planned point lies exactly on joint_5 = 0, where no wire pose
    of v3's grid lands within CONFIGURATION_TOLERANCE of a given split of joint_4 / joint_6 --
    1.3 deg at best from this path's midpoint, whichever the rule.)"""
    flip = (q0[0], q0[1], q0[2], q0[3] + math.pi, -q0[4], q0[5] + math.pi)
    points = [tuple(a + (b - a) * k / n for a, b in zip(q0, flip)) for k in range(1, n + 1)]
    return [duration * k / n for k in range(1, n + 1)], points, flip


def turn_path(q0, n=12, duration=3.0, turn=240.0 * DEG):
    """joint_6 turned by ``turn`` in ``n`` planned points (the others still)."""
    points = [tuple(np.array(q0) + np.array([0.0] * 5 + [turn * k / n])) for k in range(1, n + 1)]
    return [duration * k / n for k in range(1, n + 1)], points


def warnings(caplog):
    return [r.getMessage() for r in caplog.records if "only on another branch" in r.getMessage()]


# ------------------------------------------------------------------------- told the G2's rule

def test_current_joints_a_wrist_flip_through_the_singularity_ends_on_the_flipped_wrist(kin, caplog):
    """v3, the G2 and the driver at current_joints: a straight joint move to the flipped wrist,
    whose end pose is its start pose, so that the G2 solving the last targets nearest where the arm
    still is would stay on the start's wrist. The stream keeps points at most 18 deg apart, every
    point's solution from each of the five points before it lands on the plan, and the arm ends on
    the flipped wrist with joint_states on it all the way (joint_4 / joint_6 by their sum near
    joint_5 = 0)."""
    world = flip_world(kin, "current_joints", "current_joints")
    truth = Truth(world)
    world.run_for(world.bus_period)
    q0 = tuple(world.arm.joints)
    times, points, flip = flip_path(q0)
    since = world.now
    run = world.core.submit_trajectory(trajectory(world, times, points))
    job = run.jobs[0]
    steps = [max(abs(a - b) for a, b in zip(p.joints, q))
             for p, q in zip(job.points, [q0] + [p.joints for p in job.points[:-1]])]
    assert max(steps) <= CARTESIAN_MAX_STEP / 5 + 1e-9, [round(s / DEG, 1) for s in steps]
    # each point's wire pose, solved from each of the five points before it (the arm's joints when
    # the G2 may take it), lands on the plan
    arm_path = [q0] + [p.joints for p in job.points]
    for i, p in enumerate(job.points):
        for seed in arm_path[max(0, i - 4):i + 1]:
            q = kin.ik_pose(p.pose, seed=seed)
            assert max(abs(a - b) for a, b in zip(q, p.joints)) <= CONFIGURATION_TOLERANCE, (i, seed)
    record(world, job)
    assert job.result.success, job.result.reason
    world.run_for(0.5)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, flip)) <= V3.target_error
    Verdict(world, truth, published(world, since)).check()
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY
    assert world.core.tracker.off_branch == 0 and not warnings(caplog)


def test_current_joints_a_point_the_arm_may_still_be_behind_is_refused_in_words(kin):
    """The stream check under current_joints: three hand-made points turning joint_6 by 80 deg
    each. Nearest the previous point each lands on the plan (previous_target accepts them); the
    third, nearest the start -- where the arm may still be when the G2 takes it -- lands at -120
    deg instead of +240: refused before anything is sent, in words naming the rule."""
    q0 = tuple(World(kin, protocol="v3").arm.joints)
    points = [StreamPoint(q0[:5] + (q0[5] + k * 80 * DEG,), 100, 3, float(k), k) for k in (1, 2, 3)]
    points[-1] = StreamPoint(points[-1].joints, 100, 0, 3.0, 3)
    told = {}
    for rule in ("previous_target", "current_joints"):
        world = World(kin, {"controller": {"configuration": rule}}, protocol="v3")
        world.ready()
        try:
            told[rule] = world.core.cartesian_points(q0, points)
        except DriverError as exc:
            told[rule] = str(exc)
    assert [p.joints for p in told["previous_target"]] == [p.joints for p in points]
    text = told["current_joints"]
    assert isinstance(text, str), text
    assert "point 3 of 3" in text and "another configuration" in text and "joint_6" in text, text
    assert "-120" in text or "-12" in text.split("joint_6", 1)[1][:12], text
    assert "current_joints" in text and "up to 5 points before it" in text and "nothing was sent" in text, text


def test_current_joints_v1_after_a_stop_the_next_ptp_is_solved_nearest_the_arm(kin, caplog):
    """v1, the G2 and the driver at current_joints (the commissioning file's rule): a PTP turning
    joint_6 by +3 rad is stopped a third of the way; the next target's joint_6 solution nearest the
    arm is 0.5 rad below the start, a full turn below the one nearest the unreached target. The
    arm runs the one nearest it; joint_states follow it exactly."""
    world = make_world(kin, "v1", "current_joints", "slow")
    truth = Truth(world)
    world.run_for(world.bus_period)
    q_a = tuple(world.arm.joints)
    job = world.core.submit(MoveRequest(MoveType.PTP, kin.fk_pose(q_a[:5] + (q_a[5] + 3.0,))))
    world.run_until(lambda: world.arm.joints[5] > q_a[5] + 0.8, 30.0, "a third of the turn")
    world.core.cancel(job, "test: stop")
    world.finish(job)
    stopped, unreached = tuple(world.arm.joints), tuple(job.preview.joint_target)
    target = ControllerPose(*[float(round(v)) for v in kin.fk_pose(q_a[:5] + (q_a[5] - 0.5,)).as_tuple()])
    nearest_arm = kin.ik_pose(target, seed=stopped)
    assert abs(kin.ik_pose(target, seed=unreached)[5] - nearest_arm[5]) > 6.0      # a turn apart
    since = world.now
    job = world.core.submit(MoveRequest(MoveType.PTP, target))
    assert world.finish(job, 60.0).success, job.result.reason
    world.run_for(0.5)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, nearest_arm)) < 1e-6
    Verdict(world, truth, published(world, since)).check()
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY
    assert world.core.tracker.off_branch == 0 and not warnings(caplog)


# --------------------------------------------------------------- told another rule than the G2's

def test_mismatch_v3_a_flip_the_g2_does_not_run_is_stopped_by_the_path_check(kin):
    """The G2 at current_joints, the driver told previous_target: the flip's stream is checked
    target by target from the previous one, but the G2 takes the later targets while the arm is
    several points behind and solves them back onto the start's wrist. joint_states follow the arm
    (its poses are off the commanded path: read from the last joints) and joint_trajectory_action's
    supervision stops the run: PATH_TOLERANCE_VIOLATED, the arm at rest short of the flip. Told
    current_joints, the same goal succeeds."""
    world = flip_world(kin, "current_joints", "previous_target")
    truth = Truth(world)
    world.run_for(world.bus_period)
    q0 = tuple(world.arm.joints)
    times, points, flip = flip_path(q0)
    since = world.now
    sup, out = supervise(world, validated(world, times, points))
    assert (out.state, out.error_code) == (ABORTED, PATH_TOLERANCE_VIOLATED), out.error_string
    assert sup.stops_arm and not world.arm.moving
    assert max(abs(a - b) for a, b in zip(world.arm.joints, flip)) > 10 * DEG      # not flipped
    # the joints the driver published were the arm's: on its branch, never the plan's
    samples = published(world, since)
    for s in samples:
        _t, q = truth.at(s, check=False)
        off = np.abs(np.array(s.joints) - np.array(q))
        assert off[[0, 1, 2, 4]].max() <= ACCURACY and abs(s.joints[3] + s.joints[5] - q[3] - q[5]) <= ACCURACY, \
            (s.time, [round(v / DEG, 2) for v in s.joints], [round(v / DEG, 2) for v in q])
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY
    # told the G2's rule, the same goal runs to the flipped wrist
    clean = flip_world(kin, "current_joints", "current_joints")
    _sup, ok = supervise(clean, validated(clean, *flip_path(tuple(clean.arm.joints))[:2]))
    succeeded(ok)


def test_mismatch_v1_after_a_stop_the_joints_follow_the_arm_not_the_expected_goal(kin, caplog):
    """v1, the G2 at current_joints, the driver told previous_target: after a stop short of a
    target, the driver expects the next PTP to end a full turn of joint_6 above where the G2, solving
    nearest the arm, takes it. The reports (whole mm / deg) lie on the expected path only a turn
    away: the driver's joints stay on the arm's branch (within the few degrees a whole-degree
    report leaves open off the commanded path), with one warning naming the rule, and end on the
    arm's joints -- not 360 deg off them."""
    world = make_world(kin, "v1", "current_joints", "slow", told="previous_target")
    truth = Truth(world)
    world.run_for(world.bus_period)
    q_a = tuple(world.arm.joints)
    job = world.core.submit(MoveRequest(MoveType.PTP, kin.fk_pose(q_a[:5] + (q_a[5] + 3.0,))))
    world.run_until(lambda: world.arm.joints[5] > q_a[5] + 0.8, 30.0, "a third of the turn")
    world.core.cancel(job, "test: stop")
    world.finish(job)
    stopped, unreached = tuple(world.arm.joints), tuple(job.preview.joint_target)
    target = ControllerPose(*[float(round(v)) for v in kin.fk_pose(q_a[:5] + (q_a[5] - 0.5,)).as_tuple()])
    expected = kin.ik_pose(target, seed=unreached)            # previous_target: what the driver expects
    nearest_arm = kin.ik_pose(target, seed=stopped)           # current_joints: what the G2 runs
    assert expected[5] - nearest_arm[5] > 6.0
    since = world.now
    job = world.core.submit(MoveRequest(MoveType.PTP, target))
    world.finish(job, 60.0)
    world.run_for(0.5)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, nearest_arm)) < 1e-6
    worst = 0.0
    for s in published(world, since):
        _t, q = truth.at(s)
        worst = max(worst, float(np.max(np.abs(np.array(s.joints) - np.array(q)))))
    assert worst <= 5.0 * DEG, worst / DEG
    assert max(abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)) <= ACCURACY
    told = warnings(caplog)
    assert world.core.tracker.off_branch >= 1 and len(told) == 1, told
    assert "controller/configuration previous_target" in told[0]


def test_the_driver_takes_its_rule_from_the_commissioning(kin):
    """controller/configuration reaches both places that predict the G2's solution: the tracker
    (v1, v3) and the v3 stream preparation (its window and step)."""
    for rule, window in (("previous_target", 1), ("current_joints", 5)):
        world = World(kin, {"controller": {"configuration": rule}}, protocol="v3",
                      initial_pose=kin.fk_pose(Q_A))
        assert world.core.tracker.rule is ConfigurationRule.parse(rule)
        streams = world.core.streams
        assert streams.rule is ConfigurationRule.parse(rule) and streams.window == window
        assert streams.max_step == pytest.approx(CARTESIAN_MAX_STEP / window)
    world = World(kin, {"controller": {"configuration": "current_joints", "ring_size": 2}}, protocol="v3")
    assert world.core.streams.window == 3
    v1 = World(kin, {"controller": {"configuration": "current_joints"}}, protocol="v1")
    assert v1.core.tracker.rule is ConfigurationRule.CURRENT_JOINTS
