"""The plan action's core (driver/planning/planning.py) on a stepped world of the example cell with the fake
clock: a pose behind the pillar is planned from the arm's joints against a snapshot of the driver's
checker, inside the workspace box, and what it plans is accepted and run by the driver's own
trajectory path (protocol v3) with every sample free; refusals come back as codes and words naming
the link and the object; a scene change reaches the next plan; missing libraries give
MissingDependency. Skipped, with the reason, where OMPL, TOPP-RA, pinocchio or coal are missing."""
from __future__ import annotations

import math
import os

import pytest

from _world import World
from vr_driver.driver.planning import planning as P
from vr_driver.driver.planning.planning import CellValidity, PlanActionCore, PlanGoal, arm_points, code_of
from vr_driver.driver.motion.trajectories import TrajectoryGoal, validate
from vr_driver.errors import MissingDependency
from vr_driver.kinematics import deps
from vr_driver.kinematics.planner import PlanningError
from vr_driver.kinematics.scene import SceneObject
from vr_driver.poses import ControllerPose

_MISSING = deps.missing_dependencies(("ompl", "toppra", "pinocchio", "coal"))
pytestmark = pytest.mark.skipif(bool(_MISSING), reason="; ".join(r for _, r in _MISSING))

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")
#: behind the pillar (45 deg left, 0.88 m out) at home's height and tool tilt: a straight PTP from
#: home sweeps link_4 160 mm deep through the pillar
BEHIND = ControllerPose(500, 866, 725, 0, 45, 60)
NAMES = tuple("joint_%d" % i for i in range(1, 7))
#: a joint goal in front, clear of the cell and of the wrist singularity (the SRDF's zero has
#: joint_5 = 0, where v3's controller may take another wrist depending on the approach)
AWAY = PlanGoal(joints=(NAMES, (0.3, 0.5, -0.2, 0.0, 0.5, 0.0)))
#: the workspace box widened to the arm's reach: the stretched arm is outside the driver's default box
REACH = {"x": [-2000.0, 2000.0], "y": [-2000.0, 2000.0], "z": [-1000.0, 2500.0], "angle": [-180.0, 180.0]}


def world(kin, protocol="v3", **params):
    """The stepped world with the example cell. The planner's budget is wall-clock time (OMPL) and
    RRTConnect returns at its first path: 20 s only bounds a failure (the default 1 s ran out on a
    loaded machine: 'found no path within 1 s (Timeout)'). Plans at the full speed (velocity_scaling
    1; the driver's default, 0.1, makes every run ten times as long)."""
    w = World(kin, dict(dict(scene=CELL, planning_time=20.0, velocity_scaling=1.0), **params), protocol=protocol)
    w.ready()
    return w


def free_with(checker, positions):
    return [k for k, q in enumerate(positions) if checker.in_collision(q)]


def test_a_pose_behind_the_pillar_is_planned_accepted_and_run_by_the_driver(kin):
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    start = w.status().joints
    out = planning.plan(PlanGoal(pose=BEHIND), seed=1)
    assert out.ok and out.code == P.SUCCESS, out.text
    plan = out.trajectory
    # the call's profile: the planner's steps and the driver's stream check took time, the
    # validity was asked, one try per plan made (a re-plan gives its reason)
    prof = out.profile
    assert prof["tries"] == 1 + len(prof["replans"]) and prof["checks"] > 0
    assert prof["planner"] > 0.0 and prof["stream_check"] > 0.0 and prof["plan"] > 0.0
    assert prof["planner"] + prof["stream_check"] + prof["crossing"] <= out.planning_time + 1e-3
    assert out.text.startswith("planned with RRTConnect in ") and "over %.2f s" % plan.duration in out.text
    assert plan.positions[0] == pytest.approx(start, abs=1e-9)
    dp, da = out.target.distance_to(BEHIND)
    assert dp < 0.01 and da < 0.01
    # every sample free of the cell (the driver's padding) and its TCP inside the workspace box
    assert free_with(w.core.collision.copy(), plan.positions) == []
    assert all(w.core.params.workspace.contains(kin.fk_pose(q)) for q in plan.positions)
    # the straight move there is not: the planner had something to do
    straight = [tuple(a + (b - a) * k / 50 for a, b in zip(start, plan.goal)) for k in range(51)]
    assert free_with(w.core.collision.copy(), straight) != []
    # the driver's own checks accept it and run it (v3: Cartesian targets streamed) to the end
    names = w.core.joint_names
    lim = kin.limits
    traj = validate(TrajectoryGoal(names, plan.positions, plan.times), names, w.status().joints, lim.lower,
                    lim.upper, w.now)
    run = w.core.submit_trajectory(traj)
    w.run_until(lambda: run.done, 30.0, "trajectory done")
    assert run.success
    final = w.status().joints
    assert max(abs(a - b) for a, b in zip(final, plan.goal)) < 0.01


def test_the_workspace_box_bounds_every_sample(kin):
    """With the top of the box at 1000 mm the plan stays under it (less the clearance), where the
    plan with the default box rises higher: the box is part of the planner's validity."""
    w = world(kin, workspace={"z": [0.0, 1000.0]})
    out = PlanActionCore(w.core, kinematics=kin).plan(PlanGoal(pose=BEHIND), seed=1)
    assert out.ok, out.text
    top = max(kin.fk_pose(q).z for q in out.trajectory.positions)
    assert top <= 1000.0 - 9.0, top


def test_a_goal_in_collision_names_the_link_and_the_object(kin):
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    out = planning.plan(PlanGoal(pose=ControllerPose(1100, 0, 200, 0, 90, 0)))     # into the table
    assert out.code == P.GOAL_IN_COLLISION and out.trajectory is None
    assert out.text.startswith("goal refused: ") and "with object table" in out.text, out.text
    assert any(c.other == "table" for c in out.contacts)


def test_a_scene_change_reaches_the_next_plan(kin):
    """A box where the goal is: the next plan is refused naming it, and the roadmap of the plans
    before is dropped (it was the cell without the box); removed: planned again."""
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    goal = AWAY
    assert planning.plan(goal).ok
    planning.roadmap.add([kin.named_states["home"], AWAY.joints[1]])
    x, y, z = kin.fk_pose(AWAY.joints[1]).position_m
    w.core.add_scene_object(SceneObject("crate", "box", (0.1, 0.1, 0.1), (x, y, z)))
    out = planning.plan(goal)
    assert out.code == P.GOAL_IN_COLLISION and "with object crate" in out.text, out.text
    assert len(planning.roadmap) == 0 and planning.roadmap.counts["dropped"] == 1
    w.core.remove_scene_object("crate")
    assert planning.plan(goal).ok


def test_a_start_in_collision_is_refused_naming_it(kin):
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    inside = (0.0, 1.0, 0.0, 0.0, 1.0, 0.0)            # leaning forward, the wrist in the table
    out = planning.plan(PlanGoal(named="home"), start=inside)
    assert out.code == P.START_STATE_IN_COLLISION, out.text
    assert out.text.startswith("cannot plan from here: ") and "table" in out.text


