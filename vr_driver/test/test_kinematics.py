"""vr_driver.kinematics.solver: URDF -> KDL chain, FK against hand computation, IK round trips, errors, CLI."""
from __future__ import annotations

import json
import math
import os
import random
import time

import numpy as np
import pytest
import yaml

from panasonic_vr006l_support.description import default_kinematics_yaml, render_urdf
from panasonic_vr006l_support.model import RobotModel
import vr_driver.kinematics.solver as kin_mod
from vr_driver.errors import (IkTimeoutError, JointLimitError, ModelError, NearSingularError,
                              PoseError, UnreachableError)
from vr_driver.kinematics.solver import IkSettings, Kinematics, UrdfModel, read_ik_settings, read_srdf
from vr_driver.poses import HOME_POSE, rpy_to_matrix

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MOVEIT = os.path.join(REPO, "panasonic_vr006l_moveit_config", "config")
N_RANDOM = 300


@pytest.fixture(scope="module")
def urdf():
    return render_urdf()


@pytest.fixture(scope="module")
def dims():
    with open(default_kinematics_yaml()) as f:
        data = yaml.safe_load(f)
    return {k: v["value"] for k, v in data["geometry"].items()}, data["joints"]


def _pose_error(kin, q, target):
    t = kin.fk(q)
    dp = float(np.linalg.norm(t[:3, 3] - target[:3, 3]))
    r = t[:3, :3].T @ target[:3, :3]
    da = math.acos(max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0)))
    return dp, da


# ------------------------------------------------------------------------------------------ the model

def test_chain_comes_from_the_srdf_and_limits_from_the_urdf(kin, dims):
    assert (kin.base, kin.tip) == ("base_link", "tool0")
    assert kin.joint_names == tuple("joint_%d" % i for i in range(1, 7))
    assert kin.chain.getNrOfJoints() == 6
    assert kin.chain.getNrOfSegments() == 8            # 6 joints + flange + tool0
    _, joints = dims
    for i, name in enumerate(kin.joint_names):
        assert kin.limits.lower[i] == joints[name]["lower"]
        assert kin.limits.upper[i] == joints[name]["upper"]
        assert kin.limits.velocity[i] == joints[name]["velocity"]
    assert set(kin.named_states) == {"home", "zero"}
    assert kin.has_analytic_solver, kin.analytic_reason


def test_solver_settings_come_from_kinematics_yaml():
    with open(os.path.join(MOVEIT, "kinematics.yaml")) as f:
        settings = read_ik_settings(f.read())
    assert settings.timeout == 0.005 and settings.attempts == 3
    with pytest.raises(ModelError, match="no entry for group 'arm'"):
        read_ik_settings("manipulator: {kinematics_solver_timeout: 0.01}", group="arm")
    with pytest.raises(ModelError, match="positive"):
        IkSettings(timeout=0.0)


def test_fk_of_zero_pose_matches_the_yaml_dimensions(kin, dims):
    g, _ = dims
    t = kin.fk([0.0] * 6)
    flange = (g["shoulder_offset"] + g["forearm"] + g["j5_to_flange"], 0.0,
              g["j2_height"] + g["upper_arm"] + g["elbow_offset"])
    assert np.allclose(t[:3, 3], flange, atol=1e-12)
    assert np.allclose(t[:3, :3], rpy_to_matrix(math.pi, -math.pi / 2, 0.0), atol=1e-12)  # tool0 = flange rotated
    pose = kin.fk_pose([0.0] * 6)
    assert np.allclose(pose.as_tuple(), (800.0, 0.0, 1110.0, 0.0, 0.0, 0.0), atol=1e-9)


def test_fk_of_home_matches_a_hand_computation(kin, dims):
    g, _ = dims
    q = kin.named_states["home"]
    q2, q3, q5 = q[1], q[2], q[4]
    theta = q2 + q3                      # forearm pitch (down positive); upper arm leans forward by q2
    elbow = np.array([g["shoulder_offset"] + g["upper_arm"] * math.sin(q2),
                      g["j2_height"] + g["upper_arm"] * math.cos(q2)])
    wrist = elbow + g["elbow_offset"] * np.array([math.sin(theta), math.cos(theta)]) \
        + g["forearm"] * np.array([math.cos(theta), -math.sin(theta)])
    flange = wrist + g["j5_to_flange"] * np.array([math.cos(theta + q5), -math.sin(theta + q5)])
    pose = kin.fk_pose(q)
    assert pose.x == pytest.approx(flange[0] * 1000, abs=1e-9)
    assert pose.z == pytest.approx(flange[1] * 1000, abs=1e-9)
    assert pose.y == pytest.approx(0.0, abs=1e-9)
    assert pose.ry == pytest.approx(math.degrees(theta + q5), abs=1e-9)
    # the SRDF's rounded home joints give the controller's home pose to well under a millimetre
    dp, da = pose.distance_to(HOME_POSE)
    assert dp < 0.5 and da < 0.01


