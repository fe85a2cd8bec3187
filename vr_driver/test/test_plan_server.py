"""The plan action's ROS adapter (vr_driver.ros.plan_server) without a ROS master: the goal message
to PlanGoal (each goal_type, a bad one refused in words), the result of an outcome (codes, the
trajectory under the driver's joint names, the TCP at its end), and no OMPL: the action is not
advertised, with one warning naming the package and scripts/setup; a goal cancelled while it was
planned ends cancelled, nothing shown or sent. Needs the built messages
(``scripts/env``); skipped with the reason otherwise."""
from __future__ import annotations

import pytest

from vr_driver.driver.motion.announced import Announced

msg = pytest.importorskip("vr_driver.msg", reason="vr_driver messages not built (run scripts/test)")
plan_server = pytest.importorskip("vr_driver.ros.plan_server", reason="rospy / actionlib not importable")

from vr_driver.driver.planning import planning as P  # noqa: E402
from vr_driver.driver.planning.planning import PlanOutcome  # noqa: E402
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
    """The driver core as the plan server uses it: its joint names, and what its protocol delivers
    (``announced``: DriverCore.announce's answer; the calls are kept)."""
    joint_names = NAMES

    def __init__(self, announced=None):
        self.announced = announced or Announced(1.5, 120.0, "protocol v3 runs the plan's timing: 1.50 s, the TCP at "
                                                           "most 120 mm/s")
        self.calls = []

    def announce(self, times, positions, previews=None, stream=None):
        self.calls.append((tuple(times), tuple(positions)))
        self.inputs = (previews, stream)
        return self.announced


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


def test_the_result_says_the_speed_the_plan_runs_at():
    """The scaling it was timed with, the TCP's peak speed (central difference of our FK along the
    joint velocity) and the joint closest to its limit, in the fields and appended in words."""
    import math
    from vr_driver.kinematics.solver import Kinematics
    kin = Kinematics.default()
    limit = kin.limits.velocity
    home = tuple(kin.named_states["home"])
    # joint_1 alone at 0.2 rad/s, then joint_5 at 0.1 of its limit (the larger fraction of the two)
    v1 = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    v5 = (0.0, 0.0, 0.0, 0.0, 0.1 * limit[4], 0.0)
    zero = (0.0,) * 6
    positions, velocities = (home, home, home, home), (zero, v1, v5, zero)
    peaks = plan_server.peak_speeds(kin, positions, velocities)
    assert (peaks.joint, peaks.joint_speed) == (4, 0.1 * limit[4])
    assert peaks.joint_fraction == pytest.approx(0.1)
    # joint_1 turning at 0.2 rad/s moves the TCP at its distance from the joint_1 axis times 0.2
    x, y = kin.fk_pose(home).x, kin.fk_pose(home).y
    by_joint_1 = 0.2 * math.hypot(x, y)
    assert peaks.tcp >= by_joint_1 * (1 - 1e-6)
    assert plan_server.peak_speeds(kin, positions[:1], velocities[:1]) == (0.0, 0, 0.0, 0.0)

    class Planning:
        pass
    server = plan_server.PlanServer(_Core(), DriverParams())
    server.planning = Planning()
    server.planning.kin = kin
    plan = PlannedTrajectory(NAMES, (0.0, 0.5, 1.0, 1.5), positions, velocities, (zero,) * 4, positions, "RRTConnect")
    text = "planned with RRTConnect in 12 ms: 4 points over 1.50 s (velocity scaling 0.1)"
    result = server._result(PlanOutcome(P.SUCCESS, text, plan, 0.012, "RRTConnect"), 0.1)
    assert result.velocity_scaling == 0.1
    assert (result.peak_joint, result.peak_joint_fraction) == ("joint_5", pytest.approx(0.1))
    assert result.peak_joint_speed == pytest.approx(math.degrees(0.1 * limit[4]))
    assert result.peak_tcp_speed == pytest.approx(peaks.tcp)
    assert result.error_string == text + ("; at its fastest the TCP moves %.0f mm/s, joint_5 %.1f deg/s (10 %% of its "
                                          "limit); protocol v3 runs the plan's timing: 1.50 s, the TCP at most 120 mm/s"
                                          % (peaks.tcp, math.degrees(0.1 * limit[4])))
    # what the protocol delivers (DriverCore.announce of the planned path)
    assert (result.run_duration, result.run_peak_tcp_speed) == (1.5, 120.0)
    assert result.run_words == "protocol v3 runs the plan's timing: 1.50 s, the TCP at most 120 mm/s"
    assert server.core.calls[-1] == ((0.0, 0.5, 1.0, 1.5), tuple(positions))
    assert server.core.inputs == (None, None)           # the outcome carries no stream: the core makes it
    # the stream the planning's check made (the outcome's) is what the core announces: not made twice
    sent = ("a stream point",)
    server._result(PlanOutcome(P.SUCCESS, text, plan, 0.012, "RRTConnect", stream=sent), 0.1)
    assert server.core.inputs == (None, sent)
    # v1: the program's speed, and the default scaling that does not apply said first
    server.core.announced = Announced(3.2, 167.0, "protocol v1 runs it at the robot program's own speed ...", True)
    result = server._result(PlanOutcome(P.SUCCESS, text, plan, 0.012, "RRTConnect"), 0.1, default=True)
    assert result.run_words.startswith("velocity scaling 0.1 (the driver's default) does not apply on this protocol: "
                                       "the robot program's speed does (the TCP at most 167 mm/s, ")
    assert result.run_words.endswith("; protocol v1 runs it at the robot program's own speed ...")
    assert result.error_string.endswith(result.run_words)
    # words that do not name the scaling get it
    result = server._result(PlanOutcome(P.SUCCESS, "planned", plan, 0.012, "RRTConnect"), 0.25)
    assert result.error_string.startswith("planned; velocity scaling 0.25: at its fastest the TCP moves ")