@pytest.mark.parametrize("goal, words", [
    (PlanGoal(named="nowhere"), "unknown named state 'nowhere'"),
    (PlanGoal(named="home", velocity_scaling=1.5), "velocity_scaling must be in (0, 1]"),
    (PlanGoal(named="home", planning_time=-1.0), "allowed_planning_time must be in (0, 60]"),
    (PlanGoal(named="home", planner_id="Dijkstra"), "unknown planner_id 'Dijkstra'"),
    (PlanGoal(), "exactly one of joints, a named state or a pose (got 0)"),
    (PlanGoal(named="home", pose=BEHIND), "exactly one of joints, a named state or a pose (got 2)"),
    (PlanGoal(pose=ControllerPose(1500, 0, 700, 0, 45, 0)), "X = 1500 mm is outside the workspace"),
    (PlanGoal(joints=(("joint_1", "joint_2"), (0.0, 0.0))), "names every joint of the arm"),
    (PlanGoal(joints=(tuple("joint_%d" % i for i in range(1, 7)), (0.0,) * 5)), "one position per joint name"),
    (PlanGoal(joints=(tuple("joint_%d" % i for i in range(1, 7)), (0.0, 0.0, float("nan"), 0, 0, 0))),
     "finite"),
    (PlanGoal(joints=(tuple("joint_%d" % i for i in range(1, 7)), (9.0, 0.0, 0.0, 0, 0, 0))),
     "outside the joint limits"),
])
def test_bad_goals_are_refused_in_words(kin, goal, words):
    w = world(kin)
    out = PlanActionCore(w.core, kinematics=kin).plan(goal)
    assert out.code == P.INVALID_GOAL and out.trajectory is None
    assert words in out.text, out.text
    w.run_for(0.5)
    assert w.executed() == []


def test_a_joint_goal_in_any_name_order(kin):
    w = world(kin)
    names = tuple("joint_%d" % i for i in range(6, 0, -1))
    zero = (0.0,) * 6
    out = PlanActionCore(w.core, kinematics=kin).plan(PlanGoal(joints=(names, zero)))
    assert out.ok, out.text
    assert out.trajectory.goal == pytest.approx(zero, abs=1e-9)


def test_codes_of_the_planner_refusals():
    assert code_of(PlanningError("start", "start (...) is in collision: x", ("c",))) == P.START_STATE_IN_COLLISION
    assert code_of(PlanningError("start", "start is outside the joint limits")) == P.INVALID_ROBOT_STATE
    assert code_of(PlanningError("goal", "goal pose unreachable: far")) == P.NO_IK_SOLUTION
    assert code_of(PlanningError("goal", "all 8 joint solutions of the goal pose are in collision")) \
        == P.GOAL_IN_COLLISION
    assert code_of(PlanningError("goal", "unknown named state 'x'")) == P.INVALID_GOAL
    assert code_of(PlanningError("plan", "RRTConnect found no path")) == P.PLANNING_FAILED
    assert code_of(PlanningError("check", "sample 3 ...")) == P.INVALID_MOTION_PLAN


def test_cell_validity_is_a_padded_copy_and_names_the_box(kin):
    w = world(kin)
    v = CellValidity(w.core.collision.copy(), kin, w.core.params.workspace)
    home = kin.named_states["home"]
    assert not v.in_collision(home)
    strict = v.copy()
    strict.set_padding(v.padding + 0.01)
    assert strict.margin == pytest.approx(10.0) and v.margin == 0.0
    assert strict.checker is not v.checker and strict.checker.padding == pytest.approx(v.padding + 0.01)
    up = (0.0, 0.0, -1.5, 0.0, 0.0, 0.0)          # the forearm raised: the flange above z = 1400 mm
    assert kin.fk_pose(up).z > 1400.0
    assert v.in_collision(up)
    words = [str(c) for c in v.contacts(up)]
    assert any(t.startswith("the TCP outside the workspace box (Z by ") for t in words), words


def test_cell_validity_checks_the_box_by_the_checker_s_kinematics_as_by_kdl(kin):
    """The box and the collisions by the checker's one forward kinematics give the verdicts of the
    KDL path (the TCP by Kinematics.tcp_position, then the checker) on random configurations, in a
    box small enough that the TCP leaves it on every side; with a TCP offset too."""
    import random
    w = world(kin)
    from vr_driver.poses import Workspace
    box = Workspace.from_dict({"x": [200.0, 1200.0], "y": [-700.0, 700.0], "z": [100.0, 1300.0]})
    rng = random.Random(5)
    qs = [kin.random_joints(rng) for _ in range(400)]
    for k in (kin, _with_tcp(kin)):
        fast = CellValidity(w.core.collision.copy(), k, box, margin=10.0)
        slow = CellValidity(w.core.collision.copy(), k, box, margin=10.0)
        slow._tcp = False                                   # the KDL path
        assert fast._tcp_by_checker()
        verdicts = [fast.in_collision(q) for q in qs]
        assert verdicts == [slow.in_collision(q) for q in qs]
        outside = [q for q in qs if slow._outside(q) is not None]
        hits = [q for q in qs if w.core.collision.in_collision(q)]
        assert outside and hits and not all(verdicts)       # each reason occurs, and free ones too
        assert fast.counter[0] == len(qs)


def test_the_batch_validity_is_the_one_state_validity(kin):
    """CellValidity.first_invalid (the collisions in one call, then the box) and the plan action's
    planning validity (the wrist and elbow margins in numpy) find the row the one-state tests find
    first, on random rows and on rows along random motions (brute force; a box small enough to be
    left, the margins hit)."""
    import numpy as np
    from vr_driver.kinematics.solver import stretched_elbow
    from vr_driver.poses import Workspace
    w = world(kin)
    box = Workspace.from_dict({"x": [200.0, 1200.0], "y": [-700.0, 700.0], "z": [100.0, 1300.0]})
    planning = PlanActionCore(w.core, kinematics=kin)
    rng = np.random.default_rng(6)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    ends = lo + rng.random((41, 6)) * (hi - lo)
    ends[::4, 4] = rng.uniform(-0.06, 0.06, 11)                   # near the wrist singularity
    ends[1::4, 2] = stretched_elbow(kin) + rng.uniform(-0.15, 0.15, 10)   # near the stretch
    batches = [ends[k:k + 8] for k in range(0, 40, 8)]
    batches += [a + np.linspace(0.0, 1.0, 30)[:, None] * (b - a) for a, b in zip(ends[:20], ends[1:21])]
    for validity in (CellValidity(w.core.collision.copy(), kin, box, margin=10.0), planning.snapshot()):
        for valid in (lambda q: not validity.in_collision(q), planning._planning_validity(validity),
                      planning._planning_validity(validity, wrist_margin=False)):
            free = np.array([q for q in lo + rng.random((400, 6)) * (hi - lo) if valid(tuple(q))][:10])
            firsts = []
            for qs in batches + [free, np.concatenate([free, ends[:3]])]:
                expected = next((i for i, q in enumerate(qs) if not valid(tuple(q))), None)
                batch = valid.first_invalid if hasattr(valid, "first_invalid") else validity.first_invalid
                assert batch(qs) == expected
                firsts.append(expected)
            assert None in firsts and 0 in firsts and any(f for f in firsts)   # free, at once, later