def test_fk_agrees_with_the_independent_numpy_model(kin, urdf):
    model = RobotModel.from_urdf_string(urdf)
    rng = random.Random(7)
    for _ in range(50):
        q = kin.random_joints(rng)
        assert np.allclose(kin.fk(q), model.chain_fk("base_link", "tool0", np.array(q)), atol=1e-12)


def test_tcp_position_is_fk_pose_s_position_with_any_tcp_and_base(kin):
    """Kinematics.tcp_position (the fast path of the plan action's box) gives fk_pose's X, Y, Z, also
    after the conventions change (a TCP offset, a raised base)."""
    import copy
    from vr_driver.poses import FrameConventions
    rng = random.Random(9)
    other = copy.copy(kin)
    raised = np.eye(4)
    raised[:3, 3] = (0.1, -0.2, 0.3)
    for conv in (kin.conventions, kin.conventions.with_tcp((10.0, -20.0, 150.0, 5.0, 40.0, -30.0)),
                 FrameConventions(raised, kin.conventions.flange_in_tip, kin.conventions.tcp_in_flange)):
        other.conventions = conv
        for _ in range(30):
            q = kin.random_joints(rng)
            assert np.allclose(other.tcp_position(q), other.fk_pose(q).as_tuple()[:3], atol=1e-9)


def test_base_and_flange_frames_come_from_the_urdf(kin):
    conv = kin.conventions
    assert np.allclose(conv.base_in_root, np.eye(4))                       # base_frame_z = 0
    tip_at_zero = kin.fk([0.0] * 6)
    assert np.allclose((tip_at_zero @ conv.flange_in_tip)[:3, :3], np.eye(3), atol=1e-12)


# --------------------------------------------------------------------------------------------- IK

def test_ik_round_trips_from_random_and_neighbouring_seeds(kin):
    rng = random.Random(11)
    for i in range(N_RANDOM):
        q_true = kin.random_joints(rng)
        target = kin.fk(q_true)
        if i % 2:
            seed = kin.random_joints(rng)
        else:
            seed = tuple(v + rng.gauss(0.0, 0.02) for v in q_true)
        q = kin.ik(target, seed)
        dp, da = _pose_error(kin, q, target)
        assert dp < 1e-6 and da < 1e-6
        assert not kin.limit_violations(q)
        d_found = sum((a - b) ** 2 for a, b in zip(q, seed))
        d_true = sum((a - b) ** 2 for a, b in zip(q_true, seed))
        assert d_found <= d_true + 1e-9, "the solution is farther from the seed than a known one"


def test_ik_controller_pose_of_home_gives_the_home_joints(kin):
    q = kin.ik_pose(HOME_POSE, seed=kin.named_states["zero"])
    assert np.allclose(q, kin.named_states["home"], atol=1e-5)
    assert np.allclose(kin.fk_pose(q).as_tuple(), HOME_POSE.as_tuple(), atol=1e-6)


def test_wrist_takes_the_full_turn_nearest_the_seed(kin):
    q_true = (0.2, 0.4, -0.3, 0.5, 0.8, -0.5)
    target = kin.fk(q_true)
    q = kin.ik(target, seed=(0.2, 0.4, -0.3, 0.5, 0.8, 5.7))
    assert q[5] == pytest.approx(-0.5 + 2 * math.pi, abs=1e-9)
    q = kin.ik(target, seed=q_true)
    assert np.allclose(q, q_true, atol=1e-9)
    # joint_4 spans -3.316 ... 4.712: the seed near 4.2 picks q4 + 2 pi only if that fits
    q_true = (0.2, 0.4, -0.3, -2.0, 0.8, 0.1)
    q = kin.ik(kin.fk(q_true), seed=(0.2, 0.4, -0.3, 4.2, 0.8, 0.1))
    assert q[3] == pytest.approx(-2.0 + 2 * math.pi, abs=1e-9)


