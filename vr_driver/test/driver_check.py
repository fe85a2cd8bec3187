#!/usr/bin/python3
"""rostest of the driver against the virtual controller (launch/driver.launch, sim:=true): a real
roscore, real nodes, a real pty carrying real PROFIBUS telegrams.

Run by test/driver.test. The virtual controller's execution log is read from
/virtual_controller/executed (one JSON object per handled target), so "executed once" is checked on
what the controller did, not on what the driver believes. Waits are on messages with deadlines."""
from __future__ import annotations

import json
import math
import os
import threading
import time
import unittest
from typing import Callable, List

import actionlib
import rosgraph
import rospy
from vr_driver.ros.support import init_node
import rostest
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import MarkerArray

from vr_driver.controller.pty_link import auto_pty_link
from vr_driver.controller.simulator import SimDeviceError
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.kinematics.solver import Kinematics
from vr_driver.msg import (CartesianPose, FollowJointTrajectoryAction, FollowJointTrajectoryGoal,
                           FollowJointTrajectoryResult, JointTolerance, MoveToPoseAction, MoveToPoseGoal,
                           RobotStatus, ServiceReturnCode, TriState)
from vr_driver.poses import ControllerPose
from vr_driver.srv import StopMotion

PKG = "vr_driver"
HOME = (1120, 0, 725, 0, 45, 0)


class Recorder:
    """Keeps every message of a topic with its arrival time; wait_for(predicate) with a deadline."""

    def __init__(self, topic, kind):
        self.messages: List = []
        self.times: List[float] = []
        self.cond = threading.Condition()
        self.sub = rospy.Subscriber(topic, kind, self._cb, queue_size=100)

    def _cb(self, msg):
        with self.cond:
            self.messages.append(msg)
            self.times.append(time.monotonic())
            self.cond.notify_all()

    def wait_for(self, predicate: Callable[[object], bool], timeout: float, after: float = 0.0,
                 start: int = 0):
        """The first message (from index ``start``, arrived at or after ``after``) that satisfies
        ``predicate``, waiting up to ``timeout``; None if none came."""
        end = time.monotonic() + timeout
        with self.cond:
            while True:
                for msg, t in zip(self.messages[start:], self.times[start:]):
                    if t >= after and predicate(msg):
                        return msg
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self.cond.wait(left)

    def wait_count(self, n: int, timeout: float) -> bool:
        end = time.monotonic() + timeout
        with self.cond:
            while len(self.messages) < n:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self.cond.wait(left)
        return True

    def last(self):
        with self.cond:
            return self.messages[-1] if self.messages else None


def top_tcp_speed(kin, samples, window: float) -> float:
    """[mm/s] the TCP's largest speed over ``samples`` ((stamp [s], joints) in time order): each
    sample against the latest one at least ``window`` s before it (stamps jitter by milliseconds)."""
    xyz = [(t, kin.fk_pose(q).as_tuple()[:3]) for t, q in samples]
    best, j = 0.0, 0
    for i, (t, p) in enumerate(xyz):
        while j + 1 < i and t - xyz[j + 1][0] >= window:
            j += 1
        t0, p0 = xyz[j]
        if j < i and t - t0 >= window:
            best = max(best, math.dist(p, p0) / (t - t0))
    return best


def plan_as_sampled(times, positions, samples, step: float = 0.005):
    """The plan (``times`` [s], joint ``positions``: piecewise linear between them, held before its
    start and after its end) at the stamps of the measured ``samples`` ((stamp [s], joints) in time
    order), shifted by the start that fits them best (searched in ``step`` s over the samples' span):
    (that start [stamp], the largest joint difference there [rad], [(stamp, planned joints)]).

    A top speed measured from joint_states is an average over the time between two samples (a bus
    cycle or, on a loaded machine, a late one: 190 ms was seen): compared with the same average of
    the plan at the same stamps it measures the run, not the sampling."""
    import numpy as np
    times = np.asarray(times, dtype=float)
    plan = np.asarray(positions, dtype=float)
    stamps = np.array([t for t, _ in samples], dtype=float)
    measured = np.array([q for _, q in samples], dtype=float)

    def at(start):
        return np.stack([np.interp(stamps - start, times, plan[:, j]) for j in range(plan.shape[1])], axis=1)

    best = None
    for start in np.arange(stamps[0] - float(times[-1]), stamps[-1] + step, step):
        err = float(np.max(np.abs(at(start) - measured)))
        if best is None or err < best[1]:
            best = (float(start), err)
    start, err = best
    return start, err, [(float(t), tuple(float(v) for v in q)) for t, q in zip(stamps, at(start))]


def cp(values) -> CartesianPose:
    return CartesianPose(*[float(v) for v in values])


def as_pose(msg: CartesianPose) -> ControllerPose:
    return ControllerPose(msg.x, msg.y, msg.z, msg.rx, msg.ry, msg.rz)