def test_a_box_that_holds_every_tcp_is_not_checked_and_changes_no_verdict(kin):
    """A box wider than the TCP's reach (the planning bench's, the arm's whole reach) holds every
    TCP: CellValidity skips the box there, with the verdicts (one state, and the first invalid row
    of batches along random motions) of the validity that checks it; the bound it proves that by
    holds on random configurations, with a TCP offset too; a narrower box, or a margin that eats
    the room, is checked."""
    import numpy as np
    from vr_driver.poses import Workspace
    w = world(kin)
    wide = Workspace.from_dict({"x": [-2000.0, 2000.0], "y": [-2000.0, 2000.0], "z": [-1200.0, 2500.0]})
    rng = np.random.default_rng(8)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    for k in (kin, _with_tcp(kin)):
        skip = CellValidity(w.core.collision.copy(), k, wide, margin=10.0)
        check = CellValidity(w.core.collision.copy(), k, wide, margin=10.0)
        check._reach = False                                # the box checked as before
        assert skip.box_holds_every_tcp() and not check.box_holds_every_tcp()
        centre, half = skip._reach_ball()
        tcp = np.array([k.tcp_position(tuple(q)) for q in lo + rng.random((3000, 6)) * (hi - lo)])
        assert np.all(np.abs(tcp - centre) <= half)
        assert np.max(np.abs(tcp - centre) / half) > 0.8     # (a bound, not a box far off)
        qs = lo + rng.random((300, 6)) * (hi - lo)
        verdicts = [skip.in_collision(tuple(q)) for q in qs]
        assert verdicts == [check.in_collision(tuple(q)) for q in qs] and any(verdicts) and not all(verdicts)
        firsts = []
        for a, b in zip(qs[:40], qs[1:41]):
            motion = a + np.linspace(0.0, 1.0, 25)[:, None] * (b - a)
            firsts.append(skip.first_invalid(motion))
            assert firsts[-1] == check.first_invalid(motion)
        assert None in firsts and any(f for f in firsts)
        assert skip.counter[0] == check.counter[0]
        assert not CellValidity(w.core.collision.copy(), k, w.core.params.workspace).box_holds_every_tcp()
        skip.set_padding(skip.padding + 0.4)                # 400 mm more of margin: z no longer holds
        assert not skip.box_holds_every_tcp()


def _with_tcp(kin):
    import copy
    out = copy.copy(kin)
    out.conventions = kin.conventions.with_tcp((0.0, 50.0, 120.0, 0.0, 30.0, 0.0))
    out._tcp_frames = None
    return out


def test_a_pose_s_solutions_on_the_start_s_wrist_side_come_first_while_the_margin_holds(kin):
    """v3: a pose goal's IK solutions with joint_5 across 0 from the start rank after those on its
    side while the plan keeps the wrist margin (it walls joint_5 = 0 off), not on the last try
    (no margin) nor from a start within the margin; the elbow's rank comes first; v2: no rank."""
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    rank, last = planning._candidate_rank(wrist=True), planning._candidate_rank(wrist=False)
    start = (0.0, 0.3, -0.3, 0.0, 0.5, 0.0)
    same, across = (0.5, 0.4, -0.2, 1.0, 0.4, 0.5), (0.5, 0.4, -0.2, -2.1, -0.4, -2.6)
    assert rank(start, same) == 0 and rank(start, across) == 1
    assert last(start, same) == 0 and last(start, across) == 0
    assert rank((0.0, 0.3, -0.3, 0.0, 0.02, 0.0), across) == 0          # within the 3 deg margin
    elbow = planning._goal_preference()
    other_branch = (0.5, 0.4, -2.6, 1.0, 0.4, 0.5)
    assert elbow(start, other_branch) == 1 and rank(start, other_branch) == 2 > rank(start, across)
    assert PlanActionCore(world(kin, "v2").core, kinematics=kin)._candidate_rank(wrist=True) is None


def test_arm_points_run_from_the_base_to_the_tcp(kin):
    home = kin.named_states["home"]
    pts = arm_points(kin, home)
    assert pts[0] == (0.0, 0.0, 0.0) and len(pts) >= 5
    assert pts[-1] == pytest.approx(tuple(kin.fk(home)[:3, 3]), abs=1e-9)


def test_missing_libraries_are_named(kin, monkeypatch):
    w = world(kin)
    real = deps.require

    def without_ompl(module, feature=""):
        if module == "ompl":
            raise MissingDependency("ompl", "ompl", feature, "ModuleNotFoundError: No module named 'ompl'")
        return real(module, feature)
    monkeypatch.setattr(deps, "require", without_ompl)
    with pytest.raises(MissingDependency) as err:
        PlanActionCore(w.core, kinematics=kin)
    assert "ompl" in str(err.value)


def test_no_checker_while_collisions_are_to_be_checked_is_a_missing_dependency(kin, monkeypatch):
    w = world(kin, scene="")
    monkeypatch.setattr(type(w.core), "collision", property(lambda self: None))
    with pytest.raises(MissingDependency, match="no collision checker"):
        PlanActionCore(w.core, kinematics=kin)


def test_collision_check_off_plans_with_the_box_only_and_says_so(kin):
    w = world(kin, scene="", collision_check=False)
    out = PlanActionCore(w.core, kinematics=kin).plan(AWAY)
    assert out.ok and out.text.endswith("collisions NOT checked (collision_check: false)"), out.text


def test_a_cartesian_protocol_plans_away_from_the_wrist_singularity(kin):
    """v3: the planner's own validity (away from the start and the goal) keeps |joint_5| >= the
    margin, where the controller's nearest-solution IK could pick another wrist; v2 (joint targets)
    does not need it."""
    bent = (0.3, 0.3, -0.3, 0.0, P.WRIST_MARGIN / 2, 0.0)
    for protocol, expected in (("v3", False), ("v2", True)):
        w = world(kin, protocol=protocol)
        planning = PlanActionCore(w.core, kinematics=kin)
        valid = planning._planning_validity(planning.snapshot())
        assert valid(bent) is expected, protocol
        assert valid(bent[:4] + (2 * P.WRIST_MARGIN, 0.0))


def test_a_cartesian_protocol_plans_away_from_the_stretched_elbow(kin):
    """v3: near the stretched-out arm a pose's two elbow branches lie within a few degrees (at
    joint_3 = stretch +- 7 deg the controller's IK of the rounded pose was seen on the other one):
    the planner keeps joint_3 ELBOW_MARGIN from the stretch (but on the last try, as for the wrist);
    v2 does not need it."""
    from vr_driver.kinematics.solver import stretched_elbow
    stretch = stretched_elbow(kin)
    # the two elbow branches of a pose meet there: the stretch is where they are nearest
    near = (0.3, 0.2, stretch + P.ELBOW_MARGIN / 2, 0.0, 0.5, 0.0)
    clear = near[:2] + (stretch + 2 * P.ELBOW_MARGIN,) + near[3:]
    sols = kin.ik_solutions(kin.fk(near))
    assert min(abs(q[2] - near[2]) for q in sols if abs(q[2] - near[2]) > 1e-6) <= 1.1 * P.ELBOW_MARGIN
    for protocol, expected in (("v3", False), ("v2", True)):
        w = world(kin, protocol=protocol, workspace=REACH)
        planning = PlanActionCore(w.core, kinematics=kin)
        valid = planning._planning_validity(planning.snapshot())
        assert valid(near) is expected, protocol
        assert valid(clear), protocol
        assert planning._planning_validity(planning.snapshot(), elbow_margin=False)(near)
        assert planning._planning_validity(planning.snapshot(), wrist_margin=False)(near) is expected