def test_wrist_singularity_keeps_the_seed_roll(kin):
    q_true = (0.1, 0.3, -0.2, 0.7, 0.0, -0.4)              # q5 = 0: only q4 + q6 is defined
    target = kin.fk(q_true)
    q = kin.ik(target, seed=(0.1, 0.3, -0.2, 0.2, 0.0, 0.0))
    assert q[3] == pytest.approx(0.2, abs=1e-9)
    assert q[3] + q[5] == pytest.approx(0.3, abs=1e-9)
    dp, da = _pose_error(kin, q, target)
    assert dp < 1e-6 and da < 1e-6
    with pytest.raises(NearSingularError, match="manipulability"):
        kin.ik(target, seed=q_true, min_manipulability=1e-3)
    assert kin.manipulability(kin.named_states["home"]) > 1e-2
    assert kin.manipulability(kin.named_states["zero"]) < 1e-6


def test_a_reported_pose_rounded_out_of_the_arms_configuration_keeps_the_seed(kin):
    """v1 reports whole mm / deg. The arm stretched out (wrist centre ~0.95 m out, J2 near its
    limit): the rounded pose lies just beyond the reach of the arm's own configuration, and the
    IK nearest the true joints is another one (J1 turned by 180 deg) -- a planner starting there
    plans the wrong path. track_pose keeps the seed, which lies within the rounding."""
    q_true = tuple(math.radians(v) for v in (86.16, -98.69, -73.85, 132.56, -103.28, 274.66))
    reported = tuple(float(round(v)) for v in kin.fk_pose(q_true).as_tuple())
    assert reported == (1.0, -950.0, 335.0, 164.0, -39.0, 20.0)
    other = kin.ik_pose(reported, seed=q_true)
    assert abs(other[0] - q_true[0]) == pytest.approx(math.pi, abs=0.01)
    assert kin.track_pose(reported, q_true) == pytest.approx(q_true, abs=1e-12)
    # on a pose the seed's configuration reaches: the solution nearest the seed, not the seed
    near = tuple(float(round(v)) for v in kin.fk_pose((0.2, 0.4, -0.3, 0.5, 0.8, -0.5)).as_tuple())
    q = kin.track_pose(near, (0.2, 0.4, -0.3, 0.5, 0.8, -0.5))
    assert q == pytest.approx(kin.ik_pose(near, seed=(0.2, 0.4, -0.3, 0.5, 0.8, -0.5)), abs=1e-12)
    assert q != pytest.approx((0.2, 0.4, -0.3, 0.5, 0.8, -0.5), abs=1e-6)
    # another configuration far from a seed that is not near the pose: that solution
    assert kin.track_pose(reported, (0.0,) * 6) == pytest.approx(kin.ik_pose(reported, seed=(0.0,) * 6))
    with pytest.raises(UnreachableError):
        kin.track_pose((1400.0, 0.0, 1400.0, 0.0, 0.0, 0.0), q_true)


def test_a_pose_rounded_past_the_reach_of_a_moving_arm_is_tracked_from_a_seed_degrees_away(kin):
    """v3 reports 0.1 mm / 0.01 deg. The elbow stretched out and the wrist near its singularity: the
    rounded pose lies 0.03 mm past the arm's reach, and the seed (the last solution, a bus cycle
    behind a fast arm) is degrees away, too far to stand for the pose. track_pose finds the nearest
    configuration that puts the tip within the rounding (it once lost the joints for that record)."""
    from vr_driver.poses import ControllerPose
    q_true = tuple(math.radians(v) for v in (87.32, 52.7, -77.52, -99.35, 1.52, -80.44))
    reported = ControllerPose(55.2, 1129.4, 1150.5, -179.08, -25.05, 85.67)      # FK, v3-rounded
    assert kin.fk_pose(q_true).distance_to(reported)[0] < 0.1
    with pytest.raises(UnreachableError, match="0.03 mm beyond its reach"):
        kin.ik_pose(reported, seed=q_true)
    seed = tuple(math.radians(v) for v in (89.34, 55.76, -72.25, -102.31, -1.5, -90.78))
    q = kin.track_pose(reported, seed)
    dp, da = kin.fk_pose(q).distance_to(reported)
    assert dp <= 0.2 and da <= 0.02
    # the arm's joints (joint_4 and joint_6 only in their sum, at the wrist singularity)
    for i in (0, 1, 2, 4):
        assert abs(q[i] - q_true[i]) < math.radians(1.5), (i, math.degrees(q[i]), math.degrees(q_true[i]))
    assert abs((q[3] + q[5]) - (q_true[3] + q_true[5])) < math.radians(0.5)