class DriverTestBase(unittest.TestCase):
    """The recorders, clients and helpers of the driver rostests (no tests)."""

    @classmethod
    def setUpClass(cls):
        init_node("driver_check")
        cls.kin = Kinematics.default()
        cls.executed = Recorder("/virtual_controller/executed", String)
        cls.status = Recorder("/robot_status", RobotStatus)
        cls.joints = Recorder("/joint_states", JointState)
        cls.tool = Recorder("/tool_pose", PoseStamped)
        cls.diag = Recorder("/diagnostics", DiagnosticArray)
        cls.rosout = Recorder("/rosout", Log)
        cls.markers = Recorder("/interface/markers", MarkerArray)
        cls.client = actionlib.SimpleActionClient("/move_to_pose", MoveToPoseAction)
        cls.raw_client = actionlib.ActionClient("/move_to_pose", MoveToPoseAction)
        cls.trajectory_client = actionlib.ActionClient("/joint_trajectory_action", FollowJointTrajectoryAction)
        cls.started = time.monotonic()
        assert cls.client.wait_for_server(rospy.Duration(20.0)), "move_to_pose server not up"
        assert cls.raw_client.wait_for_server(rospy.Duration(20.0)), "move_to_pose server not up"
        assert cls.trajectory_client.wait_for_server(rospy.Duration(20.0)), "joint_trajectory_action not up"
        rospy.wait_for_service("/virtual_controller/set_estop", 20.0)
        cls.set_estop = rospy.ServiceProxy("/virtual_controller/set_estop", SetBool)
        cls.set_drives = rospy.ServiceProxy("/virtual_controller/set_drives_powered", SetBool)
        cls.stop_motion = rospy.ServiceProxy("/stop_motion", StopMotion)
        cls.path_pub = rospy.Publisher("/joint_path_command", JointTrajectory, queue_size=1)

    # -------------------------------------------------------------------- helpers
    def entries(self):
        with self.executed.cond:
            return [json.loads(m.data) for m in self.executed.messages]

    def refusals(self):
        with self.rosout.cond:
            return [m for m in self.rosout.messages
                    if m.name == "/interface" and "joint_path_command refused" in m.msg]

    def wait_motion_possible(self, timeout=10.0):
        msg = self.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE, timeout,
                                   after=time.monotonic())
        self.assertIsNotNone(msg, "motion_possible never became TRUE")

    def at_home(self):
        """The arm at HOME (a known start): a PTP there, also when it is there already (with v3 that
        is one target with its pose: it once had none and the bus thread dropped the link); the
        joints of the first joint_states sample after it."""
        self.wait_motion_possible()
        state, result = self.move(MoveToPoseGoal.PTP, HOME)
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        return list(self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position)

    def move(self, kind, target, via=None, preview_only=False, timeout=40.0):
        goal = MoveToPoseGoal(target=cp(target), move_type=kind, has_via=via is not None,
                              via=cp(via) if via is not None else CartesianPose(),
                              preview_only=preview_only)
        return self.send_and_wait(self.raw_client, goal, timeout, "no result in time")

    def send_and_wait(self, client, goal, timeout, message):
        """(status, result) of one goal sent on a plain ActionClient. SimpleActionClient drops a
        transition that arrives before its send_goal() has returned (ros/actionlib#206, "Got a
        transition callback on a goal handle that we're not tracking"), and the driver refuses a
        bad goal that fast: the test then waited for a result it had already been sent (about 1
        run in 10 under load)."""
        done = threading.Event()

        def transition(handle):
            if handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()
        handle = client.send_goal(goal, transition_cb=transition)
        self.assertTrue(done.wait(timeout), message)
        return handle.get_goal_status(), handle.get_result()

    def wait_entries(self, n, timeout=10.0):
        self.assertTrue(self.executed.wait_count(n, timeout), "expected %d executed entries, have %d"
                        % (n, len(self.executed.messages)))
        return self.entries()

    def trajectory_goal(self, points, times, names=None, tol=None):
        goal = FollowJointTrajectoryGoal()
        goal.trajectory.joint_names = list(names or ["joint_%d" % i for i in range(1, 7)])
        goal.trajectory.points = [JointTrajectoryPoint(positions=list(p), time_from_start=rospy.Duration(t))
                                  for p, t in zip(points, times)]
        if tol is not None:
            goal.path_tolerance = [JointTolerance(name=n, position=tol) for n in goal.trajectory.joint_names]
            goal.goal_tolerance = [JointTolerance(name=n, position=tol) for n in goal.trajectory.joint_names]
        return goal

    def follow(self, goal, timeout=60.0):
        return self.send_and_wait(self.trajectory_client, goal, timeout,
                                  "no result from joint_trajectory_action")

    def check_on_path(self, points, times, q0, start, tol=None):
        """joint_states from message ``start`` on stayed within the path tolerance of the planned
        path (``tol``, or 1 deg: validate's fallback) -- and some were seen on the way, not only at its ends."""
        from vr_driver.driver.motion.trajectories import TrajectoryGoal, path_deviation, validate
        names = tuple("joint_%d" % i for i in range(1, 7))
        lim = self.kin.limits
        plan = validate(TrajectoryGoal(names, tuple(map(tuple, points)), tuple(times),
                                       path_tolerance={n: tol for n in names} if tol is not None else {}),
                        names, q0, lim.lower, lim.upper, 0.0)
        with self.joints.cond:
            seen = [m.position for m in self.joints.messages[start:]]
        travel = [(q[0] - q0[0]) / (points[-1][0] - q0[0]) for q in seen]
        self.assertTrue(any(0.2 < f < 0.8 for f in travel), "no joint_states during the motion")
        worst = max(path_deviation(plan, q)[0] for q in seen)
        self.assertLessEqual(worst, 1.0, "left the path tolerance (%.2f x)" % worst)

    def check_trajectory_refusals(self):
        """Each bad goal of joint_trajectory_action is refused with its control_msgs code, a reason,
        and nothing reaches the controller."""
        self.wait_motion_possible()
        before = len(self.entries())
        q0 = list(self.joints.last().position)
        q1 = [q0[0] + 0.2] + q0[1:]
        nan = float("nan")
        names = ["joint_%d" % i for i in range(1, 7)]
        cases = [
            (self.trajectory_goal([q1], [1.0], names=names[:5] + ["joint_x"]),
             FollowJointTrajectoryResult.INVALID_JOINTS),
            (self.trajectory_goal([q1], [1.0], names=names[:5]), FollowJointTrajectoryResult.INVALID_JOINTS),
            (self.trajectory_goal([q1, q1], [1.0, 1.0]), FollowJointTrajectoryResult.INVALID_GOAL),
            (self.trajectory_goal([q1, q0], [1.0, 0.5]), FollowJointTrajectoryResult.INVALID_GOAL),
            (self.trajectory_goal([[q0[0] + 2.0] + q0[1:]], [0.1]), FollowJointTrajectoryResult.INVALID_GOAL),
            (self.trajectory_goal([q0[:2] + [nan] + q0[3:]], [1.0]), FollowJointTrajectoryResult.INVALID_GOAL),
            (self.trajectory_goal([[0.0, 1.5, 0.5, 0.0, 0.0, 0.0]], [5.0]),     # below the floor
             FollowJointTrajectoryResult.INVALID_GOAL),
        ]
        for goal, code in cases:
            state, result = self.follow(goal, 20.0)
            self.assertIn(state, (GoalStatus.REJECTED, GoalStatus.ABORTED))
            self.assertEqual(result.error_code, code, result.error_string)
            self.assertTrue(result.error_string)
        self.status.wait_for(lambda m: False, 0.5)
        self.assertEqual(len(self.entries()), before)



