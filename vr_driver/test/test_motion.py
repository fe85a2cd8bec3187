"""vr_driver.kinematics.preview: PTP / LIN / CIRC trajectories, their geometry, limits, timing and rejections."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from vr_driver.errors import (JointLimitError, MotionError, NearSingularError, PoseError, UnreachableError,
                              VrDriverError)
from vr_driver.kinematics.preview import MovePreviewer, MotionSettings, MoveType, Trajectory, trapezoid_tau
from vr_driver.poses import HOME_POSE, ControllerPose

TOL = 1e-3  # 1 mm


@pytest.fixture(scope="module")
def home(kin):
    return kin.named_states["home"]


def _joint_chord_points(kin, traj, per_segment=4):
    """TCP positions along the joint-space chords between samples (what the robot actually follows)."""
    pts = []
    conv = kin.conventions
    for a, b in zip(traj.positions[:-1], traj.positions[1:]):
        for f in np.linspace(0.0, 1.0, per_segment, endpoint=False):
            pts.append(conv.tip_to_tcp(kin.fk(a + f * (b - a)))[:3, 3])
    pts.append(conv.tip_to_tcp(kin.fk(traj.positions[-1]))[:3, 3])
    return np.array(pts)


def _assert_within_limits(kin, traj: Trajectory):
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    assert np.all(traj.positions >= lo - 1e-9) and np.all(traj.positions <= hi + 1e-9)
    assert np.all(np.diff(traj.times) > 0.0)
    vel = np.abs(np.diff(traj.positions, axis=0) / np.diff(traj.times)[:, None])
    assert np.all(vel <= np.array(kin.limits.velocity) * (1 + 1e-9))
    # the FK of every sample is the TCP pose stored with it
    for q, t in zip(traj.positions[::7], traj.tcp[::7]):
        assert np.allclose(kin.conventions.tip_to_tcp(kin.fk(q)), t, atol=1e-6)


def test_trapezoid_profile_inverse():
    for ramp in (0.0, 0.2, 0.4):
        taus = [trapezoid_tau(s, ramp) for s in np.linspace(0, 1, 101)]
        assert taus[0] == 0.0 and taus[-1] == pytest.approx(1.0)
        assert all(b > a for a, b in zip(taus, taus[1:]))
    # cruise: half the path at tau = 0.5 by symmetry
    assert trapezoid_tau(0.5, 0.2) == pytest.approx(0.5)


def test_ptp_reaches_the_target_and_is_timed_by_the_slowest_joint(kin, planner, home):
    target = ControllerPose(900, 300, 500, 0, 90, 30)
    traj = planner.ptp(home, target)
    assert traj.move_type is MoveType.PTP
    assert np.allclose(traj.positions[0], home)
    dp, da = kin.fk_pose(traj.goal).distance_to(target)
    assert dp < 1e-6 and da < 1e-6
    _assert_within_limits(kin, traj)
    # the duration is what the trapezoid needs for the slowest joint, no more
    dq = np.abs(np.array(traj.goal) - np.array(home))
    ramp = planner.settings.ramp_fraction
    expected = float(np.max(dq / np.array(kin.limits.velocity))) / (1.0 - ramp)
    assert traj.duration == pytest.approx(expected, rel=0.02)
    assert traj.duration <= expected * (1 + 1e-9)
    assert planner.estimate_duration("ptp", home, target) == pytest.approx(traj.duration)


def test_ptp_to_joints_and_zero_length_move(kin, planner, home):
    traj = planner.ptp_joints(home, kin.named_states["zero"])
    assert np.allclose(traj.goal, 0.0)
    _assert_within_limits(kin, traj)
    still = planner.ptp_joints(home, home)
    assert still.duration == 0.0


def test_lin_path_stays_within_1mm_of_the_segment(kin, planner, home):
    target = ControllerPose(900, 300, 500, 10, 60, 30)
    traj = planner.lin(home, target)
    p0 = np.array([1.120, 0.0, 0.725])
    p1 = np.array([0.900, 0.300, 0.500])
    d = p1 - p0
    pts = _joint_chord_points(kin, traj)
    s = np.clip((pts - p0) @ d / (d @ d), 0.0, 1.0)
    dist = np.linalg.norm(pts - (p0 + s[:, None] * d), axis=1)
    assert dist.max() < TOL
    assert s[0] == pytest.approx(0.0, abs=1e-6) and s[-1] == pytest.approx(1.0, abs=1e-6)
    dp, da = kin.fk_pose(traj.goal).distance_to(target)
    assert dp < 1e-6 and da < 1e-6
    # orientation is interpolated: halfway the rotation is halfway
    mid = traj.poses()[len(traj) // 2]
    _, half_angle = mid.distance_to(target)
    _, full = HOME_POSE.distance_to(target)
    assert half_angle == pytest.approx(full / 2, abs=1.0)
    _assert_within_limits(kin, traj)
    # the TCP never moves faster than the linear speed limit
    speeds = np.linalg.norm(np.diff(traj.tcp[:, :3, 3], axis=0), axis=1) / np.diff(traj.times)
    assert speeds.max() <= planner.settings.linear_speed * (1 + 1e-9)


def test_lin_pure_rotation_is_timed_by_the_angular_speed(kin, planner, home):
    target = ControllerPose(1120, 0, 725, 0, 45, 40)
    traj = planner.lin(home, target)
    assert np.allclose(traj.tcp[:, :3, 3], [1.120, 0.0, 0.725], atol=1e-9)
    assert traj.duration >= math.radians(40) / planner.settings.angular_speed


def test_circ_path_stays_within_1mm_of_the_circle_through_the_via_point(kin, planner, home):
    via = ControllerPose(1000, 250, 900, 0, 45, 0)
    end = ControllerPose(800, 400, 700, 0, 30, 20)
    traj = planner.circ(home, via, end)
    p0, p1, p2 = np.array([1.120, 0, 0.725]), np.array([1.0, 0.25, 0.9]), np.array([0.8, 0.4, 0.7])
    # the circle, solved independently: centre c with |c-p0| = |c-p1| = |c-p2| in the plane of the points
    n = np.cross(p1 - p0, p2 - p0)
    a = np.array([2 * (p1 - p0), 2 * (p2 - p0), n])
    b = np.array([p1 @ p1 - p0 @ p0, p2 @ p2 - p0 @ p0, n @ p0])
    c = np.linalg.solve(a, b)
    radius = np.linalg.norm(p0 - c)
    n = n / np.linalg.norm(n)
    pts = _joint_chord_points(kin, traj)
    off_plane = (pts - c) @ n
    radial = np.linalg.norm(pts - c - off_plane[:, None] * n, axis=1) - radius
    assert np.max(np.hypot(off_plane, radial)) < TOL
    # it passes the via point (within a sample spacing) and ends at the end pose
    assert np.min(np.linalg.norm(traj.tcp[:, :3, 3] - p1, axis=1)) < planner.settings.max_cartesian_step
    dp, da = kin.fk_pose(traj.goal).distance_to(end)
    assert dp < 1e-6 and da < 1e-6
    _assert_within_limits(kin, traj)
    assert planner.plan("circ", home, end, via=via).duration == pytest.approx(traj.duration)


def test_random_moves_never_violate_position_or_velocity_limits(kin, planner):
    rng = random.Random(21)
    done = 0
    for i in range(12):
        start = kin.random_joints(rng)
        goal = kin.random_joints(rng)
        traj = planner.ptp_joints(start, goal)
        _assert_within_limits(kin, traj)
        # a short LIN from a random start, where it is feasible
        pose = kin.fk_pose(start)
        target = ControllerPose(pose.x + rng.uniform(-80, 80), pose.y + rng.uniform(-80, 80),
                                pose.z + rng.uniform(-80, 80), pose.rx, pose.ry, pose.rz)
        try:
            traj = planner.lin(start, target)
        except VrDriverError:
            continue
        _assert_within_limits(kin, traj)
        done += 1
    assert done >= 6


def test_unreachable_target_is_rejected_before_sampling(planner, home):
    with pytest.raises(UnreachableError, match="LIN target .*arm reaches"):
        planner.lin(home, (3000, 0, 725, 0, 45, 0))
    with pytest.raises(UnreachableError, match="PTP target"):
        planner.ptp(home, (3000, 0, 725, 0, 45, 0))


def test_lin_through_the_wrist_singularity_is_rejected_with_the_step(kin, planner):
    start = (0.0, 0.4, -0.3, 0.3, 0.2, 0.0)
    end = (0.0, 0.4, -0.3, 0.3, -0.2, 0.0)        # the straight line passes joint_5 = 0
    with pytest.raises((NearSingularError, MotionError), match=r"LIN step \d+ of \d+"):
        planner.lin(start, kin.fk_pose(end))


def test_lin_leaving_the_reach_mid_path_is_rejected(kin, planner):
    # both ends reachable, the straight line between them passes the base's axis too close (wrist
    # over the joint_1 axis): the path needs a joint_1 flip
    start = kin.ik_pose((400, -300, 900, 0, 90, 0), seed=kin.named_states["home"])
    with pytest.raises(VrDriverError, match=r"LIN step"):
        planner.lin(start, (-400, 300, 900, 0, 90, 0))


def test_circ_rejects_degenerate_geometry(planner, home):
    with pytest.raises(MotionError, match="collinear"):
        planner.circ(home, (1000, 0, 725, 0, 45, 0), (900, 0, 725, 0, 45, 0))
    with pytest.raises(MotionError, match="distinct"):
        planner.circ(home, (1120, 0, 725, 0, 45, 0), (900, 0, 725, 0, 45, 0))
    with pytest.raises(MotionError, match="needs a via"):
        planner.plan(MoveType.CIRC, home, (900, 0, 725, 0, 45, 0))


def test_bad_input_is_rejected(kin, planner, home):
    with pytest.raises(JointLimitError, match="joint_1"):
        planner.ptp((3.0, 0, 0, 0, 0, 0), HOME_POSE)
    with pytest.raises(PoseError, match="6 values"):
        planner.lin(home[:5], HOME_POSE)
    with pytest.raises(PoseError, match=r"target: .*Z \[mm\]"):
        planner.lin(home, (1000, 0, float("nan"), 0, 0, 0))
    with pytest.raises(MotionError, match="unknown move type"):
        planner.plan("spline", home, HOME_POSE)
    with pytest.raises(MotionError, match="velocity_scale"):
        MotionSettings(velocity_scale=0.0)


def test_velocity_scale_slows_the_move(kin, home):
    fast = MovePreviewer(kin).ptp_joints(home, (0.5, 0.2, -0.5, 1.0, 0.5, 1.0))
    slow = MovePreviewer(kin, MotionSettings(velocity_scale=0.5)).ptp_joints(home, (0.5, 0.2, -0.5, 1.0, 0.5, 1.0))
    assert slow.duration == pytest.approx(2 * fast.duration, rel=1e-9)