def test_jacobian_matches_finite_differences_of_fk(kin):
    q = np.array([0.3, 0.2, -0.4, 0.5, 0.6, -0.7])
    jac = kin.jacobian(q)
    h = 1e-7
    for c in range(6):
        dq = np.zeros(6)
        dq[c] = h
        dp = (kin.fk(q + dq)[:3, 3] - kin.fk(q - dq)[:3, 3]) / (2 * h)
        assert np.allclose(jac[:3, c], dp, atol=1e-6)


def test_unreachable_pose_fails_fast_with_the_reason(kin):
    budget = kin.settings.timeout
    for pose in [(3000, 0, 725, 0, 45, 0), (0, 0, 5000, 0, 0, 0)]:
        t0 = time.perf_counter()
        with pytest.raises(UnreachableError, match="arm reaches"):
            kin.ik_pose(pose)
        assert time.perf_counter() - t0 < 10 * budget
    # the numeric path: the reach check answers before any search
    t0 = time.perf_counter()
    with pytest.raises(UnreachableError, match="beyond the chain's total length"):
        kin.ik_pose((3000, 0, 725, 0, 45, 0), numeric=True)
    assert time.perf_counter() - t0 < 10 * budget


def test_numeric_search_gives_up_within_the_budget(kin):
    # inside the chain's length bound (~1.96 m) but unreachable (the wrist centre 1.16 m from the
    # shoulder, the arm stretches to 1.135 m): the numeric path restarts NR_JL until the budget is spent;
    # the analytic path says why at once
    target = kin.fk([0.0] * 6)
    target[:3, 3] = (1.4, 0.0, 0.42)
    assert np.linalg.norm(target[:3, 3]) < kin.reach_bound
    t0 = time.perf_counter()
    with pytest.raises(IkTimeoutError, match="budget"):
        kin.ik(target, numeric=True, rng=random.Random(1))
    assert time.perf_counter() - t0 < 10 * kin.settings.timeout
    with pytest.raises(UnreachableError, match="from the shoulder"):
        kin.ik(target)


def test_reachable_only_outside_limits_raises_joint_limit_error(kin):
    target = kin.fk((3.0, 0.3, -0.5, 0.0, 0.5, 0.0))         # joint_1 = 3.0 is beyond 2.705
    with pytest.raises(JointLimitError, match=r"joint_1 .*limits \[-2.7050, 2.7050\]"):
        kin.ik(target)
    with pytest.raises(JointLimitError, match="joint_3 = -3.5"):
        kin.check_limits((0, 0, -3.5, 0, 0, 0))


def test_numeric_path_round_trips(kin):
    rng = random.Random(3)
    for i in range(40):
        q_true = kin.random_joints(rng)
        target = kin.fk(q_true)
        seed = tuple(v + rng.gauss(0.0, 0.05) for v in q_true) if i % 2 else None
        q = kin.ik(target, seed, numeric=True, rng=random.Random(i), timeout=0.05)
        dp, da = _pose_error(kin, q, target)
        assert dp < 1e-6 and da < 1e-6 and not kin.limit_violations(q)


def test_a_chain_without_the_analytic_structure_falls_back_to_kdl(urdf):
    # move joint_6 off the wrist centre: the wrist is no longer spherical
    xml = urdf
    model = UrdfModel.from_string(urdf)
    j6 = model.joints["joint_6"]
    old = 'xyz="%s"' % " ".join(_fmt(v) for v in j6.xyz)
    assert old in xml
    start = xml.index('<joint name="joint_6"')
    xml = xml[:start] + xml[start:].replace(old, 'xyz="0 0.03 0"', 1)
    kin = Kinematics.from_urdf_string(xml)
    assert not kin.has_analytic_solver and "wrist" in kin.analytic_reason
    rng = random.Random(5)
    for _ in range(10):
        q_true = kin.random_joints(rng)
        target = kin.fk(q_true)
        q = kin.ik(target, tuple(v + 0.03 for v in q_true), rng=random.Random(1), timeout=0.05)
        dp, da = _pose_error(kin, q, target)
        assert dp < 1e-6 and da < 1e-6


def _fmt(v):
    return ("%g" % v) if v != 0 else "0"