class DriverTest(DriverTestBase):
    # -------------------------------------------------------------------- tests (run in name order)
    def test_01_status_and_joint_states_at_their_rates(self):
        first = self.status.wait_for(lambda m: True, 5.0)
        self.assertIsNotNone(first, "no robot_status within 5 s of launch")
        self.assertIsNotNone(self.joints.wait_for(lambda m: True, 5.0), "no joint_states within 5 s")
        self.wait_motion_possible()
        t0 = time.monotonic()
        n_status, n_joints = len(self.status.messages), len(self.joints.messages)
        self.status.wait_for(lambda m: False, 2.0)          # collect for 2 s
        dt = time.monotonic() - t0
        status_rate = (len(self.status.messages) - n_status) / dt
        joint_rate = (len(self.joints.messages) - n_joints) / dt
        self.assertAlmostEqual(status_rate, 10.0, delta=3.0)
        self.assertAlmostEqual(joint_rate, 20.0, delta=5.0)
        js = self.joints.last()
        self.assertEqual(list(js.name), ["joint_%d" % i for i in range(1, 7)])
        # one message per controller record, stamped with the time the controller took it: the
        # stamps strictly increase (a record is never re-published under a new stamp) and lie
        # before the moment the message was read, by the reply's time on the wire at least
        with self.joints.cond:
            stamps = [m.header.stamp.to_sec() for m in self.joints.messages[n_joints:]]
        self.assertGreater(len(stamps), 10)
        self.assertTrue(all(b > a for a, b in zip(stamps, stamps[1:])), stamps)
        self.assertLess(stamps[-1], rospy.get_time())
        tool = self.tool.last()
        self.assertEqual(tool.header.frame_id, "base")
        p, q = tool.pose.position, tool.pose.orientation
        reported = ControllerPose.from_ros((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        dp, da = self.kin.fk_pose(js.position).distance_to(reported)
        self.assertLess(dp, 1.0)
        self.assertLess(da, 1.0)
        # (diagnostic_updater's first message says "Node starting up" with no values: wait for the task's)
        diag = self.diag.wait_for(lambda m: any("link" in s.name and any(kv.key == "bus retries" for kv in s.values)
                                                for s in m.status), 5.0)
        self.assertIsNotNone(diag, "no link diagnostics")
        link = [s for s in diag.status if "link" in s.name][0]
        keys = {kv.key for kv in link.values}
        self.assertIn("bus retries", keys)
        self.assertIn("link reconnects", keys)
        # /diagnostics at its period (1 s): it alternated 1 s and 2 s (0.67 Hz) before
        start = len(self.diag.messages)
        self.assertTrue(self.diag.wait_count(start + 5, 10.0), "fewer than 5 diagnostics in 10 s")
        with self.diag.cond:
            times = self.diag.times[start:start + 5]
        gaps = [b - a for a, b in zip(times, times[1:])]
        self.assertLess(max(gaps), 1.6, gaps)

    def test_02_ptp_lin_circ_goals_execute_once(self):
        self.wait_motion_possible()
        before = len(self.entries())
        state, result = self.move(MoveToPoseGoal.PTP, (1000, 200, 800, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        self.assertLessEqual(as_pose(result.reached).distance_to(ControllerPose(1000, 200, 800, 0, 45, 0))[0], 1.0)
        state, result = self.move(MoveToPoseGoal.LIN, (1000, -150, 800, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        state, result = self.move(MoveToPoseGoal.CIRC, (1000, 150, 800, 0, 45, 0),
                                  via=(1100, 0, 800, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        entries = self.wait_entries(before + 4)[before:]
        self.assertEqual([(e["move_type"], e["target"], e["outcome"]) for e in entries], [
            ("PTP", [1000, 200, 800, 0, 45, 0], "executed"),
            ("LIN", [1000, -150, 800, 0, 45, 0], "executed"),
            ("CIRC_VIA", [1100, 0, 800, 0, 45, 0], "via_stored"),
            ("CIRC_END", [1000, 150, 800, 0, 45, 0], "executed"),
        ])
        state, result = self.move(MoveToPoseGoal.LIN, (1000, 0, 700, 0, 45, 0), preview_only=True)
        self.assertEqual(state, GoalStatus.SUCCEEDED)
        self.assertEqual(len(result.joint_target), 6)
        self.assertGreater(result.estimated_duration, 0.0)

    def test_03_bad_goals_are_refused_and_nothing_is_sent(self):
        self.wait_motion_possible()
        before = len(self.entries())
        for target, words in [((1500, 0, 725, 0, 45, 0), "workspace"),
                              ((1400, 0, 1400, 0, 0, 0), "reach"),
                              ((1120, 0, float("nan"), 0, 45, 0), "finite")]:
            state, result = self.move(MoveToPoseGoal.PTP, target)
            self.assertEqual(state, GoalStatus.ABORTED)
            self.assertFalse(result.success)
            self.assertIn(words, result.reason.lower())
        state, result = self.move(7, HOME)
        self.assertEqual(state, GoalStatus.ABORTED)
        self.assertIn("move_type", result.reason)
        # a good goal afterwards is the only new entry: the refused ones never reached the bus
        state, result = self.move(MoveToPoseGoal.PTP, (1050, 0, 750, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        entries = self.wait_entries(before + 1)[before:]
        self.assertEqual([e["target"] for e in entries], [[1050, 0, 750, 0, 45, 0]])

    def test_04_cancel_mid_motion_stops_the_arm(self):
        self.wait_motion_possible()
        before = len(self.entries())
        target = (1000, 650, 800, 0, 45, 0)                   # LIN at 0.25 m/s: ~2.5 s
        state, preview = self.move(MoveToPoseGoal.LIN, target, preview_only=True)
        self.assertEqual(state, GoalStatus.SUCCEEDED, preview.reason)
        self.assertGreater(preview.estimated_duration, 1.0)   # long enough to cancel half way
        goal = MoveToPoseGoal(target=cp(target), move_type=MoveToPoseGoal.LIN)
        moving = threading.Event()
        self.client.send_goal(goal, feedback_cb=lambda fb: fb.phase == "moving" and moving.set())
        self.assertTrue(moving.wait(10.0), "never saw the moving phase")
        self.client.cancel_goal()
        self.assertTrue(self.client.wait_for_result(rospy.Duration(10.0)))
        self.assertEqual(self.client.get_state(), GoalStatus.PREEMPTED)
        (entry,) = self.wait_entries(before + 1)[before:]
        self.assertEqual(entry["outcome"], "rejected")
        self.assertIn("stop", entry["reason"])
        stopped = ControllerPose(*entry["final_pose"])
        # the result reports where the arm came to rest: the controller's own rest pose, exactly
        self.assertEqual(as_pose(self.client.get_result().reached), stopped)
        self.assertGreater(stopped.distance_to(ControllerPose(*target))[0], 20.0)
        # it stays where it stopped
        self.wait_motion_possible()
        tool = self.tool.wait_for(lambda m: True, 2.0, after=time.monotonic())
        p = tool.pose.position
        self.assertLess(math.dist((p.x * 1000, p.y * 1000, p.z * 1000), stopped.as_tuple()[:3]), 1.5)

    def test_05_joint_path_in_order_and_empty_stops(self):
        self.wait_motion_possible()
        before = len(self.entries())
        q = list(self.joints.last().position)
        traj = JointTrajectory(joint_names=["joint_%d" % i for i in range(1, 7)])
        for k in range(1, 6):
            point = [q[0] + 0.08 * k, q[1], q[2] - 0.04 * k, 0.0, q[4], 0.1 * k]
            traj.points.append(JointTrajectoryPoint(positions=point))
        expected = [self.kin.fk_pose(p.positions) for p in traj.points]
        self.path_pub.publish(traj)
        entries = self.wait_entries(before + 5, 40.0)[before:]
        self.assertEqual([e["move_type"] for e in entries], ["PTP"] * 5)
        for entry, pose in zip(entries, expected):
            self.assertTrue(all(abs(a - b) <= 0.5 for a, b in zip(entry["target"], pose.as_tuple())),
                            (entry["target"], pose))
            self.assertEqual(entry["outcome"], "executed")
        # a long path, then an empty one: it stops and the rest never goes out
        self.wait_motion_possible()
        before = len(self.entries())
        q = list(self.joints.last().position)
        long_path = JointTrajectory(joint_names=traj.joint_names)
        for k in range(1, 6):
            long_path.points.append(JointTrajectoryPoint(
                positions=[q[0] + (0.5 if k % 2 else -0.5), q[1], q[2], q[3], q[4], q[5]]))
        self.path_pub.publish(long_path)
        self.status.wait_for(lambda m: m.in_motion.val == TriState.TRUE, 10.0, after=time.monotonic())
        self.path_pub.publish(JointTrajectory(joint_names=traj.joint_names))
        self.wait_motion_possible()
        self.status.wait_for(lambda m: False, 1.0)         # give a wrongly sent target time to show
        self.assertLess(len(self.entries()) - before, 5)

    def test_06_estop_refuses_goals_until_cleared(self):
        self.wait_motion_possible()
        before = len(self.entries())
        self.assertTrue(self.set_estop(True).success)
        msg = self.status.wait_for(lambda m: m.e_stopped.val == TriState.TRUE, 2.0, after=time.monotonic())
        self.assertIsNotNone(msg, "robot_status.e_stopped never TRUE")
        self.assertEqual(msg.motion_possible.val, TriState.FALSE)
        state, result = self.move(MoveToPoseGoal.PTP, (1000, 0, 800, 0, 45, 0))
        self.assertEqual(state, GoalStatus.ABORTED)
        self.assertIn("emergency stop", result.reason)
        self.assertTrue(self.set_estop(False).success)
        self.assertTrue(self.set_drives(True).success)
        self.wait_motion_possible()
        state, result = self.move(MoveToPoseGoal.PTP, (1000, 0, 800, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        self.assertEqual([e["target"] for e in self.wait_entries(before + 1)[before:]],
                         [[1000, 0, 800, 0, 45, 0]])

    def test_07_stop_motion_service(self):
        self.wait_motion_possible()
        self.client.send_goal(MoveToPoseGoal(target=cp((800, 600, 1000, 0, 45, 0)),
                                             move_type=MoveToPoseGoal.PTP))
        self.status.wait_for(lambda m: m.in_motion.val == TriState.TRUE, 10.0, after=time.monotonic())
        response = self.stop_motion()
        self.assertEqual(response.code.val, ServiceReturnCode.SUCCESS)
        self.assertTrue(self.client.wait_for_result(rospy.Duration(10.0)))
        self.assertIn(self.client.get_state(), (GoalStatus.PREEMPTED, GoalStatus.ABORTED))
        msg = self.status.wait_for(lambda m: m.in_motion.val == TriState.FALSE, 3.0, after=time.monotonic())
        self.assertIsNotNone(msg)

    def test_08_hostile_inputs_are_refused_and_nothing_is_sent(self):
        self.wait_motion_possible()
        before = len(self.entries())
        inf, nan = float("inf"), float("nan")
        goals = []
        for i in range(6):                                  # NaN, inf, -inf, huge in every field
            for bad in (nan, inf, -inf, 1e308, -1e308):
                target = list(HOME)
                target[i] = bad
                goals.append((MoveToPoseGoal.PTP, target, None))
        goals += [(0, HOME, None), (4, HOME, None), (255, HOME, None),
                  (MoveToPoseGoal.LIN, HOME, (1000, 0, 800, 0, 45, 0)),      # via with LIN
                  (MoveToPoseGoal.CIRC, HOME, None),                          # CIRC without via
                  (MoveToPoseGoal.CIRC, HOME, (nan, 0, 800, 0, 45, 0))]
        for kind, target, via in goals:
            state, result = self.move(kind, target, via=via, timeout=10.0)
            self.assertEqual(state, GoalStatus.ABORTED, (kind, target, via))
            self.assertFalse(result.success)
            self.assertTrue(result.reason, (kind, target, via))
        names = ["joint_%d" % i for i in range(1, 7)]
        q = list(self.joints.last().position)
        for joint_names, points in [
                (names[:5], [q[:5]]),                                  # a joint missing
                (names[:5] + ["joint_x"], [q]),                        # a wrong name
                (names[:5] + ["joint_1"], [q]),                        # a duplicate name
                (names, [q[:5]]),                                      # a short point
                (names, [q + [0.0]]),                                  # a long point
                (names, [q[:2] + [nan] + q[3:]]),
                (names, [q[:2] + [inf] + q[3:]]),
                (names, [q[:2] + [1e9] + q[3:]]),                      # far outside the limits
                ([], [q])]:
            traj = JointTrajectory(joint_names=joint_names)
            traj.points = [JointTrajectoryPoint(positions=p) for p in points]
            seen = len(self.refusals())
            self.path_pub.publish(traj)
            # one refusal per bad path, each logged with its reason (the subscriber keeps only the
            # latest message, so wait for each before sending the next)
            self.assertTrue(self.rosout.wait_for(lambda m: len(self.refusals()) > seen, 5.0),
                            "no refusal logged for %s %s" % (joint_names, points))
        # the node is alive and still works; only the good goal reaches the controller
        self.wait_motion_possible()
        state, result = self.move(MoveToPoseGoal.PTP, (1100, 0, 760, 0, 45, 0))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        self.assertEqual([e["target"] for e in self.wait_entries(before + 1)[before:]],
                         [[1100, 0, 760, 0, 45, 0]])
        self.status.wait_for(lambda m: False, 0.5)          # a wrongly sent path would show by now
        self.assertEqual(len(self.entries()), before + 1)

    def test_09_preview_beside_a_move_and_preemption_by_a_new_move(self):
        self.wait_motion_possible()
        before = len(self.entries())
        other = actionlib.SimpleActionClient("/move_to_pose", MoveToPoseAction)
        self.assertTrue(other.wait_for_server(rospy.Duration(10.0)))
        moving = threading.Event()
        long_lin = MoveToPoseGoal(target=cp((1000, -600, 800, 0, 45, 0)), move_type=MoveToPoseGoal.LIN)
        self.client.send_goal(long_lin, feedback_cb=lambda fb: fb.phase == "moving" and moving.set())
        self.assertTrue(moving.wait(10.0))
        # another client previews while the arm moves: the move goes on
        other.send_goal(MoveToPoseGoal(target=cp((1000, 0, 700, 0, 45, 0)), move_type=MoveToPoseGoal.PTP,
                                       preview_only=True))
        self.assertTrue(other.wait_for_result(rospy.Duration(10.0)))
        self.assertEqual(other.get_state(), GoalStatus.SUCCEEDED)
        self.assertTrue(self.client.wait_for_result(rospy.Duration(20.0)))
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_result().reason)
        # a new motion goal preempts the running one: that one stops, the new one runs
        moving.clear()
        self.client.send_goal(MoveToPoseGoal(target=cp((1000, 600, 800, 0, 45, 0)),
                                             move_type=MoveToPoseGoal.LIN),
                              feedback_cb=lambda fb: fb.phase == "moving" and moving.set())
        self.assertTrue(moving.wait(10.0))
        other.send_goal(MoveToPoseGoal(target=cp((1050, 0, 800, 0, 45, 0)), move_type=MoveToPoseGoal.PTP))
        self.assertTrue(self.client.wait_for_result(rospy.Duration(10.0)))
        self.assertEqual(self.client.get_state(), GoalStatus.PREEMPTED)
        self.assertIn("preempted", self.client.get_result().reason)
        self.assertTrue(other.wait_for_result(rospy.Duration(20.0)))
        self.assertEqual(other.get_state(), GoalStatus.SUCCEEDED, other.get_result().reason)
        entries = self.wait_entries(before + 3)[before:]
        self.assertEqual([(e["target"], e["outcome"]) for e in entries],
                         [([1000, -600, 800, 0, 45, 0], "executed"),
                          ([1000, 600, 800, 0, 45, 0], "rejected"),
                          ([1050, 0, 800, 0, 45, 0], "executed")])

    def test_10_the_newest_of_twenty_goals_sent_back_to_back_wins(self):
        """issue 14: each goal ran in its own thread and the last to get there won (1 of 8
        repeats ended at the newest goal; once the arm went to the first of 20)."""
        self.wait_motion_possible()
        before = len(self.entries())
        client = actionlib.ActionClient("/move_to_pose", MoveToPoseAction)
        self.assertTrue(client.wait_for_server(rospy.Duration(10.0)))
        targets = [(1000, -475 + 50 * k, 800, 0, 45, 0) for k in range(20)]
        done = threading.Event()
        handles = []

        def transition(handle):
            if handles and handle == handles[-1] and \
                    handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()
        for target in targets:
            handles.append(client.send_goal(MoveToPoseGoal(target=cp(target), move_type=MoveToPoseGoal.LIN),
                                            transition_cb=transition))
        self.assertTrue(done.wait(60.0), "the newest goal did not finish")
        last = handles[-1]
        self.assertEqual(last.get_goal_status(), GoalStatus.SUCCEEDED, last.get_result().reason)
        self.assertEqual(as_pose(last.get_result().reached), ControllerPose(*targets[-1]))
        tool = self.tool.wait_for(lambda m: True, 2.0, after=time.monotonic())
        p = tool.pose.position
        self.assertLess(math.dist((p.x * 1000, p.y * 1000, p.z * 1000), targets[-1][:3]), 1.5)
        entries = self.entries()[before:]
        self.assertEqual(entries[-1]["target"], list(targets[-1]))
        self.assertEqual(entries[-1]["outcome"], "executed")
        # an older goal never ran after the newest one started
        self.assertEqual([e for e in entries if e["target"] == list(targets[-1])], entries[-1:])

    def test_11_joint_paths_at_100_hz_replace_each_other(self):
        """issue 14: every one-point path was appended (183 of 183 executed, the arm moving for
        49.5 s after the publisher stopped). Now a new path replaces the queued targets."""
        self.wait_motion_possible()
        before = len(self.entries())
        q0 = list(self.joints.last().position)
        names = ["joint_%d" % i for i in range(1, 7)]
        rate = rospy.Rate(100)
        sent = 0
        for k in range(200):
            q = list(q0)
            q[0] = q0[0] + 0.002 * (k + 1)
            self.path_pub.publish(JointTrajectory(joint_names=names,
                                                  points=[JointTrajectoryPoint(positions=q)]))
            sent += 1
            rate.sleep()
        stopped_publishing = time.monotonic()
        final = self.kin.fk_pose(q)
        # the arm ends at the last path's point soon after the publisher stopped
        msg = self.tool.wait_for(
            lambda m: math.dist((m.pose.position.x * 1000, m.pose.position.y * 1000,
                                 m.pose.position.z * 1000), final.as_tuple()[:3]) < 1.5,
            10.0, after=stopped_publishing)
        self.assertIsNotNone(msg, "the arm did not reach the last path's point")
        settled = self.status.wait_for(lambda m: m.in_motion.val == TriState.FALSE, 10.0,
                                       after=time.monotonic())
        self.assertIsNotNone(settled)
        moving_after = time.monotonic() - stopped_publishing
        entries = self.entries()[before:]
        self.assertLess(len(entries), sent // 2, "paths piled up: %d executed of %d" % (len(entries), sent))
        self.assertLess(moving_after, 5.0)

    def test_12_a_frozen_driver_reports_no_old_good_news(self):
        """issue 14: after SIGSTOP / SIGCONT of the driver, one "motion possible, in motion"
        robot_status went out before in_error. Nothing published after the resume may show the
        pre-freeze state."""
        import os
        import signal
        import xmlrpc.client
        import rosgraph
        self.wait_motion_possible()
        uri = rosgraph.Master("/driver_check").lookupNode("/interface")
        pid = xmlrpc.client.ServerProxy(uri).getPid("/driver_check")[2]
        moving = threading.Event()
        self.client.send_goal(MoveToPoseGoal(target=cp((1000, 600, 800, 0, 45, 0)),
                                             move_type=MoveToPoseGoal.LIN),
                              feedback_cb=lambda fb: fb.phase == "moving" and moving.set())
        self.assertTrue(moving.wait(10.0))
        os.kill(pid, signal.SIGSTOP)
        stopped = rospy.get_time()
        try:
            self.status.wait_for(lambda m: False, 1.5)            # frozen (the bus process is not)
        finally:
            os.kill(pid, signal.SIGCONT)
        # the first status the node made after the resume (by its stamp: messages it had queued
        # before the stop are delivered after the resume too, and are not what this is about)
        first = self.status.wait_for(lambda m: m.header.stamp.to_sec() > stopped + 0.05, 5.0)
        self.assertIsNotNone(first)
        self.assertEqual(first.motion_possible.val, TriState.FALSE)
        self.assertEqual(first.in_error.val, TriState.TRUE)
        # the bus runs in a process of its own, which the freeze does not reach: it kept the card fed
        # (the node was silent for less than bus_node_timeout), so the link held and the move ran
        # to its end -- the driver of one process lost the link here and the goal was aborted
        self.assertTrue(self.client.wait_for_result(rospy.Duration(10.0)))
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_result().reason)
        self.wait_motion_possible(10.0)

    def test_13_the_default_sim_port_is_this_launchs_own_locked_link(self):
        """driver.test leaves sim_port at its default (auto): both nodes found
        <ROS log dir>/vr006l_virtual_g2_<master port>, and the controller holds it against a second one."""
        link = auto_pty_link()
        port = rosgraph.get_master_uri().rstrip("/").rsplit(":", 1)[-1]
        self.assertTrue(link.endswith("vr006l_virtual_g2_" + port), link)
        self.assertTrue(os.path.islink(link), link)
        self.assertEqual(os.path.realpath(link), os.path.realpath(rospy.get_param("/virtual_controller/device_path")))
        with open(link + ".lock") as f:
            holder = int(f.read())
        self.assertNotEqual(holder, os.getpid())
        with self.assertRaises(SimDeviceError) as ctx:
            VirtualController(pty_link=link)
        self.assertIn("in use by the live process %d" % holder, str(ctx.exception))
        self.assertEqual(os.path.realpath(link), os.path.realpath(rospy.get_param("/virtual_controller/device_path")))
        self.wait_motion_possible()                       # the driver's link is untouched

    def test_14_joint_trajectory_action_runs_a_30_point_trajectory(self):
        """issue 16: an actionlib client of joint_trajectory_action, as MoveIt's controller manager
        uses it: SUCCESSFUL, joint_states within the path tolerance throughout, each target once."""
        self.wait_motion_possible()
        state, result = self.move(MoveToPoseGoal.PTP, HOME)         # a known start, whatever ran before
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.reason)
        before = len(self.entries())
        q0 = list(self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position)
        points, times = [], []
        for k in range(1, 31):
            f = k / 30.0
            points.append([q0[0] + 0.6 * f, q0[1] + 0.25 * math.sin(math.pi * f), q0[2], q0[3],
                           q0[4] + 0.2 * f, q0[5]])
            times.append(0.12 * k)
        # v1 sends whole mm / degree Cartesian targets, solved again by the controller's IK: the
        # wrist joints can end a few degrees from the plan (v2 carries the joints themselves)
        tol = math.radians(5.0)
        start = len(self.joints.messages)
        state, result = self.follow(self.trajectory_goal(points, times, tol=tol))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.error_string)
        self.assertEqual(result.error_code, FollowJointTrajectoryResult.SUCCESSFUL)
        self.assertIn("planned", result.error_string)                 # how much slower, in words
        self.check_on_path(points, times, q0, start, tol)
        entries = self.entries()[before:]
        targets = [tuple(e["target"]) for e in entries]
        self.assertEqual(len(targets), len(set(targets)), "a target executed twice")
        self.assertTrue(all(e["outcome"] == "executed" for e in entries), entries)
        # the first joint_states sample taken after the result (the last one may predate the arrival:
        # one per new record, at most joint_states_rate)
        final = self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position
        self.assertLessEqual(max(abs(a - b) for a, b in zip(final, points[-1])), tol)
        # RViz: the planned and the executed TCP path on ~markers, both published before the result.
        # The plan is sampled every 0.05 rad (dozens of points); the executed path has a point per
        # controller record the action's loop saw, at most joint_states_rate (20 Hz) while v1 runs
        # the thinned plan in about 0.5 s: about 10 points idle, fewer under load (it asked for
        # more than 10 and failed then) -- so at least the two ends of a motion
        def line(ns, least):
            def shows(m):
                return any(k.ns == ns and len(k.points) >= least for k in m.markers)
            msg = self.markers.wait_for(shows, 5.0)
            self.assertIsNotNone(msg, "no %s marker with %d points or more" % (ns, least))
            return [k for k in msg.markers if k.ns == ns][0].points
        line("trajectory_plan", 10)
        executed = line("trajectory_executed", 2)
        span = math.dist((executed[0].x, executed[0].y, executed[0].z), (executed[-1].x, executed[-1].y, executed[-1].z))
        self.assertGreater(span, 0.01, "the executed path does not move: %s" % executed)

    def test_15_joint_trajectory_action_refusals_send_nothing(self):
        self.check_trajectory_refusals()

if __name__ == "__main__":
    rostest.rosrun(PKG, "driver", DriverTest)