def test_a_plan_the_driver_would_refuse_is_planned_again(kin, monkeypatch):
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    answers = ["point 3 of 9: the controller would reach its pose in another configuration", ""]
    seen = []

    def refusal(plan):
        seen.append(plan)
        return answers.pop(0) if answers else ""
    monkeypatch.setattr(planning, "driver_refusal", refusal)
    out = planning.plan(PlanGoal(pose=BEHIND), seed=3)
    assert out.ok, out.text
    assert len(seen) == 2 and out.trajectory is seen[1]
    # refused every time: no plan, the last refusal in words
    monkeypatch.setattr(planning, "driver_refusal", lambda plan: "segment 2 of 5: refused")
    out = planning.plan(PlanGoal(pose=BEHIND), seed=3)
    assert out.code == P.INVALID_MOTION_PLAN and out.trajectory is None
    assert out.text == "the driver would refuse each of %d plans, the last: segment 2 of 5: refused" % P.ATTEMPTS


def test_the_last_try_from_where_a_plan_ended_retreats_along_its_path(kin, monkeypatch):
    """After every try before found no path, the last try of a plan from where the last plan ended
    goes back along that plan's path (the way the arm came in) and plans on from its start: the legs
    checked by the plan's own validity, the result's stream checked by the driver. Not for a try
    failed otherwise, nor from elsewhere, nor before the last try."""
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    home = tuple(w.status().joints)
    first = planning.plan(PlanGoal(pose=BEHIND), seed=1)
    assert first.ok, first.text
    came = first.trajectory.path
    assert planning.last_path == came and len(came) >= 3        # (a detour: not the straight move)
    end = first.trajectory.goal

    real = P.plan_with_crossing

    def no_path(planner, start, target, crossing, before=()):
        if not before:                      # (the retreat's try, through waypoints, plans)
            raise PlanningError("plan", "RRTConnect found no path within 1 s (Timeout)")
        return real(planner, start, target, crossing, before)
    monkeypatch.setattr(P, "plan_with_crossing", no_path)
    out = planning.plan(AWAY, start=end, seed=2)
    assert out.ok, out.text
    assert out.profile["retreat"] == 1 and out.profile["tries"] == P.ATTEMPTS
    path = out.trajectory.path
    back = [path.index(q) for q in reversed(came[:-1])]           # every waypoint back, in turn
    assert back == sorted(back)
    assert free_with(w.core.collision.copy(), out.trajectory.positions) == []
    assert planning.driver_refusal(out.trajectory) == ""
    assert planning.last_path == path                            # (the plan made now is the last)
    # the conditions: the last try, after tries that found no path, near the last plan's end
    planning.last_path = came
    plan_failed = ["plan: no path"] * (P.ATTEMPTS - 1)
    assert P.retreat_waypoints(planning.last_path, end, (), P.ATTEMPTS - 1, plan_failed)
    assert P.retreat_waypoints(planning.last_path, end, (), P.ATTEMPTS - 2, plan_failed[1:]) == ()
    assert P.retreat_waypoints(planning.last_path, end, (), P.ATTEMPTS - 1, ["stream: refused"] + plan_failed[1:]) == ()
    assert P.retreat_waypoints(planning.last_path, home, (), P.ATTEMPTS - 1, plan_failed) == ()
    assert P.retreat_waypoints(planning.last_path, end, ((0.0,) * 6,), P.ATTEMPTS - 1, plan_failed) == ()



def test_the_way_back_ends_where_the_last_path_crossed_the_stretched_elbow():
    """Run backwards, the last plan's elbow crossing turns joint_3 from past the stretch to near it,
    where the controller keeps its branch (the hood cell's query 41): the retreat ends at the last
    point on the start's side of the stretch; without a stretch (joint targets) it goes all the way."""
    plan_failed = ["plan: no path"] * (P.ATTEMPTS - 1)
    stretch = -1.34
    path = tuple((0.1 * k, 0.0, j3, 0.0, 0.5, 0.0) for k, j3 in enumerate((-0.5, -1.0, -1.3, -1.5, -1.8, -2.0)))
    end = path[-1]
    assert P.retreat_waypoints(path, end, (), P.ATTEMPTS - 1, plan_failed) == tuple(reversed(path[:-1]))
    assert P.retreat_waypoints(path, end, (), P.ATTEMPTS - 1, plan_failed, stretch) == (path[4], path[3])
    assert P.retreat_waypoints(path[3:], end, (), P.ATTEMPTS - 1, plan_failed, stretch) == (path[4], path[3])


def test_a_try_after_one_that_found_no_path_searches_with_another_planner(kin, monkeypatch):
    """RRTConnect's try found no path: the next searches with RETRY_PLANNER (and a plan made so
    says so); a try refused otherwise keeps the planner; RRTConnect where RETRY_PLANNER was asked."""
    assert P.retry_planner("RRTConnect") == P.RETRY_PLANNER and P.retry_planner(P.RETRY_PLANNER) == "RRTConnect"
    planning = PlanActionCore(world(kin).core, kinematics=kin)
    used = []
    real = P.plan_with_crossing

    def first_finds_nothing(planner, start, target, crossing, before=()):
        used.append(planner.planner_name)
        if len(used) == 1:
            raise PlanningError("plan", "RRTConnect found no path within 1 s (Timeout)")
        return real(planner, start, target, crossing, before)
    monkeypatch.setattr(P, "plan_with_crossing", first_finds_nothing)
    out = planning.plan(AWAY, seed=1)
    assert out.ok, out.text
    assert used == ["RRTConnect", P.RETRY_PLANNER] and "searched with %s" % P.RETRY_PLANNER in out.text
    used.clear()

    def recorded(planner, start, target, crossing, before=()):
        used.append(planner.planner_name)
        return real(planner, start, target, crossing, before)
    monkeypatch.setattr(P, "plan_with_crossing", recorded)
    monkeypatch.setattr(planning, "driver_refusal", lambda plan: "segment 2 of 5: refused" if len(used) < 3 else "")
    assert planning.plan(AWAY, seed=1).ok
    assert used == ["RRTConnect", "RRTConnect", "RRTConnect"]

