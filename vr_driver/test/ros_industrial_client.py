#!/usr/bin/python3
"""rostest of the ROS-Industrial driver interface (test/ros_industrial.test, issue 26), written
against the ROS-Industrial robot driver specification, not against this driver's code: the MD5 sums
below are industrial_msgs' and control_msgs' own (as their generated code carries them), and every
topic and service is checked over the master and the wire (the TCPROS connection headers), so a
ROS-Industrial client that knows only industrial_msgs / control_msgs talks to this driver. The
service and message classes used to call are this package's copies; their MD5 is asserted equal to
the specification's first, so a call with them is a call with the specification's type.

The driver runs as the support package's robot_interface_streaming_vr006l.launch starts it (sim;
ros_industrial.test: protocol v2, joint targets streamed; ros_industrial_v1.test: protocol v1, one
target at a time)."""
from __future__ import annotations

import math
import threading
import time

import actionlib
import rosgraph
import rospy
import rosservice
import rostest
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from rospy import AnyMsg
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from driver_check import PKG, DriverTestBase, Recorder

# ---- the specification: industrial_msgs 0.7.x and control_msgs 1.5 (ROS Noetic), by type
SPEC_MD5 = {
    "industrial_msgs/StopMotion": "50b1f38f75f5677e5692f3b3e7e1ea48",
    "industrial_msgs/StartMotion": "50b1f38f75f5677e5692f3b3e7e1ea48",
    "industrial_msgs/CmdJointTrajectory": "94fdf82abbbb1071bc31be1a2aea4fcd",
    "industrial_msgs/GetRobotInfo": "5db3230b3e61c85a320b999ffd7f3b3f",
    "industrial_msgs/ServiceReturnCode": "85a4e241266be66b1e1426b03083a412",
    "industrial_msgs/DeviceInfo": "373ed7fa0fac92d443be9cd5198e80f0",
    "industrial_msgs/RobotStatus": "b733cb45a38101840b75c4c0d6093d19",
    "control_msgs/FollowJointTrajectoryFeedback": "10817c60c2486ef6b33e97dcd87f4474",
    "control_msgs/FollowJointTrajectoryActionGoal": "cff5c1d533bf2f82dd0138d57f4304bb",
    "trajectory_msgs/JointTrajectory": "65b4f94a94d1ed67169da35a02f33d3f",
    "sensor_msgs/JointState": "3066dcd76a6cfaef579bd0f34173e9fd",
}
SUCCESS, FAILURE = 1, -1                      # industrial_msgs/ServiceReturnCode
SERVICES = {"/stop_motion": "industrial_msgs/StopMotion", "/start_motion": "industrial_msgs/StartMotion",
            "/joint_path_command": "industrial_msgs/CmdJointTrajectory",
            "/get_robot_info": "industrial_msgs/GetRobotInfo"}
PUBLISHED = {"/feedback_states": "control_msgs/FollowJointTrajectoryFeedback",
             "/robot_status": "industrial_msgs/RobotStatus", "/joint_states": "sensor_msgs/JointState"}
NAMES = ["joint_%d" % i for i in range(1, 7)]
DEG = math.pi / 180.0


def service_md5(name: str) -> str:
    """The MD5 the service itself announces on a probe connection (what a client's call is checked
    against)."""
    uri = rosservice.get_service_uri(name)
    assert uri, "no service %s" % name
    return rosservice.get_service_headers(name, uri)["md5sum"]


def topic_md5(name: str, timeout: float = 10.0) -> str:
    """The MD5 in the publisher's connection header of the first message of ``name``."""
    got = {}
    done = threading.Event()

    def cb(msg):
        got["md5"] = msg._connection_header["md5sum"]
        done.set()
    sub = rospy.Subscriber(name, AnyMsg, cb, queue_size=1)
    try:
        assert done.wait(timeout), "no message on %s in %.0f s" % (name, timeout)
    finally:
        sub.unregister()
    return got["md5"]


