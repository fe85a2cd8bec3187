#!/usr/bin/python3
"""rostest of the two-arm example cell (launch/two_arms.launch, issue 19): two drivers in the
namespaces arm1 / arm2 with the prefixes arm1_ / arm2_, each against its own virtual controller over
its own pty (real telegrams), their joint_states merged into /joint_states for one
robot_state_publisher.

Run by test/two_arms.test. What each virtual controller executed is read from its own
/armN/virtual_controller/executed log. Waits are on messages and action results with deadlines."""
from __future__ import annotations

import json
import threading
import time
import unittest

import actionlib
import rosgraph
import rospy
from vr_driver.ros.support import init_node
import rostest
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import MarkerArray

from driver_check import Recorder, cp
from vr_driver.msg import (FollowJointTrajectoryAction, FollowJointTrajectoryGoal, FollowJointTrajectoryResult,
                           MoveToPoseAction, MoveToPoseFeedback, MoveToPoseGoal, RobotStatus, ServiceReturnCode,
                           TriState)
from vr_driver.srv import StopMotion

PKG = "vr_driver"
ARMS = ("arm1", "arm2")
LINKS = ("base_link", "base", "link_1", "link_2", "link_3", "link_4", "link_5", "link_6", "flange", "tool0")


def joints(arm):
    return ["%s_joint_%d" % (arm, i) for i in range(1, 7)]


class Arm:
    """One driver's public API, by its namespace."""

    def __init__(self, arm):
        self.name = arm
        ns = "/" + arm + "/"
        self.status = Recorder(ns + "robot_status", RobotStatus)
        self.joints = Recorder(ns + "joint_states", JointState)
        self.tool = Recorder(ns + "tool_pose", PoseStamped)
        self.markers = Recorder(ns + "interface/markers", MarkerArray)
        self.executed = Recorder(ns + "virtual_controller/executed", String)
        self.move_client = actionlib.ActionClient(ns + "move_to_pose", MoveToPoseAction)
        self.trajectory_client = actionlib.ActionClient(ns + "joint_trajectory_action", FollowJointTrajectoryAction)
        self.stop_motion = rospy.ServiceProxy(ns + "stop_motion", StopMotion)
        self.path_pub = rospy.Publisher(ns + "joint_path_command", JointTrajectory, queue_size=1)

    def wait_up(self, timeout):
        end = time.monotonic() + timeout
        assert self.move_client.wait_for_server(rospy.Duration(timeout)), "%s: move_to_pose not up" % self.name
        assert self.trajectory_client.wait_for_server(rospy.Duration(max(1.0, end - time.monotonic()))), \
            "%s: joint_trajectory_action not up" % self.name
        rospy.wait_for_service("/%s/stop_motion" % self.name, max(1.0, end - time.monotonic()))
        assert self.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE,
                                    max(1.0, end - time.monotonic())), "%s: motion never possible" % self.name
        assert self.joints.wait_for(lambda m: True, max(1.0, end - time.monotonic())), \
            "%s: no joint_states" % self.name

    def entries(self):
        with self.executed.cond:
            return [json.loads(m.data) for m in self.executed.messages]

    def send(self, goal, client=None, feedback=None):
        """(handle, done event) of one goal on a plain ActionClient (see driver_check.send_and_wait)."""
        done = threading.Event()

        def transition(handle):
            if handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()
        handle = (client or self.move_client).send_goal(goal, transition_cb=transition, feedback_cb=feedback)
        return handle, done


class TwoArmsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_node("two_arms_check")
        cls.tf = Recorder("/tf", TFMessage)
        cls.tf_static = Recorder("/tf_static", TFMessage)
        cls.merged = Recorder("/joint_states", JointState)
        cls.diag = Recorder("/diagnostics", DiagnosticArray)
        cls.rosout = Recorder("/rosout", Log)
        cls.arms = {arm: Arm(arm) for arm in ARMS}
        for arm in cls.arms.values():
            arm.wait_up(40.0)

    def wait_motion_possible(self, arm, timeout=15.0):
        self.assertIsNotNone(arm.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE, timeout,
                                                 after=time.monotonic()), "%s: motion never possible" % arm.name)

    def move(self, arm, kind, target, timeout=40.0):
        handle, done = arm.send(MoveToPoseGoal(target=cp(target), move_type=kind))
        self.assertTrue(done.wait(timeout), "%s: no move_to_pose result" % arm.name)
        return handle.get_goal_status(), handle.get_result()

    # -------------------------------------------------------------------- tests (run in name order)
    def test_01_one_tf_tree_holds_both_arms_with_no_conflicting_parent(self):
        frames = {arm + "_" + link for arm in ARMS for link in LINKS}
        parents = {}
        publishers = set()

        def collect():
            for rec in (self.tf, self.tf_static):
                with rec.cond:
                    for msg in rec.messages:
                        publishers.add(msg._connection_header["callerid"])
                        for t in msg.transforms:
                            parents.setdefault(t.child_frame_id, set()).add(t.header.frame_id)
            return frames <= set(parents)
        end = time.monotonic() + 20.0
        while not collect() and time.monotonic() < end:
            self.tf.wait_for(lambda m: False, 0.2)
        self.assertEqual(set(parents), frames, "frames in TF")
        self.assertEqual(publishers, {"/robot_state_publisher"}, "one publisher of the one tree")
        for child, ps in parents.items():
            self.assertEqual(len(ps), 1, "%s has the parents %s" % (child, sorted(ps)))
        for arm in ARMS:
            for link in LINKS:
                frame, chain = arm + "_" + link, []
                while frame in parents:
                    (frame,) = parents[frame]
                    chain.append(frame)
                    self.assertLess(len(chain), 20, "a cycle above %s_%s" % (arm, link))
                self.assertEqual(frame, "world", "%s_%s is not under world: %s" % (arm, link, chain))
                self.assertTrue(all(f.startswith(arm + "_") for f in chain[:-1]), chain)
        # each driver's own names: its joints, its tool_pose frame (which is in the tree)
        for arm in self.arms.values():
            self.assertEqual(list(arm.joints.last().name), joints(arm.name))
            tool = arm.tool.wait_for(lambda m: True, 10.0)
            self.assertIsNotNone(tool, "%s: no tool_pose" % arm.name)
            self.assertEqual(tool.header.frame_id, arm.name + "_base")
        merged = self.merged.wait_for(lambda m: True, 10.0, after=time.monotonic())
        self.assertEqual(sorted(merged.name), sorted(joints("arm1") + joints("arm2")))

    def test_02_diagnostics_name_each_driver(self):
        seen = {}

        def record(msg):
            """Both drivers' link and controller tasks seen, each link OK (a link still connecting --
            a loaded machine is slow to start two drivers and two controllers -- is waited for)."""
            for st in msg.status:
                seen[st.name] = st
            return all("%s/interface: %s" % (arm, task) in seen for arm in ARMS for task in ("link", "controller")) \
                and all(seen["%s/interface: link" % arm].level == DiagnosticStatus.OK for arm in ARMS)
        self.assertIsNotNone(self.diag.wait_for(record, 30.0), "diagnostics seen: %s" % (
            ["%s (%d: %s)" % (name, st.level, st.message) for name, st in sorted(seen.items())]))
        devices = set()
        for arm in ARMS:
            link = seen["%s/interface: link" % arm]
            values = {kv.key: kv.value for kv in link.values}
            port = rosgraph.get_master_uri().rstrip("/").rsplit(":", 1)[-1]
            self.assertTrue(values["device"].endswith("vr006l_virtual_g2_%s_%s" % (port, arm)), values["device"])
            devices.add(values["device"])
        self.assertEqual(len(devices), 2, "each driver on its own virtual controller's pty")

    def test_03_a_move_of_arm1_changes_only_arm1_joints(self):
        arm1, arm2 = self.arms["arm1"], self.arms["arm2"]
        self.wait_motion_possible(arm1)
        before1, before2 = len(arm1.entries()), len(arm2.entries())
        start = time.monotonic()
        state, result = self.move(arm1, MoveToPoseGoal.PTP, (1000, 0, 800, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)

        def values(msg, arm):
            return [msg.position[list(msg.name).index(n)] for n in joints(arm)]
        # the arm at rest, as arm1's driver publishes it, reaches the merged stream
        rest = list(arm1.joints.wait_for(lambda m: True, 5.0, after=time.monotonic()).position)
        self.assertIsNotNone(self.merged.wait_for(lambda m: values(m, "arm1") == rest, 5.0, after=start),
                             "arm1's joints never reached /joint_states")
        with self.merged.cond:
            during = [m for m, t in zip(self.merged.messages, self.merged.times) if t >= start]
        self.assertGreaterEqual(len(during), 2)
        first1 = values(during[0], "arm1")
        self.assertGreater(max(abs(a - b) for a, b in zip(first1, rest)), 0.05, "arm1 did not move")
        ref2 = values(during[0], "arm2")
        for msg in during:
            self.assertEqual(values(msg, "arm2"), ref2, "an arm2 joint changed while arm1 moved")
        self.assertEqual(len(arm1.entries()), before1 + 1)
        self.assertEqual(arm1.entries()[-1]["outcome"], "executed")
        self.assertEqual(len(arm2.entries()), before2, "arm2's controller was sent something")
        # the preview markers are in arm1's controller frame
        markers = arm1.markers.wait_for(lambda m: True, 5.0)
        self.assertIsNotNone(markers)
        self.assertEqual({m.header.frame_id for m in markers.markers}, {"arm1_base"})

    def test_04_stop_motion_of_arm2_stops_only_arm2(self):
        arm1, arm2 = self.arms["arm1"], self.arms["arm2"]
        self.wait_motion_possible(arm1)
        self.wait_motion_possible(arm2)
        before1, before2 = len(arm1.entries()), len(arm2.entries())
        moving = {arm: threading.Event() for arm in ARMS}

        def on_feedback(arm):
            return lambda _handle, fb: fb.phase == MoveToPoseFeedback.PHASE_MOVING and moving[arm].set()
        # LIN at 0.25 m/s over 650 mm: ~2.5 s each, long enough to stop one half way
        h1, done1 = arm1.send(MoveToPoseGoal(target=cp((1000, -650, 800, 0, 45, 0)), move_type=MoveToPoseGoal.LIN),
                              feedback=on_feedback("arm1"))
        h2, done2 = arm2.send(MoveToPoseGoal(target=cp((1000, 650, 800, 0, 45, 0)), move_type=MoveToPoseGoal.LIN),
                              feedback=on_feedback("arm2"))
        self.assertTrue(moving["arm2"].wait(15.0), "arm2 never moving")
        self.assertTrue(moving["arm1"].wait(15.0), "arm1 never moving")
        response = arm2.stop_motion()
        self.assertEqual(response.code.val, ServiceReturnCode.SUCCESS)
        self.assertTrue(done2.wait(20.0), "arm2's goal did not end")
        self.assertTrue(done1.wait(30.0), "arm1's goal did not end")
        self.assertNotEqual(h2.get_goal_status(), GoalStatus.SUCCEEDED)
        self.assertFalse(h2.get_result().success)
        self.assertEqual(h1.get_goal_status(), GoalStatus.SUCCEEDED, h1.get_result().reason)
        self.assertTrue(arm2.executed.wait_count(before2 + 1, 10.0))
        (entry2,) = arm2.entries()[before2:]
        self.assertEqual(entry2["outcome"], "rejected")
        self.assertIn("stop", entry2["reason"])
        self.assertTrue(arm1.executed.wait_count(before1 + 1, 10.0))
        (entry1,) = arm1.entries()[before1:]
        self.assertEqual(entry1["outcome"], "executed")

    def test_05_a_goal_with_arm2_joint_names_sent_to_arm1_is_refused_with_the_reason(self):
        arm1, arm2 = self.arms["arm1"], self.arms["arm2"]
        self.wait_motion_possible(arm1)
        before1, before2 = len(arm1.entries()), len(arm2.entries())
        q = list(arm1.joints.last().position)
        goal = FollowJointTrajectoryGoal()
        goal.trajectory.joint_names = joints("arm2")
        goal.trajectory.points = [JointTrajectoryPoint(positions=[q[0] + 0.2] + q[1:],
                                                       time_from_start=rospy.Duration(2.0))]
        handle, done = arm1.send(goal, client=arm1.trajectory_client)
        self.assertTrue(done.wait(20.0), "no result from arm1's joint_trajectory_action")
        self.assertIn(handle.get_goal_status(), (GoalStatus.REJECTED, GoalStatus.ABORTED))
        result = handle.get_result()
        self.assertEqual(result.error_code, FollowJointTrajectoryResult.INVALID_JOINTS, result.error_string)
        for name in ("arm2_joint_1", "arm1_joint_1"):
            self.assertIn(name, result.error_string)
        # the same on joint_path_command: refused, said on /rosout by arm1's driver
        after = time.monotonic()
        arm1.path_pub.publish(JointTrajectory(joint_names=joints("arm2"), points=goal.trajectory.points))
        refusal = self.rosout.wait_for(lambda m: m.name == "/arm1/interface" and "joint_path_command refused"
                                       in m.msg, 10.0, after=after)
        self.assertIsNotNone(refusal, "arm1 did not refuse the arm2 joint path")
        self.assertIn("arm2_joint_1", refusal.msg)
        # nothing reached either controller (both refusals come before anything is queued)
        self.assertEqual((len(arm1.entries()), len(arm2.entries())), (before1, before2))


if __name__ == "__main__":
    rostest.rosrun(PKG, "two_arms", TwoArmsTest)