def test_the_driver_refusal_is_the_stream_check(kin):
    """A plan the v3 stream check accepts is "" (the plans above run); a jump of the wrist between
    two points of a short plan is refused in the driver's words. The outcome carries the stream
    the check made: what the trajectory action sends for the plan, and the node's announcement of
    it is the one it would make itself (without making the stream a second time)."""
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    out = planning.plan(AWAY)
    assert out.ok and out.stream and out.previews == ()
    times, positions = list(out.trajectory.times), [tuple(q) for q in out.trajectory.positions]
    traj = validate(TrajectoryGoal.of(out.trajectory), NAMES, positions[0], kin.limits.lower, kin.limits.upper, 0.0)
    assert out.stream == w.core.prepare_trajectory(traj, positions[0])[1]
    assert w.core.announce(times, positions, stream=out.stream) == w.core.announce(times, positions)
    # v1: its PTP moves' previews, announced at the program's speed as the node would
    v1 = world(kin, "v1")
    out1 = PlanActionCore(v1.core, kinematics=kin).plan(AWAY)
    assert out1.ok and out1.previews and out1.stream == ()
    times1, positions1 = list(out1.trajectory.times), [tuple(q) for q in out1.trajectory.positions]
    assert v1.core.announce(times1, positions1, previews=out1.previews) == v1.core.announce(times1, positions1)
    assert planning.driver_refusal(out.trajectory) == ""
    start = w.status().joints
    flipped = (start[0], start[1], start[2], start[3] + 3.14159, -start[4], start[5] + 3.14159)
    fake = out.trajectory.__class__(out.trajectory.joint_names, (0.0, 2.0, 4.0), (start, flipped, start),
                                    ((0.0,) * 6,) * 3, ((0.0,) * 6,) * 3, (start, start), "RRTConnect")
    assert "configuration" in planning.driver_refusal(fake)


def test_planning_leaves_the_drivers_planning_gate_free(kin, monkeypatch):
    """The gate is taken only to copy the checker: while OMPL plans, previews, trajectory checks and
    joint_command steps (which take the gate) are not held up; one plan at a time is the planner's
    own lock."""
    from vr_driver.kinematics import planner as planner_module
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    seen = []
    real = planner_module.Planner.plan

    def plan(self, start, goal, **kw):
        seen.append((w.core.planning_gate.locked(), planning._lock.locked()))
        return real(self, start, goal, **kw)
    monkeypatch.setattr(planner_module.Planner, "plan", plan)
    assert planning.plan(AWAY).ok
    assert seen == [(False, True)]


def test_a_prefixed_arm_plans_under_its_own_names():
    """prefix left_: the joint goal names the prefixed joints, the markers' chain root is left_base_link."""
    from vr_driver.driver.core import driver_kinematics
    from vr_driver.params import DriverParams
    kin = driver_kinematics(DriverParams.from_dict({"prefix": "left_"}))
    w = World(kin, {"prefix": "left_", "scene": CELL}, protocol="v3")
    w.ready()
    planning = PlanActionCore(w.core)
    assert planning.kin.base == "left_base_link"
    names = tuple("left_joint_%d" % i for i in range(1, 7))
    assert w.core.joint_names == names
    assert planning.plan(PlanGoal(joints=(names, (0.0,) * 6))).ok
    out = planning.plan(PlanGoal(joints=(tuple("joint_%d" % i for i in range(1, 7)), (0.0,) * 6)))
    assert out.code == P.INVALID_GOAL and "left_joint_1" in out.text


def test_a_goal_where_the_arm_is_is_one_point_at_rest(kin):
    """The arm reported at home is within 1e-6 rad of the SRDF's home (the IK of its reported pose):
    'plan home' there is one point where the arm is -- the planner's timing finds none for such a
    move -- and the driver takes it as nothing to do."""
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    here = w.status().joints
    home = kin.named_states["home"]
    assert 0.0 < max(abs(a - b) for a, b in zip(here, home)) < P.AT_GOAL
    out = planning.plan(PlanGoal(named="home"))
    assert out.ok, out.text
    assert out.trajectory.times == (0.0,) and out.trajectory.positions == (tuple(here),)
    assert out.text.startswith("planned with RRTConnect in ") and out.text.endswith(": the arm is at the goal, "
                                                                                   "nothing to move")
    # a goal just beyond AT_GOAL is planned as a move
    beyond = tuple(v + 2 * P.AT_GOAL for v in here)
    out = planning.plan(PlanGoal(joints=(w.core.joint_names, beyond)))
    assert out.ok and len(out.trajectory.times) >= 2, out.text


def test_on_v1_the_driver_refusal_is_the_ptp_moves_between_the_stop_points(kin):
    """v1 runs a plan as straight joint moves (PTP) between its thinned stop points, not along the
    plan's samples: a plan whose samples go round the pillar but whose stop points leave a straight
    move through it is refused in the driver's words (and planned again), one that runs is ""."""
    w = world(kin, protocol="v1", workspace={"y": [-1200.0, 1200.0]})     # the goal is 1104 mm out
    planning = PlanActionCore(w.core, kinematics=kin)
    out = planning.plan(AWAY)
    assert out.ok and planning.driver_refusal(out.trajectory) == ""
    # a plan (made up: straight from home to joint_1 at 1.4 rad, beyond the pillar) that thins to one
    # stop point: v1 would run the straight PTP through the pillar
    start = tuple(w.status().joints)
    beyond = (1.4,) + start[1:]
    n = 8
    times = tuple(0.5 * k for k in range(n + 1))
    positions = tuple(tuple(a + (b - a) * k / n for a, b in zip(start, beyond)) for k in range(n + 1))
    zero = ((0.0,) * 6,) * (n + 1)
    fake = out.trajectory.__class__(out.trajectory.joint_names, times, positions, zero, zero,
                                    (start, beyond), "RRTConnect")
    text = planning.driver_refusal(fake)
    assert text.startswith("PTP 1 to stop point %d of the plan" % n) and "pillar" in text, text


def test_a_goal_across_the_wrist_singularity_is_planned_without_the_margin(kin):
    """With v3 the planner keeps |joint_5| >= WRIST_MARGIN, which walls joint_5 = 0 off: from where a
    cancelled plan left the arm (joint_5 -39.8 deg) a goal with joint_5 +28.6 deg had no path (the
    planning rostest failed on it once). A joint goal with joint_5 of the other sign is planned
    without the margin from the first try (a pose goal: on the last); the driver's stream check
    still decides, and accepts it."""
    import math
    w = world(kin)
    planning = PlanActionCore(w.core, kinematics=kin)
    validity = planning.snapshot()
    q = (0.3, 0.5, -0.2, 0.0, 0.0, 0.0)                           # joint_5 = 0, free of the cell
    assert not validity.in_collision(q)
    assert not planning._planning_validity(validity)(q)
    assert planning._planning_validity(validity, wrist_margin=False)(q)
    start = tuple(math.radians(v) for v in (14.3, -4.9, 11.5, 11.6, -39.8, -126.0))
    # (with the margin, a try would find nothing and take its whole budget: 2 s, not the world's 20)
    out = planning.plan(PlanGoal(joints=(kin.joint_names, (0.3, 0.5, -0.2, 0.0, 0.5, 0.0)), planning_time=2.0),
                        start=start, seed=0)
    assert out.ok, out.text
    assert out.planning_time < 2.0, out.planning_time        # the first try: no budget spent walled in
    assert planning.driver_refusal(out.trajectory) == ""
    assert min(p[4] for p in out.trajectory.positions) < 0.0 < max(p[4] for p in out.trajectory.positions)