def path_msg(q0, targets, times):
    msg = JointTrajectory(joint_names=list(NAMES))
    msg.points = [JointTrajectoryPoint(positions=list(q0), time_from_start=rospy.Duration(0.0))]
    msg.points += [JointTrajectoryPoint(positions=list(q), time_from_start=rospy.Duration(t))
                   for q, t in zip(targets, times)]
    return msg


class RosIndustrialTest(DriverTestBase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        from vr_driver.srv import CmdJointTrajectory, GetRobotInfo, StartMotion, StopMotion
        from vr_driver.msg import FollowJointTrajectoryFeedback
        cls.classes = {"industrial_msgs/StopMotion": StopMotion, "industrial_msgs/StartMotion": StartMotion,
                       "industrial_msgs/CmdJointTrajectory": CmdJointTrajectory,
                       "industrial_msgs/GetRobotInfo": GetRobotInfo,
                       "control_msgs/FollowJointTrajectoryFeedback": FollowJointTrajectoryFeedback,
                       "trajectory_msgs/JointTrajectory": JointTrajectory}
        for name in SERVICES:
            rospy.wait_for_service(name, 20.0)
        cls.ri_stop = rospy.ServiceProxy("/stop_motion", StopMotion)
        cls.ri_start = rospy.ServiceProxy("/start_motion", StartMotion)
        cls.ri_path = rospy.ServiceProxy("/joint_path_command", CmdJointTrajectory)
        cls.ri_info = rospy.ServiceProxy("/get_robot_info", GetRobotInfo)
        cls.feedback = Recorder("/feedback_states", FollowJointTrajectoryFeedback)
        cls.diagnostics = Recorder("/diagnostics", DiagnosticArray)

    # ------------------------------------------------------------------ helpers
    def rest_joints(self):
        """At HOME, at rest: the joints of the first joint_states sample after it."""
        return self.at_home()

    def bus_cycle_rate(self, window):
        """Bus cycles per second over the last ``window`` s, from the driver's /diagnostics cycle
        counter (the first and the last message in it)."""
        def cycles(msg):
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if "bus cycles" in values:
                    return float(values["bus cycles"])
            return None
        now = time.monotonic()
        with self.diagnostics.cond:
            seen = [(t, cycles(m)) for m, t in zip(self.diagnostics.messages, self.diagnostics.times)
                    if t >= now - window - 1.0]
        seen = [(t, c) for t, c in seen if c is not None]
        self.assertGreaterEqual(len(seen), 2, "no bus cycle counts on /diagnostics")
        (t0, c0), (t1, c1) = seen[0], seen[-1]
        return (c1 - c0) / (t1 - t0) if t1 > t0 else 0.0

    def wait_at(self, target, tol, timeout):
        return self.joints.wait_for(lambda m: max(abs(a - b) for a, b in zip(m.position, target)) < tol,
                                    timeout, after=time.monotonic())

    # ------------------------------------------------------------------ tests
    def test_01_every_type_has_the_specifications_md5(self):
        for cls_type, cls in self.classes.items():
            self.assertEqual(cls._md5sum, SPEC_MD5[cls_type], cls_type)
        for name, kind in SERVICES.items():
            self.assertEqual(service_md5(name), SPEC_MD5[kind], "%s is not %s" % (name, kind))
        for name, kind in PUBLISHED.items():
            self.assertEqual(topic_md5(name), SPEC_MD5[kind], "%s is not %s" % (name, kind))
        # subscribed: a publisher of the specification's types gets a connection from the driver
        for name, kind, msg_class in (("/joint_path_command", "trajectory_msgs/JointTrajectory", JointTrajectory),):
            self.assertEqual(msg_class._md5sum, SPEC_MD5[kind])
            pub = rospy.Publisher(name, msg_class, queue_size=1)
            end = time.monotonic() + 10.0
            while pub.get_num_connections() == 0 and time.monotonic() < end:
                time.sleep(0.05)
            self.assertGreater(pub.get_num_connections(), 0, "the driver does not take %s on %s" % (kind, name))
            pub.unregister()
        # the action's goal topic is subscribed with control_msgs' goal type
        master = rosgraph.Master("/ros_industrial_client")
        types = dict(master.getTopicTypes())
        self.assertIn("/joint_trajectory_action/goal", types)
        from vr_driver.msg import FollowJointTrajectoryActionGoal
        self.assertEqual(FollowJointTrajectoryActionGoal._md5sum, SPEC_MD5["control_msgs/FollowJointTrajectoryActionGoal"])

    def test_02_controller_joint_names_in_the_drivers_namespace(self):
        self.assertEqual(rospy.get_param("/controller_joint_names"), NAMES)
        self.assertEqual(rospy.get_param("/interface/controller_joint_names"), NAMES)

    def test_03_get_robot_info(self):
        info = self.ri_info()
        self.assertEqual(info.code.val, SUCCESS)
        self.assertIn("G2", info.controller.model)
        protocol = rospy.get_param("/interface/protocol")
        self.assertIn("protocol %s" % protocol, info.controller.model)    # the protocol the launch chose
        self.assertIn("PROFIBUS-DP", info.controller.address)
        self.assertRegex(info.controller.sw_version, r"vr_driver \d+\.\d+\.\d+")
        self.assertEqual(len(info.robots), 1)
        self.assertIn("VR-006L", info.robots[0].model)
        self.assertEqual((info.controller.serial_number, info.robots[0].serial_number), ("", ""))

    def test_04_start_motion_says_whether_motion_is_possible(self):
        self.wait_motion_possible()
        self.assertEqual(self.ri_start().code.val, SUCCESS)
        self.assertTrue(self.set_estop(True).success)
        try:
            self.assertIsNotNone(self.status.wait_for(lambda m: m.e_stopped.val == 1, 10.0, after=time.monotonic()))
            self.assertEqual(self.ri_start().code.val, FAILURE)
        finally:
            self.set_estop(False)
            self.set_drives(True)            # the e-stop switched them off (as on the G2)
        self.wait_motion_possible()
        self.assertEqual(self.ri_start().code.val, SUCCESS)

    def test_05_feedback_states_at_the_joint_states_rate_and_consistent(self):
        q0 = self.rest_joints()
        j0, f0 = len(self.joints.messages), len(self.feedback.messages)
        window = 3.0
        time.sleep(window)                  # counting messages over a fixed window
        with self.joints.cond, self.feedback.cond:
            js = self.joints.messages[j0:]
            fb = self.feedback.messages[f0:]
        rate = float(rospy.get_param("/interface/joint_states_rate", 20.0))
        # one joint_states per controller record, at most at its rate: the bus's own cycle rate
        # over the window (the driver's /diagnostics cycle counter) bounds it on a loaded machine
        bus_rate = self.bus_cycle_rate(window)
        rospy.loginfo("ros_industrial: over %.1f s: %d joint_states, %d feedback_states; the bus at %.1f cycles/s",
                      window, len(js), len(fb), bus_rate)
        self.assertGreater(len(js), 0.5 * min(rate, bus_rate) * window,
                           "joint_states slower than its rate (%g /s) and the bus (%.1f cycles/s)" % (rate, bus_rate))
        self.assertLessEqual(abs(len(fb) - len(js)), 2, "feedback_states %d vs joint_states %d" % (len(fb), len(js)))
        js_stamps = {m.header.stamp.to_nsec() for m in js}
        same = sum(1 for m in fb if m.header.stamp.to_nsec() in js_stamps)
        self.assertGreaterEqual(same, len(fb) - 2, "feedback_states not stamped as joint_states")
        for m in fb:
            self.assertEqual(list(m.joint_names), NAMES)
            for d, a, e in zip(m.desired.positions, m.actual.positions, m.error.positions):
                self.assertAlmostEqual(e, a - d, places=9)
            # at rest: the desired joints are the actual ones
            self.assertLess(max(abs(a - d) for a, d in zip(m.actual.positions, m.desired.positions)), 1e-9)
            self.assertLess(max(abs(a - q) for a, q in zip(m.actual.positions, q0)), 0.01)

    def test_06_a_path_through_the_joint_path_command_service_runs(self):
        q0 = self.rest_joints()
        target = list(q0)
        target[0] += 20 * DEG
        mid = [(a + b) / 2 for a, b in zip(q0, target)]
        before = len(self.feedback.messages)
        # refused: NaN in a point -- FAILURE, nothing moves
        bad = path_msg(q0, [mid, [float("nan")] + target[1:]], [1.5, 3.0])
        self.assertEqual(self.ri_path(bad).code.val, FAILURE)
        self.assertIsNone(self.joints.wait_for(lambda m: abs(m.position[0] - q0[0]) > 0.5 * DEG, 1.0,
                                               after=time.monotonic()), "a refused path moved the arm")
        # accepted: SUCCESS, the arm goes there
        self.assertEqual(self.ri_path(path_msg(q0, [mid, target], [1.5, 3.0])).code.val, SUCCESS)
        self.assertIsNotNone(self.wait_at(target, 0.2 * DEG, 15.0), "the path did not arrive")
        # feedback_states on the way: desired was the plan (between start and end, ahead of rest)
        with self.feedback.cond:
            seen = self.feedback.messages[before:]
        moving = [m for m in seen if abs(m.desired.positions[0] - m.actual.positions[0]) > 1e-6]
        self.assertTrue(moving, "feedback_states never had desired != actual during the path")
        # v1 runs each point as a Cartesian target in whole mm / deg: its joint target lands up to
        # 1.5 deg from the point asked for (its default goal tolerance is twice that)
        slack = {"v1": 1.6 * DEG}.get(rospy.get_param("/interface/protocol"), 1e-6)
        for m in moving:
            self.assertTrue(min(q0[0], target[0]) - slack <= m.desired.positions[0] <= max(q0[0], target[0]) + slack,
                            "desired %.4f outside the path %.4f .. %.4f" % (m.desired.positions[0], q0[0], target[0]))

    def test_07_stop_motion_stops_a_running_trajectory(self):
        """J1 out to -35 deg and over to +35 deg (a stop point between for v1, which runs each
        point at the program's own speed); stop_motion during the first half: the goal ends
        without success and the arm rests far from the end."""
        q0 = self.rest_joints()
        out, over = list(q0), list(q0)
        out[0] -= 35 * DEG                   # J1 from HOME: 640 mm off the x axis, inside the box
        over[0] += 35 * DEG
        goal = self.trajectory_goal([out, over], [3.5, 10.5])
        done = threading.Event()

        def transition(handle):
            if handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()
        handle = self.trajectory_client.send_goal(goal, transition_cb=transition)
        self.assertIsNotNone(self.joints.wait_for(lambda m: q0[0] - m.position[0] > 8 * DEG, 15.0,
                                                  after=time.monotonic()), "the trajectory never moved")
        self.assertEqual(self.ri_stop().code.val, SUCCESS)
        self.assertTrue(done.wait(20.0), "the trajectory goal did not end after stop_motion")
        self.assertNotEqual(handle.get_goal_status(), GoalStatus.SUCCEEDED)
        rest = self.status.wait_for(lambda m: m.in_motion.val == 0, 10.0, after=time.monotonic())
        self.assertIsNotNone(rest, "the arm did not come to rest")
        final = self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position
        rospy.loginfo("ros_industrial: stop_motion: J1 came to rest at %.1f deg on a 0 -> -35 -> +35 deg "
                      "trajectory", (final[0] - q0[0]) / DEG)
        self.assertGreater(over[0] - final[0], 30 * DEG, "the arm went on towards the end: not stopped")
        # and start_motion: motion is possible again (stop_motion latches nothing)
        self.assertEqual(self.ri_start().code.val, SUCCESS)

if __name__ == "__main__":
    rostest.rosrun(PKG, "ros_industrial", RosIndustrialTest)