def test_the_ik_search_and_the_joint_limits_stand_on_their_own(kin):
    """kinematics.ik.IkSolver (the IK search) and kinematics.limits.JointLimits (the joint-space
    operations), built on their own from the chain, answer as the Kinematics that delegates to
    them; the names older code imports from kinematics.solver are theirs."""
    from vr_driver.kinematics import analytic, ik, limits
    assert (kin_mod.IkSettings, kin_mod.JointLimits, kin_mod.model_accelerations) == (
        ik.IkSettings, limits.JointLimits, limits.model_accelerations)
    assert isinstance(kin.ik_solver.analytic, analytic.AnalyticSolver)
    movable = [j for j in kin.chain_joints if j.movable]
    lim = limits.JointLimits.of_joints(movable)
    assert lim == kin.limits
    solver = ik.IkSolver(kin.chain_joints, kin.chain, lim, kin.settings)
    rng = random.Random(3)
    for _ in range(20):
        q_true, seed = kin.random_joints(rng), kin.random_joints(rng)
        target = kin.fk(q_true)
        r, p = ik.rotation_and_position(target)
        assert solver.nearest(r, p, seed, time.perf_counter() + 1.0, 1.0, random.Random(1)) == kin.ik(target, seed)
        assert solver.solutions(r, p, seed) == kin.ik_solutions(target, seed)
    assert lim.clamp([10.0] * 6) == lim.upper and lim.clamp([-10.0] * 6) == lim.lower
    assert [v.split(" =")[0] for v in lim.violations((0.0, 0.0, 10.0, 0.0, -10.0, 0.0))] == ["joint_3", "joint_5"]
    assert not lim.violations(lim.random_joints(rng))
    with pytest.raises(ModelError, match="joint_2: acceleration limit must be a number > 0, got 0"):
        limits.JointLimits.of_joints(movable, accelerations={"joint_1": 1.0, "joint_2": 0})



def test_the_analytic_solvers_nearest_mode_finds_the_same_first_candidate(kin):
    """``AnalyticSolver.solve(..., nearest=True)`` (what ``kin.ik`` asks first: the arm branches
    nearest the seed first, those farther than a candidate found not solved) puts first the same
    candidate as the full solve -- to the last bit -- on random poses and seeds, near joint_5 = 0
    and with seeds a turn off; it solves fewer (the point of it), and ``kin.ik`` returns that
    candidate, the full list's first."""
    from vr_driver.kinematics.ik import rotation_and_position
    solver = kin.ik_solver.analytic
    lo, hi = kin.limits.lower, kin.limits.upper
    rng = random.Random(46)
    fewer = 0
    for i in range(400):
        q = list(kin.random_joints(rng))
        if i % 3 == 0:
            q[4] = rng.uniform(-0.01, 0.01)
        seed = tuple(v + rng.gauss(0.0, 0.3 if i % 2 else 3.0) for v in q)
        r, p = rotation_and_position(kin.fk(q))
        full = solver.solve(r, p, seed, lo, hi)[0]
        first = solver.solve(r, p, seed, lo, hi, nearest=True)[0]
        assert first[:1] == full[:1]
        fewer += len(first) < len(full)
        if full:
            assert kin.ik(kin.fk(q), seed) == full[0][1]
        else:                       # (no branch within the limits: the full solve's words)
            with pytest.raises(JointLimitError):
                kin.ik(kin.fk(q), seed)
    assert fewer > 200


# ------------------------------------------------------------------------------------- bad input

def test_bad_inputs_raise_pose_error(kin):
    with pytest.raises(PoseError, match="6 values"):
        kin.fk([0.0] * 5)
    with pytest.raises(PoseError, match="joint_3 must be a finite number"):
        kin.fk([0, 0, float("nan"), 0, 0, 0])
    with pytest.raises(PoseError, match=r"unknown joint names \['joint_7'\]"):
        kin.joint_vector({"joint_%d" % i: 0.0 for i in range(2, 8)})
    with pytest.raises(PoseError, match="missing joints"):
        kin.joint_vector({"joint_1": 0.0})
    assert kin.joint_vector({"joint_%d" % i: float(i) for i in range(1, 7)}) == (1, 2, 3, 4, 5, 6)
    target = kin.fk([0.0] * 6)
    target[0, 3] = float("inf")
    with pytest.raises(PoseError, match="NaN or inf"):
        kin.ik(target)
    with pytest.raises(PoseError, match="not a rotation"):
        kin.ik(np.diag([1.0, 2.0, 1.0, 1.0]))
    with pytest.raises(PoseError, match="seed|6 values"):
        kin.ik(kin.fk([0.0] * 6), seed=[0.0] * 4)
    with pytest.raises(PoseError, match=r"Rz \[deg\]"):
        kin.ik_pose((1120, 0, 725, 0, 45, float("nan")))