def test_the_codes_are_the_actions():
    for name in ("SUCCESS", "PLANNING_FAILED", "INVALID_MOTION_PLAN", "CONTROL_FAILED", "PREEMPTED",
                 "START_STATE_IN_COLLISION", "GOAL_IN_COLLISION", "INVALID_GOAL", "INVALID_ROBOT_STATE",
                 "NO_IK_SOLUTION"):
        assert getattr(msg.PlanResult, name) == getattr(P, name), name


def test_without_ompl_the_action_is_not_advertised_and_says_why_once(monkeypatch):
    class WithoutOmpl:
        """The planning process whose worker cannot import OMPL (start() raises its words)."""

        def __init__(self, core):
            pass

        def start(self):
            raise MissingDependency("ompl", "ompl", "the plan action (vr_driver.driver.planning.planning)",
                                    "ModuleNotFoundError: No module named 'ompl'")
    monkeypatch.setattr(plan_server, "PlanningProcess", WithoutOmpl)
    warnings = []
    monkeypatch.setattr(plan_server.rospy, "logwarn", lambda text, *args: warnings.append(text % args))
    server = plan_server.PlanServer(_Core(), DriverParams())
    assert server.start() is False
    assert server.server is None and server.client is None and server.marker_pub is None and server.planning is None
    assert len(warnings) == 1
    assert warnings[0].startswith("interface: the plan action is not served: the plan action (vr_driver.driver."
                                  "planning.planning) needs the Python package ompl"), warnings[0]
    assert "scripts/setup" in warnings[0] and "No module named 'ompl'" in warnings[0]
    assert server.unavailable and "ompl" in server.unavailable


class _Handle:
    """An action goal handle that records what the server did with it."""

    def __init__(self, goal):
        self.goal = goal
        self.feedback, self.ended = [], []

    def get_goal(self):
        return self.goal

    def publish_feedback(self, feedback):
        self.feedback.append(feedback.phase)

    def set_canceled(self, result, text=""):
        self.ended.append(("canceled", result))

    def set_aborted(self, result, text=""):
        self.ended.append(("aborted", result))

    def set_succeeded(self, result, text=""):
        self.ended.append(("succeeded", result))


def test_a_goal_cancelled_while_it_is_planned_ends_cancelled_with_nothing_shown_or_sent():
    import threading
    calls = []

    class Planning:
        def plan(self, goal, cancel=None):
            calls.append((goal.named, cancel))
            return PlanOutcome(P.PREEMPTED, "cancelled while planning (the planning process was stopped)",
                               planning_time=0.5, planner_id="RRTConnect")
    server = plan_server.PlanServer(_Core(), DriverParams())
    server.planning = Planning()
    server.show = lambda outcome: calls.append("shown")
    cancel = threading.Event()
    handle = _Handle(msg.PlanGoal(goal_type=msg.PlanGoal.NAMED, named_state="home"))
    server._execute(handle, handle.goal, cancel)
    assert calls == [("home", cancel)]                     # the goal's cancel reaches the planning
    assert handle.feedback == [msg.PlanFeedback.PHASE_PLANNING]
    [(how, result)] = handle.ended
    assert how == "canceled" and result.error_code == msg.PlanResult.PREEMPTED
    assert result.error_string == "cancelled while planning (the planning process was stopped)"
    assert result.trajectory.points == []