def test_a_pose_goal_on_a_cartesian_protocol_prefers_the_starts_elbow_branch(kin):
    """v3: a pose goal's IK solutions on the start's side of the stretched elbow come before those
    across it, nearer or not (the controller, solving each target nearest the previous one, keeps
    the start's branch there); v2 plans to the nearest, whichever branch."""
    from vr_driver.kinematics.planner import Planner
    from vr_driver.kinematics.solver import stretched_elbow
    stretch = stretched_elbow(kin)
    below, above = (0.3, 0.2, stretch - 0.2, 0.3, 0.6, 0.1), (0.3, 0.2, stretch + 0.3, 0.3, 0.6, 0.1)

    v3 = PlanActionCore(world(kin, workspace=REACH).core, kinematics=kin)._goal_preference()
    assert PlanActionCore(world(kin, protocol="v2", workspace=REACH).core, kinematics=kin)._goal_preference() is None
    assert (v3(below, below), v3(below, above), v3(above, below), v3(above, above)) == (0, 1, 1, 0)
    # the planner orders by the rank first: here the nearest solution (the start's side) comes last
    start = (0.3, 0.2, stretch - 0.05, 0.3, 0.6, 0.1)
    nearest = Planner(kin, None).goal_candidates(start, kin.fk(above))
    ranked = Planner(kin, None, goal_preference=lambda s, q: 0 if q[2] > stretch else 1).goal_candidates(
        start, kin.fk(above))
    assert nearest[0][2] < stretch and ranked[0][2] > stretch
    assert sorted(nearest) == sorted(ranked)
    with pytest.raises(TypeError, match="goal_preference must be a callable"):
        Planner(kin, None, goal_preference=3)


def test_a_goal_across_the_stretched_elbow_refused_every_time_says_so(kin, monkeypatch):
    from vr_driver.kinematics.solver import stretched_elbow
    stretch = stretched_elbow(kin)

    planning = PlanActionCore(world(kin, workspace=REACH).core, kinematics=kin)
    monkeypatch.setattr(planning, "driver_refusal", lambda plan: "point 3 of 7: another configuration")
    start, across = (0.3, 0.2, stretch + 0.3, 0.3, 0.6, 0.1), (0.3, 0.2, stretch - 0.3, 0.3, 0.6, 0.1)
    out = planning.plan(PlanGoal(joints=(kin.joint_names, across)), start=start, seed=1)
    assert out.code == P.INVALID_MOTION_PLAN, out.text
    assert "is across the stretched elbow (joint_3 %.1f deg)" % math.degrees(stretch) in out.text
    # a goal on the start's side: the refusal alone
    same = start[:2] + (start[2] + 0.02,) + start[3:]
    out = planning.plan(PlanGoal(joints=(kin.joint_names, same)), start=start, seed=1)
    assert out.code == P.INVALID_MOTION_PLAN and "stretched elbow" not in out.text, out.text


#: a start and a joint goal across the stretched elbow whose straight joint line folds joint_2 and
#: joint_3 in together (the wrist centre out to full reach and back): bench/planning.py --driver
#: --protocol v3, seed 1, query 20 [deg]
FOLD_START = (22.5, -22.2, -48.0, -25.9, 15.3, 0.8)
FOLD_GOAL = (37.2, 32.7, -83.3, -188.4, -59.8, -53.3)


def run_to_the_end(w, plan):
    """``plan`` validated as the action validates it and run on ``w`` to its end; then at rest."""
    traj = validate(TrajectoryGoal.of(plan), tuple(plan.joint_names), w.status().joints, w.kin.limits.lower,
                    w.kin.limits.upper, w.now)
    run = w.core.submit_trajectory(traj)
    w.run_until(lambda: run.done, 3.0 * plan.duration + 10.0, "the run")
    assert run.success, run.failure().result.reason
    w.run_for(0.5)


def fold_world(kin, rule, **params):
    """The stepped v3 world at FOLD_START, the G2 and the driver at configuration ``rule``."""
    from vr_driver.kinematics.solver import ConfigurationRule
    w = World(kin, dict(dict(scene=CELL, velocity_scaling=1.0, workspace=REACH, controller={"configuration": rule}),
                        **params), protocol="v3", initial_pose=kin.fk_pose(tuple(math.radians(v) for v in FOLD_START)))
    w.arm.configuration = ConfigurationRule.parse(rule)
    w.ready()
    return w


def test_a_joint_goal_across_the_stretched_elbow_is_planned_through_it_and_run(kin, monkeypatch):
    """v3: the plan passes the stretch where the straight line does and turns joint_3 alone from
    ELBOW_APPROACH before it to ELBOW_CROSS past it (or the goal's, if nearer); the driver's stream
    check accepts it (a target past the stretch is nearest the planned branch from there), and the
    stepped controller runs it to the goal on the goal's branch. Without those waypoints every plan
    is refused: the controller keeps the start's branch."""
    from vr_driver.kinematics.solver import stretched_elbow
    stretch = stretched_elbow(kin)
    start, goal = (tuple(math.radians(v) for v in q) for q in (FOLD_START, FOLD_GOAL))
    w = fold_world(kin, "previous_target", planning_time=20.0)
    assert w.status().joints == pytest.approx(start, abs=1e-3)
    planning = PlanActionCore(w.core, kinematics=kin)
    via, target = planning._elbow_crossing(start, goal)
    assert target == goal and len(via) == 2
    near, past = via
    assert near[2] - stretch == pytest.approx(P.ELBOW_APPROACH)               # the start's side (above)
    assert past[2] - stretch == pytest.approx(goal[2] - stretch)               # the goal, 6.4 deg past: nearer
    assert near[:2] + near[3:] == past[:2] + past[3:]                          # joint_3 alone between them
    out = planning.plan(PlanGoal(joints=(kin.joint_names, goal)), seed=1)
    assert out.ok, out.text
    plan = out.trajectory
    for q in via:
        assert min(max(abs(a - b) for a, b in zip(p, q)) for p in plan.path) < 1e-3    # (from the read joints)
    run_to_the_end(w, plan)
    assert w.arm.joints == pytest.approx(goal, abs=math.radians(0.05))         # the goal's branch: the arm's own
    assert w.status().joints == pytest.approx(goal, abs=math.radians(0.05))    # ... and what the driver reads
    # without the waypoints the controller keeps the start's branch: refused every time
    monkeypatch.setattr(planning, "_elbow_crossings", lambda s, t: ((), t))
    planning.core = fold_world(kin, "previous_target").core
    # (1 s: the tries with the elbow's margin find nothing and take their whole budget)
    out = planning.plan(PlanGoal(joints=(kin.joint_names, goal), planning_time=1.0), start=start, seed=1)
    assert out.code == P.INVALID_MOTION_PLAN and "another configuration" in out.text, out.text