def test_model_errors_say_what_is_wrong(urdf):
    with pytest.raises(ModelError, match="not valid XML"):
        Kinematics.from_urdf_string("<robot>")
    with pytest.raises(ModelError, match="link 'nowhere' is not in the URDF"):
        Kinematics.from_urdf_string(urdf, tip="nowhere")
    with pytest.raises(ModelError, match="no kinematic chain from tool0 to base_link"):
        Kinematics.from_urdf_string(urdf, base="tool0", tip="base_link")
    with open(os.path.join(MOVEIT, "panasonic_vr006l.srdf")) as f:
        srdf = f.read()
    assert read_srdf(srdf)[:2] == ("base_link", "tool0")
    with pytest.raises(ModelError, match="no chain group 'arm'"):
        Kinematics.from_urdf_string(urdf, srdf, group="arm")
    with pytest.raises(ModelError, match="joint type 'floating'"):
        Kinematics.from_urdf_string(urdf.replace('type="revolute"', 'type="floating"', 1))


def test_from_files_reads_the_moveit_config(tmp_path, urdf):
    path = tmp_path / "robot.urdf"
    path.write_text(urdf)
    kin = Kinematics.from_files(str(path), os.path.join(MOVEIT, "panasonic_vr006l.srdf"),
                                os.path.join(MOVEIT, "kinematics.yaml"))
    assert kin.tip == "tool0" and kin.settings.timeout == 0.005
    with pytest.raises(ModelError, match="cannot read"):
        Kinematics.from_files(str(tmp_path / "missing.urdf"))


# -------------------------------------------------------------------------------------------- CLI

def _run(capsys, *argv):
    code = kin_mod.main(list(argv))
    out = capsys.readouterr().out.strip()
    return code, (json.loads(out) if out else None)


def test_cli_fk_and_ik(capsys):
    code, out = _run(capsys, "fk", "0", "0", "0", "0", "0", "0")
    assert code == 0 and out["reachable"] and out["error"] is None
    assert out["pose"] == pytest.approx([800, 0, 1110, 0, 0, 0], abs=1e-6)
    code, out = _run(capsys, "ik", "1120", "0", "725", "0", "45", "0", "--seed", "0", "0", "0", "0", "0", "0")
    assert code == 0 and out["joints"] == pytest.approx([0, 0.645469, -0.280043, 0, 0.419972, 0], abs=1e-5)
    code, out = _run(capsys, "ik", "3000", "0", "725", "0", "45", "0")
    assert code == 3 and out["reachable"] is False and "UnreachableError" in out["error"]
    code, out = _run(capsys, "fk", "3", "0", "0", "0", "0", "0")
    assert code == 3 and "joint_1" in out["error"]


def test_cli_usage_errors_exit_2(capsys):
    assert _run(capsys, "ik", "1", "2")[0] == 2
    assert _run(capsys, "fk", "0", "0", "x", "0", "0", "0")[0] == 2
    assert _run(capsys, "ik", "1120", "0", "725", "0", "nan", "0")[0] == 2
    assert kin_mod.main([]) == 2
    assert kin_mod.main(["bogus"]) == 2


def test_kinematics_reads_the_urdf_with_the_support_packages_reader(urdf):
    """One URDF reader: UrdfModel is panasonic_vr006l_support's RobotModel with our ModelError."""
    from panasonic_vr006l_support import model as support_model
    import vr_driver.kinematics.solver as kinematics
    assert issubclass(UrdfModel, support_model.RobotModel) and kinematics.UrdfJoint is support_model.Joint
    assert not hasattr(kinematics, "_floats")
    model = UrdfModel.from_string(urdf)
    assert [j.name for j in model.chain("base_link", "tool0")] == [
        j.name for j in support_model.RobotModel.from_urdf_string(urdf).chain("base_link", "tool0")]
    mimic = urdf.replace('<joint name="joint_6" type="revolute">',
                         '<joint name="joint_6" type="revolute"><mimic joint="joint_5"/>', 1)
    assert mimic != urdf
    with pytest.raises(ModelError, match="joint_6: mimic joints are not supported"):
        UrdfModel.from_string(mimic)
