"""The plan action's ROS adapter (vr_driver.ros.plan_server) without a ROS master: the goal message
to PlanGoal (each goal_type, a bad one refused in words), the result of an outcome (codes, the
trajectory under the driver's joint names, the TCP at its end), and no OMPL: the action is not
advertised, with one warning naming the package and scripts/setup. Needs the built messages
(``scripts/env``); skipped with the reason otherwise."""
from __future__ import annotations

import pytest

msg = pytest.importorskip("vr_driver.msg", reason="vr_driver messages not built (run scripts/test)")
plan_server = pytest.importorskip("vr_driver.ros.plan_server", reason="rospy / actionlib not importable")

from vr_driver.driver import planning as P  # noqa: E402
from vr_driver.driver.planning import PlanOutcome  # noqa: E402
from vr_driver.errors import MissingDependency, VrDriverError  # noqa: E402
from vr_driver.kinematics.planner import PlannedTrajectory  # noqa: E402
from vr_driver.params import DriverParams  # noqa: E402
from vr_driver.poses import ControllerPose  # noqa: E402

NAMES = tuple("joint_%d" % i for i in range(1, 7))


def test_goal_messages_become_plan_goals():
    g = plan_server.goal_from_msg(msg.PlanGoal(goal_type=msg.PlanGoal.POSE, pose=msg.CartesianPose(500, 866, 725, 0, 45, 60),
                                               planner_id="PRM", allowed_planning_time=2.0, velocity_scaling=0.5))
    assert g.pose == ControllerPose(500, 866, 725, 0, 45, 60) and g.named == "" and g.joints is None
    assert (g.planner_id, g.planning_time, g.velocity_scaling) == ("PRM", 2.0, 0.5)
    g = plan_server.goal_from_msg(msg.PlanGoal(goal_type=msg.PlanGoal.NAMED, named_state="home"))
    assert g.named == "home" and g.pose is None and (g.planner_id, g.planning_time, g.velocity_scaling) == ("", 0.0, 0.0)
    g = plan_server.goal_from_msg(msg.PlanGoal(goal_type=msg.PlanGoal.JOINTS, joint_names=list(NAMES),
                                               positions=[0.0, 0.1, 0.2, 0.3, 0.4, 0.5]))
    assert g.joints == (NAMES, (0.0, 0.1, 0.2, 0.3, 0.4, 0.5))


@pytest.mark.parametrize("goal, words", [
    (msg.PlanGoal(goal_type=0), "goal_type 0 is unknown (1 JOINTS, 2 NAMED, 3 POSE)"),
    (msg.PlanGoal(goal_type=7), "goal_type 7 is unknown"),
    (msg.PlanGoal(goal_type=msg.PlanGoal.NAMED), "goal_type NAMED needs named_state"),
    (msg.PlanGoal(goal_type=msg.PlanGoal.POSE, pose=msg.CartesianPose(float("nan"), 0, 700, 0, 0, 0)), "finite"),
])
def test_bad_goal_messages_are_refused_in_words(goal, words):
    with pytest.raises((ValueError, VrDriverError)) as err:
        plan_server.goal_from_msg(goal)
    assert words in str(err.value)


class _Core:
    joint_names = NAMES


def test_the_result_of_a_plan_carries_the_trajectory_under_the_drivers_names():
    import rospy
    server = plan_server.PlanServer(_Core(), DriverParams())
    zero = (0.0,) * 6
    plan = PlannedTrajectory(("a", "b", "c", "d", "e", "f"), (0.0, 0.5, 1.0), (zero, (0.1,) * 6, (0.2,) * 6),
                             (zero, (0.2,) * 6, zero), (zero, zero, zero), (zero, (0.2,) * 6), "RRTConnect")
    out = PlanOutcome(P.SUCCESS, "planned", plan, 0.25, "RRTConnect", ControllerPose(1000, 0, 800, 0, 45, 0))
    result = server._result(out)
    assert result.error_code == msg.PlanResult.SUCCESS == P.SUCCESS
    assert list(result.trajectory.joint_names) == list(NAMES)
    assert [p.time_from_start for p in result.trajectory.points] == [rospy.Duration(0), rospy.Duration(0.5),
                                                                      rospy.Duration(1.0)]
    assert list(result.trajectory.points[1].velocities) == [0.2] * 6
    assert (result.duration, result.planning_time, result.planner_id) == (1.0, 0.25, "RRTConnect")
    assert (result.target.x, result.target.z, result.target.ry) == (1000, 800, 45)
    refused = server._result(PlanOutcome(P.GOAL_IN_COLLISION, "goal refused: link_6 with object table"))
    assert refused.error_code == msg.PlanResult.GOAL_IN_COLLISION and refused.trajectory.points == []


def test_the_codes_are_the_actions():
    for name in ("SUCCESS", "PLANNING_FAILED", "INVALID_MOTION_PLAN", "CONTROL_FAILED", "PREEMPTED",
                 "START_STATE_IN_COLLISION", "GOAL_IN_COLLISION", "INVALID_GOAL", "INVALID_ROBOT_STATE",
                 "NO_IK_SOLUTION"):
        assert getattr(msg.PlanResult, name) == getattr(P, name), name


def test_without_ompl_the_action_is_not_advertised_and_says_why_once(monkeypatch):
    def without_ompl(core):
        raise MissingDependency("ompl", "ompl", "the plan action (vr_driver.driver.planning)",
                                "ModuleNotFoundError: No module named 'ompl'")
    monkeypatch.setattr(plan_server, "DriverPlanning", without_ompl)
    warnings = []
    monkeypatch.setattr(plan_server.rospy, "logwarn", lambda text, *args: warnings.append(text % args))
    server = plan_server.PlanServer(_Core(), DriverParams())
    assert server.start() is False
    assert server.server is None and server.client is None and server.marker_pub is None
    assert len(warnings) == 1
    assert warnings[0].startswith("interface: the plan action is not served: the plan action (vr_driver.driver."
                                  "planning) needs the Python package ompl"), warnings[0]
    assert "scripts/setup" in warnings[0] and "No module named 'ompl'" in warnings[0]
    assert server.unavailable and "ompl" in server.unavailable