def test_under_current_joints_the_crossing_holds_at_the_stretch_and_runs(kin):
    """A G2 that solves a target nearest its joints when it takes it (``current_joints``, a
    commissioning's finding) takes targets up to ring_size + 1 points ahead, while the arm may still
    be on the start's branch far from the stretch. The plan holds ELBOW_HOLD at the first waypoint
    (a pause: the next target goes out once the arm is at rest there), so the target past the
    stretch is solved from there; this one (joint_3 35 deg before the stretch to 45 deg past it)
    runs to its goal on the goal's branch."""
    from vr_driver.kinematics.solver import ConfigurationRule, stretched_elbow
    stretch = stretched_elbow(kin)
    start = (0.4, -0.3, stretch - math.radians(35), 0.1, -0.6, 0.2)
    goal = (0.2, 0.3, stretch + math.radians(45), -0.2, -0.5, 0.4)
    w = World(kin, dict(scene=CELL, velocity_scaling=1.0, workspace=REACH, planning_time=20.0,
                        controller={"configuration": "current_joints"}), protocol="v3", initial_pose=kin.fk_pose(start))
    w.arm.configuration = ConfigurationRule.CURRENT_JOINTS
    w.ready()
    planning = PlanActionCore(w.core, kinematics=kin)
    out = planning.plan(PlanGoal(joints=(kin.joint_names, goal)), seed=1)
    assert out.ok, out.text
    plan = out.trajectory
    near = planning._elbow_crossing(w.status().joints, goal)[0][0]
    pauses = [k for k in range(1, len(plan.times)) if plan.positions[k] == plan.positions[k - 1]]
    assert len(pauses) == 1 and plan.positions[pauses[0]] == pytest.approx(near, abs=1e-3)
    assert plan.times[pauses[0]] - plan.times[pauses[0] - 1] == pytest.approx(P.ELBOW_HOLD)
    run_to_the_end(w, plan)
    assert w.arm.joints == pytest.approx(goal, abs=math.radians(0.05))


def test_under_current_joints_a_crossing_too_near_the_goal_is_refused_in_words(kin):
    """The fold goal ends 6.4 deg past the stretch: after the hold 2 deg before it, the G2 under
    ``current_joints`` may take a target past it from the hold, where the start's branch is the
    nearer; the driver's stream check, solving each target from each place the arm may be, refuses
    the plan in words, and nothing is sent (a known limit: bench/README.md, "Planning")."""
    w = fold_world(kin, "current_joints", planning_time=1.0)
    planning = PlanActionCore(w.core, kinematics=kin)
    goal = tuple(math.radians(v) for v in FOLD_GOAL)
    assert len(planning._elbow_crossing(w.status().joints, goal)[0]) == 2    # the waypoints are tried
    out = planning.plan(PlanGoal(joints=(kin.joint_names, goal)), seed=1)
    assert out.code == P.INVALID_MOTION_PLAN, out.text
    assert "in another configuration than planned" in out.text and "current_joints" in out.text, out.text
    assert "nothing was sent" in out.text and "across the stretched elbow" in out.text, out.text
    assert w.core.status().joints == pytest.approx(tuple(math.radians(v) for v in FOLD_START), abs=1e-3)


def test_each_try_crosses_the_stretched_elbow_by_its_own_waypoints(kin, monkeypatch):
    """A goal across the stretch gets up to ATTEMPTS crossings, each two valid waypoints with
    joint_3 alone between them, the first the straight line's (what _elbow_crossing gives); a try
    whose plan through one found no path takes the next (not the same walled-in leg again: the
    hood cell's query 52), and the last try's words still say why."""
    from vr_driver.kinematics.solver import stretched_elbow
    stretch = stretched_elbow(kin)
    start, goal = (tuple(math.radians(v) for v in q) for q in (FOLD_START, FOLD_GOAL))
    planning = PlanActionCore(world(kin, workspace=REACH).core, kinematics=kin)
    crossings, target = planning._elbow_crossings(start, goal)
    assert target == goal and len(crossings) == P.ATTEMPTS and len(set(crossings)) == P.ATTEMPTS
    assert crossings[0] == planning._elbow_crossing(start, goal)[0]
    strict = planning._planning_validity(planning.snapshot(), wrist_margin=False, elbow_margin=False)
    for near, past in crossings:
        assert near[:2] + near[3:] == past[:2] + past[3:] and strict(near) and strict(past)
        assert (near[2] - stretch) * (start[2] - stretch) > 0 > (past[2] - stretch) * (start[2] - stretch)
    tried = []

    def walled_in(planner, q0, tgt, crossing, before=()):
        tried.append(crossing)
        raise PlanningError("plan", "found no path (walled in)")
    monkeypatch.setattr(P, "plan_with_crossing", walled_in)
    out = planning.plan(PlanGoal(joints=(kin.joint_names, goal), planning_time=0.1), start=start, seed=1)
    assert out.code == P.PLANNING_FAILED and "walled in" in out.text, out.text
    assert tried == list(crossings)


def test_no_crossing_waypoints_where_they_would_not_help(kin):
    """(): a goal on the start's side, joint targets (v2). A goal within ELBOW_CROSS / 2 past the
    stretch is crossed to ELBOW_CROSS past it and reached back along its own branch (the G2 would
    solve a target that near the stretch onto the start's branch: the hood cell's seed 3, query 42)."""
    from vr_driver.kinematics.solver import stretched_elbow
    stretch = stretched_elbow(kin)
    start = tuple(math.radians(v) for v in FOLD_START)

    v3 = PlanActionCore(world(kin, workspace=REACH).core, kinematics=kin)
    same = start[:2] + (start[2] - 0.1,) + start[3:]
    assert v3._elbow_crossing(start, same) == ((), same)
    close = start[:2] + (stretch - 0.9 * P.ELBOW_CROSS / 2,) + start[3:]
    (near, past), target = v3._elbow_crossing(start, close)
    assert target == close and past[2] - stretch == pytest.approx(-P.ELBOW_CROSS)    # beyond the goal
    goal = tuple(math.radians(v) for v in FOLD_GOAL)
    v2 = PlanActionCore(world(kin, protocol="v2", workspace=REACH).core, kinematics=kin)
    assert v2._elbow_crossing(start, goal) == ((), goal)


#: the hood cell of the planning bench (bench/cells/hood_post.yaml) and its queries 37 and 38 (seed 1):
#: the start deep under the hood's top (the folded elbow), a pose and a joint goal across the
#: stretched elbow; PATH36 the geometric path of query 36, which ended at the start (its elbow
#: crossing at its start, joint_3 from 2 deg before the stretch to 12 deg past it)
HOOD = os.path.join(REPO, "bench", "cells", "hood_post.yaml")
START37 = (0.52680, 1.94061, -2.66817, 2.90263, -1.40748, -3.10177)
GOAL37 = (0.34185, 0.66583, 0.23262, 0.09437, 0.25325, 5.90613)
GOAL38 = (0.05929, 2.56136, -1.01520, 3.38412, -0.85791, 3.07256)
PATH36 = ((0.94087, 1.41507, -0.20743, 3.57084, -1.18995, -2.44635),
          (0.94087, 1.41507, -1.30779, 3.57084, -1.18995, -2.44635),
          (0.94087, 1.41507, -1.55213, 3.57084, -1.18995, -2.44635),
          (0.95971, 1.48507, -1.71470, 3.44058, -1.19289, -2.37115),
          (0.97717, 1.55392, -1.87437, 3.31309, -1.19617, -2.29958),
          (0.99182, 1.62044, -2.02824, 3.19112, -1.20011, -2.23527),
          (1.00228, 1.68347, -2.17341, 3.07746, -1.20505, -2.18185),
          (1.00715, 1.74186, -2.30697, 2.97485, -1.21133, -2.14295),
          (1.00503, 1.79445, -2.42603, 2.88607, -1.21926, -2.12219),
          (0.99453, 1.84007, -2.52768, 2.81389, -1.22920, -2.12322),
          (0.97424, 1.87755, -2.60903, 2.76107, -1.24146, -2.14966),
          (0.94277, 1.90575, -2.66717, 2.73036, -1.25639, -2.20515),
          (0.90151, 1.92582, -2.70501, 2.71902, -1.27365, -2.28604),
          (0.85187, 1.93892, -2.72544, 2.72427, -1.29291, -2.38871),
          (0.79804, 1.94854, -2.73717, 2.73782, -1.31316, -2.50227),
          (0.73302, 1.94886, -2.72569, 2.77349, -1.33608, -2.64488),
          (0.66661, 1.94803, -2.71132, 2.81193, -1.35933, -2.79111),
          (0.59740, 1.94487, -2.69114, 2.85590, -1.38325, -2.94460),
          START37)


