#!/usr/bin/python3
"""rostest of planning under load (test/planning_load.test): the driver with the example cell,
protocol v3 at 19.2 kbit/s on the paced virtual line (the bytes take their wire time, the I/O island
on the line), the plan action. 20 goals (short moves in front of the arm: joints, poses, home) are
planned and executed one after another through the plan action while a second client starts a
preview-only plan around the pillar (behind it, home) each time a trajectory runs, with a planner
that uses its whole budget (RRT*) -- so OMPL plans while trajectories stream. Each of the 20 ends SUCCEEDED (executed by
joint_trajectory_action); the link is never lost (the driver's /diagnostics: link losses 0), and the
controller's card (and the island's) never sees its DP watchdog expire (their warnings on /rosout:
none). Before the planning ran in a worker process of its own, OMPL held the node's interpreter
lock for 0.6 to 5 s and a bus thread in the node missed the cards' 300 ms watchdog: with the bus in
the node's thread and the planning put back into the node's interpreter, this test failed (33
gaps of 150 to 281 ms between two bus cycles, the I/O island's watchdog expired; with the worker:
one of 151 ms). Waits are on messages with deadlines."""
from __future__ import annotations

import threading
import time
import unittest

import actionlib
import rospy
from vr_driver.ros.support import init_node
import rostest
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Log

from driver_check import Recorder, cp
from vr_driver.kinematics.deps import missing_dependencies
from vr_driver.msg import PlanAction, PlanGoal, PlanResult, RobotStatus, TriState

PKG = "vr_driver"
NAMES = ["joint_%d" % i for i in range(1, 7)]
#: the executed goals, in turn: short moves in front of the arm (each 0.25 to 0.5 s planned), all
#: with joint_5 > 0 (the wrist never crosses its singularity)
CYCLE = [
    PlanGoal(goal_type=PlanGoal.JOINTS, joint_names=NAMES, positions=[0.3, 0.5, -0.2, 0.0, 0.5, 0.0]),
    PlanGoal(goal_type=PlanGoal.POSE, pose=cp((875, -478, 824, 0, 50, -30))),       # right, under the shelf
    PlanGoal(goal_type=PlanGoal.POSE, pose=cp((1000, 0, 600, 0, 60, 0))),           # low, over the table
    PlanGoal(goal_type=PlanGoal.NAMED, named_state="home"),
]
for _goal in CYCLE:
    _goal.allowed_planning_time = 5.0     # RRTConnect ends when it has a path: a budget, not a duration
    _goal.velocity_scaling = 1.0          # the full speed, as measured (the driver's default is 0.1)
GOALS = 20
#: the background load, in turn: preview-only plans behind the pillar and home (from wherever the arm
#: is, around the pillar: OMPL plans) with RRT*, which plans until its budget is spent, each try
LOAD = [PlanGoal(goal_type=PlanGoal.POSE, pose=cp((500, 866, 725, 0, 45, 60)), planner_id="RRTstar",
                 allowed_planning_time=0.5, preview_only=True, velocity_scaling=1.0),
        PlanGoal(goal_type=PlanGoal.NAMED, named_state="home", planner_id="RRTstar", allowed_planning_time=0.5,
                 preview_only=True, velocity_scaling=1.0)]


def link_values(msg):
    """The key / value pairs of the driver's link status in a /diagnostics message (None: not in it)."""
    for status in msg.status:
        values = {kv.key: kv.value for kv in status.values}
        if "link losses" in values:
            return values
    return None


class PlanningLoadTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        missing = missing_dependencies()
        if missing:
            raise unittest.SkipTest("; ".join(reason for _, reason in missing))
        init_node("planning_load_check")
        cls.rosout = Recorder("/rosout", Log)
        cls.diag = Recorder("/diagnostics", DiagnosticArray)
        cls.status = Recorder("/robot_status", RobotStatus)
        cls.client = actionlib.ActionClient("/plan", PlanAction)
        cls.load_client = actionlib.ActionClient("/plan", PlanAction)
        for client in (cls.client, cls.load_client):
            assert client.wait_for_server(rospy.Duration(30.0)), "the plan action is not served"

    def plan(self, client, goal, timeout=60.0):
        """(state, result) of one plan goal (its result within ``timeout``)."""
        done = threading.Event()

        def transition(handle):
            if handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()
        handle = client.send_goal(goal, transition_cb=transition)
        self.assertTrue(done.wait(timeout), "no result from the plan action")
        return handle.get_goal_status(), handle.get_result()

    def expiries(self):
        with self.rosout.cond:
            return ["%s: %s" % (m.name, m.msg) for m in self.rosout.messages
                    if "watchdog" in m.msg and "expired" in m.msg]

    def test_plans_while_trajectories_run_never_cost_the_link(self):
        self.assertIsNotNone(self.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE, 30.0),
                             "motion never became possible")
        executing = threading.Event()          # an executed goal's trajectory is running
        stop = threading.Event()
        previews = []                          # (state, result code) of each preview plan
        load_errors = []

        def load():
            # a preview starts each time a trajectory is running (the plan action's executing
            # phase), so that OMPL plans in the worker while the trajectory streams -- whatever the
            # machine's speed: waiting on the phase, not on a guess of how long things take
            k = 0
            while not stop.is_set():
                if not executing.wait(0.2):
                    continue
                k += 1
                try:
                    state, result = self.plan(self.load_client, LOAD[k % len(LOAD)])
                except AssertionError as exc:
                    load_errors.append(str(exc))
                    return
                previews.append((state, result.error_code if result else None))

        t0 = time.monotonic()
        loader = threading.Thread(target=load, daemon=True)
        loader.start()
        results = []
        try:
            for k in range(GOALS):
                goal = CYCLE[k % len(CYCLE)]
                done = threading.Event()

                def transition(handle, done=done):
                    if handle.get_comm_state() == actionlib.CommState.DONE:
                        done.set()

                def feedback(_handle, fb):
                    if fb.phase == "executing":
                        executing.set()
                handle = self.client.send_goal(goal, transition_cb=transition, feedback_cb=feedback)
                self.assertTrue(done.wait(60.0), "goal %d: no result from the plan action" % k)
                executing.clear()
                state, result = handle.get_goal_status(), handle.get_result()
                results.append((k, state, result.error_code, result.error_string))
                self.assertEqual((state, result.error_code), (GoalStatus.SUCCEEDED, PlanResult.SUCCESS),
                                 "goal %d: %s" % (k, result.error_string))
        finally:
            stop.set()
            loader.join(30.0)
        took = time.monotonic() - t0
        self.assertEqual(load_errors, [])
        rospy.loginfo("planning_load: %d goals executed in %.1f s; %d preview plans started while a "
                      "trajectory ran", len(results), took, len(previews))
        self.assertGreaterEqual(len(previews), 3, "too few plans were started while a trajectory ran: %s" % previews)
        self.assertTrue(all(code in (PlanResult.SUCCESS, PlanResult.PLANNING_FAILED, PlanResult.INVALID_MOTION_PLAN)
                            for _, code in previews), previews)
        # the link: never lost, over the whole run (the counters count from the driver's start)
        msg = self.diag.wait_for(lambda m: link_values(m) is not None, 10.0, after=time.monotonic())
        self.assertIsNotNone(msg, "no link diagnostics")
        values = link_values(msg)
        rospy.loginfo("planning_load: link %s", ", ".join("%s %s" % (k, values[k]) for k in sorted(values)))
        self.assertEqual(values["link losses"], "0", values)
        self.assertEqual(values.get("bus losses", "0"), "0", values)
        self.assertEqual(values["link state"], "connected", values)
        self.assertEqual(self.expiries(), [], "a DP watchdog expired")
        with self.rosout.cond:       # a figure, not a verdict: the node warns of each gap > half the watchdog
            gaps = [m.msg for m in self.rosout.messages if "between two Data_Exchange cycles" in m.msg]
        rospy.loginfo("planning_load: %d gap(s) of more than half the card's watchdog between two bus cycles%s",
                      len(gaps), ": " + "; ".join(g.split(":")[0] for g in gaps) if gaps else "")


if __name__ == "__main__":
    rostest.rosrun(PKG, "planning_load", PlanningLoadTest)