def crossings_of(stretch, positions):
    """(index of the first sample past the stretch, for every change of side) of a plan's samples."""
    side = [math.remainder(q[2] - stretch, 2.0 * math.pi) > 0.0 for q in positions]
    return [k for k in range(1, len(side)) if side[k] != side[k - 1]]


def test_a_leg_keeps_to_its_side_of_the_stretched_elbow():
    """elbow_side_legs: a leg between two configurations on one side of the stretch refuses joint_3
    past it (the stretch itself allowed), one by one and in a batch alike; a leg across it, or from
    the stretch, has no test of its own."""
    stretch = -1.34
    a, b = (0.1, 0.2, -2.0, 0.0, 0.5, 0.0), (0.3, 0.1, -1.5, 0.0, 0.5, 0.0)
    leg = P.elbow_side_legs(stretch)(a, b)
    assert leg(a) and leg(b) and leg((0.0, 0.0, stretch, 0.0, 0.0, 0.0))
    assert not leg((0.0, 0.0, stretch + 1e-6, 0.0, 0.0, 0.0)) and not leg((0.0, 0.0, 0.5, 0.0, 0.0, 0.0))
    rows = [(0.0, 0.0, j3, 0.0, 0.0, 0.0) for j3 in (-2.5, -1.9, stretch, -1.2, -1.6, 1.0)]
    assert leg.first_invalid(rows) == 3 == [leg(q) for q in rows].index(False)
    assert leg.first_invalid(rows[:3]) is None
    other = P.elbow_side_legs(stretch)(b[:2] + (-1.0,) + b[3:], (0.0, 0.0, 1.0, 0.0, 0.0, 0.0))
    assert other(rows[3]) and not other(rows[0]) and other.first_invalid(rows) == 0
    assert P.elbow_side_legs(stretch)(a, (0.0, 0.0, -1.0, 0.0, 0.0, 0.0)) is None       # across: the crossing's turn
    assert P.elbow_side_legs(stretch)((0.0, 0.0, stretch, 0.0, 0.0, 0.0), a) is None


def test_the_planner_keeps_each_leg_to_its_own_test(kin):
    """Planner(leg_validity=...): every state of a leg's search (its escape zones too) passes the
    leg's own test -- a block in joint_1 / joint_2 to go round, the leg's test refusing one way
    round: every path goes the other way; without it some seed's path goes that way."""
    from vr_driver.kinematics.planner import BatchValidity, Planner

    def free(q):
        return not (abs(q[0]) < 0.3 and abs(q[1]) < 0.3)

    def above(a, b):
        return BatchValidity(lambda q: q[1] >= 0.0, lambda qs: next((i for i, q in enumerate(qs) if q[1] < 0.0), None))
    a, b = (-0.6, 0.0, -0.5, 0.0, 0.5, 0.0), (0.6, 0.0, -0.5, 0.0, 0.5, 0.0)
    below = 0
    for seed in range(1, 7):
        plan = Planner(kin, free, seed=seed, leg_validity=above).plan(a, b)
        assert min(q[1] for q in plan.path) >= 0.0 and min(q[1] for q in plan.positions) >= -1e-6
        below += min(q[1] for q in Planner(kin, free, seed=seed).plan(a, b).path) < 0.0
    assert below > 0


@pytest.fixture(scope="module")
def hood(kin):
    w = world(kin, scene=HOOD, workspace=REACH)
    return w, PlanActionCore(w.core, kinematics=kin)


def test_the_hood_cells_joint_goal_across_the_stretch_crosses_once_from_rest(hood):
    """The hood cell's query 38 (a joint goal across the stretched elbow from deep under the hood's
    top; refused by the driver's stream check on all three tries in 5 of 20 seeds, before): planned
    and accepted with every seed, crossing the stretch once, turning joint_3 from rest there."""
    w, planning = hood
    stretch = P.stretched_elbow(planning.kin)
    for seed in range(1, 5):
        planning.last_path = None
        out = planning.plan(PlanGoal(joints=(NAMES, GOAL38)), start=START37, seed=seed)
        assert out.ok, out.text
        plan = out.trajectory
        [k] = crossings_of(stretch, plan.positions)
        rest = next(i for i in range(k - 1, -1, -1) if not any(plan.velocities[i]))
        assert all(abs(q[j] - plan.positions[rest][j]) < 1e-9 for q in plan.positions[rest:k + 1] for j in (0, 1, 3, 4, 5))
        assert planning.driver_refusal(plan) == ""


def test_a_walled_in_last_try_crosses_back_where_the_last_plan_crossed(hood, monkeypatch):
    """The hood cell's query 37 (a pose across the stretched elbow; its start's side walled in
    under the hood's top): when the tries before found no path, the last goes back along the last
    plan's path to before the stretch where that plan crossed it, and crosses there, its other
    joints the last path's (a crossing known to be valid and reached), then on to the goal."""
    w, planning = hood
    stretch = P.stretched_elbow(planning.kin)
    real = P.plan_with_crossing

    def walled_in(planner, start, target, crossing, before=()):
        if not before:
            raise PlanningError("plan", "RRTConnect found no path within 1 s (Timeout)")
        return real(planner, start, target, crossing, before)
    monkeypatch.setattr(P, "plan_with_crossing", walled_in)
    planning.last_path = PATH36
    out = planning.plan(PlanGoal(pose=planning.kin.fk_pose(GOAL37)), start=START37, seed=1)
    assert out.ok, out.text
    assert out.profile["retreat"] == 1 and out.profile["tries"] == P.ATTEMPTS
    path = out.trajectory.path
    assert [path.index(q) for q in reversed(PATH36[2:-1])] == sorted(path.index(q) for q in PATH36[2:-1])
    [k] = crossings_of(stretch, out.trajectory.positions)
    assert max(abs(a - b) for j, (a, b) in enumerate(zip(out.trajectory.positions[k], PATH36[2])) if j != 2) < 1e-3
    assert planning.driver_refusal(out.trajectory) == ""
