#!/usr/bin/python3
"""rostest of collision-aware planning (test/planning.test): the driver with the example cell (table,
pillar, shelf) and protocol v3 against the virtual controller. A pose behind the pillar: the straight
PTP through move_to_pose is refused naming the link and the pillar, nothing sent; the plan action
plans and previews it (nothing sent; ~plan_markers shows it), the planned trajectory sent to
joint_trajectory_action as MoveIt would runs SUCCESSFUL with every joint_states sample free of the
cell (a CollisionChecker of the same URDF and scene, no padding); a box added on the next plan's path
through ~scene/add makes the plan after it go around the box, and that one runs through the plan
action's own execution. Waits are on messages with deadlines."""
from __future__ import annotations

import math
import os
import re
import subprocess
import threading
import time
import unittest

import actionlib
import rospkg
import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Pose
from visualization_msgs.msg import MarkerArray

from driver_check import DriverTestBase, Recorder, cp, plan_as_sampled, top_tcp_speed
from vr_driver.kinematics.collision import CollisionChecker
from vr_driver.kinematics.deps import missing_dependencies
from vr_driver.kinematics.scene import SceneObject, load_scene
from vr_driver.msg import (FollowJointTrajectoryGoal, FollowJointTrajectoryResult, MoveToPoseGoal, PlanAction,
                           PlanFeedback, PlanGoal, PlanResult, SceneObject as SceneObjectMsg, TriState)
from vr_driver.poses import ControllerPose
from vr_driver.srv import AddSceneObject, RemoveSceneObject

#: behind the pillar (45 deg left, 0.88 m out), at home's height and tool tilt: the straight PTP from
#: home sweeps link_4 through the pillar (160 mm deep); a plan lifts the forearm over it
BEHIND = (500, 866, 725, 0, 45, 60)
#: the box put on the path of the plan back home [m]
BOX = 0.15


class PlanningTest(DriverTestBase):
    @classmethod
    def setUpClass(cls):
        # without the planning libraries the driver refuses the cell (pinocchio, coal) or serves no
        # plan action (OMPL, TOPP-RA): skip with the reason, as the unit tests do
        missing = missing_dependencies()
        if missing:
            raise unittest.SkipTest("; ".join(reason for _, reason in missing))
        super().setUpClass()
        cls.plan_client = actionlib.ActionClient("/plan", PlanAction)
        assert cls.plan_client.wait_for_server(rospy.Duration(20.0)), "the plan action is not served"
        cls.plan_markers = Recorder("/interface/plan_markers", MarkerArray)
        rospy.wait_for_service("/interface/scene/add", 20.0)
        cls.scene_add = rospy.ServiceProxy("/interface/scene/add", AddSceneObject)
        cls.scene_remove = rospy.ServiceProxy("/interface/scene/remove", RemoveSceneObject)
        # the test's own judge: the same URDF (robot_description) and cell, the true shapes (no padding)
        srdf = os.path.join(rospkg.RosPack().get_path("panasonic_vr006l_moveit_config"), "config",
                            "panasonic_vr006l.srdf")
        with open(srdf) as f:
            srdf_xml = f.read()
        cls.cell = load_scene(rospy.get_param("/interface/scene"))
        cls.checker = CollisionChecker.from_urdf(rospy.get_param("/robot_description"), srdf_xml, padding=0.0,
                                                 scene=cls.cell)

    # -------------------------------------------------------------------- helpers
    def plan(self, goal, timeout=60.0):
        """(state, result, feedback phases seen) of one plan goal."""
        done = threading.Event()
        phases = []

        def transition(handle):
            if handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()

        def feedback(_handle, fb):
            if not phases or phases[-1] != fb.phase:
                phases.append(fb.phase)
        handle = self.plan_client.send_goal(goal, transition_cb=transition, feedback_cb=feedback)
        self.assertTrue(done.wait(timeout), "no result from the plan action")
        return handle.get_goal_status(), handle.get_result(), phases

    # the goals of these tests ask for the full speed: the driver's default (0.1) would make every run
    # ten times longer; test_07 checks the default
    def pose_goal(self, pose, preview_only):
        return PlanGoal(goal_type=PlanGoal.POSE, pose=cp(pose), preview_only=preview_only,
                        allowed_planning_time=5.0, velocity_scaling=1.0)

    def named_goal(self, name, preview_only):
        return PlanGoal(goal_type=PlanGoal.NAMED, named_state=name, preview_only=preview_only,
                        allowed_planning_time=5.0, velocity_scaling=1.0)

    def at_home(self):
        """The arm at home from wherever an earlier test left it: through the plan action (the cell's
        way home; the base class's straight PTP is refused from behind the pillar, so one failed
        test made every later one fail); then the base class's PTP there, which also waits for motion
        to be possible and returns the joints."""
        self.wait_motion_possible()
        here = tuple(self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position)
        home = self.kin.named_states["home"]
        if max(abs(a - b) for a, b in zip(here, home)) > 1e-3:
            state, result, _ = self.plan(self.named_goal("home", preview_only=False))
            self.assertEqual(state, GoalStatus.SUCCEEDED, result.error_string)
        return super().at_home()

    @staticmethod
    def points(result):
        return [tuple(p.positions) for p in result.trajectory.points]

    def colliding(self, checker, samples):
        return [k for k, q in enumerate(samples) if checker.in_collision(q)]

    def samples_since(self, start):
        with self.joints.cond:
            return [tuple(m.position) for m in self.joints.messages[start:]]

    def assert_free_run(self, checker, start, duration):
        """Every joint_states sample from message ``start`` on is free of ``checker``'s scene; enough of
        them were seen to cover the motion."""
        seen = self.samples_since(start)
        self.assertGreaterEqual(len(seen), max(5, int(0.5 * duration * 20.0)), "too few joint_states samples")
        bad = [(k, [str(c) for c in checker.contacts(q)]) for k, q in enumerate(seen) if checker.in_collision(q)]
        self.assertEqual(bad, [], "joint_states samples in collision")
        return min(checker.min_distance(q) for q in seen)

    # -------------------------------------------------------------------- tests (in name order)
    def test_01_the_straight_ptp_behind_the_pillar_is_refused_naming_link_and_object(self):
        self.at_home()
        before = len(self.entries())
        state, result = self.move(MoveToPoseGoal.PTP, BEHIND)
        self.assertEqual(state, GoalStatus.ABORTED, result.reason)
        self.assertIn("pillar", result.reason)
        self.assertRegex(result.reason, r"link_[1-6]")
        self.status.wait_for(lambda m: False, 0.5)
        self.assertEqual(len(self.entries()), before, "the refused PTP reached the controller")

    def test_02_planned_previewed_and_executed_successful_through_joint_trajectory_action(self):
        q0 = tuple(self.at_home())
        before = len(self.entries())
        t0 = time.monotonic()
        state, result, phases = self.plan(self.pose_goal(BEHIND, preview_only=True))
        self.assertEqual(state, GoalStatus.SUCCEEDED, result.error_string)
        self.assertEqual(result.error_code, PlanResult.SUCCESS, result.error_string)
        self.assertTrue(result.error_string.startswith("preview only (nothing sent): planned with RRTConnect"),
                        result.error_string)
        # the speed it will run at, said before it runs: the scaling asked for, the peaks within it
        self.assertEqual(result.velocity_scaling, 1.0)
        self.assertRegex(result.error_string, r"velocity scaling 1\b.*at its fastest the TCP moves [0-9]+ mm/s, "
                                              r"joint_[1-6] [0-9.]+ deg/s \([0-9]+ % of its limit\)")
        self.assertGreater(result.peak_tcp_speed, 0.0)
        self.assertLessEqual(result.peak_joint_fraction, 1.0 + 1e-6)
        # planning, then previewing (a preview-only goal ends right after its last feedback: feedback and
        # result travel on two topics, and actionlib drops feedback that arrives after the result --
        # seen under load; test_03's executed plan shows all three phases)
        self.assertEqual(phases, [PlanFeedback.PHASE_PLANNING, PlanFeedback.PHASE_PREVIEWING][:len(phases)])
        self.assertGreaterEqual(len(phases), 1)
        points = self.points(result)
        self.assertGreater(len(points), 10)
        self.assertEqual(list(result.trajectory.joint_names), ["joint_%d" % i for i in range(1, 7)])
        self.assertAlmostEqual(result.duration, result.trajectory.points[-1].time_from_start.to_sec(), places=6)
        self.assertGreater(result.planning_time, 0.0)
        self.assertLess(max(abs(a - b) for a, b in zip(points[0], q0)), 0.01)
        end = self.kin.fk_pose(points[-1])
        dp, da = end.distance_to(ControllerPose(*BEHIND))
        self.assertLess(dp, 0.1)
        self.assertLess(da, 0.01)
        # every planned sample free of the cell; the straight joint move there is not
        self.assertEqual(self.colliding(self.checker, points), [])
        straight = [tuple(a + (b - a) * k / 50 for a, b in zip(q0, points[-1])) for k in range(51)]
        self.assertNotEqual(self.colliding(self.checker, straight), [])
        # previewed: the TCP path and the sweep on ~plan_markers, nothing sent
        shown = self.plan_markers.wait_for(lambda m: any(k.ns == "plan_tcp_path" for k in m.markers), 5.0,
                                           after=t0)
        self.assertIsNotNone(shown, "no plan on ~plan_markers")
        path = [k for k in shown.markers if k.ns == "plan_tcp_path"][0]
        self.assertEqual(len(path.points), len(points))
        self.assertAlmostEqual(path.points[-1].x, end.x / 1000.0, places=4)
        self.assertGreaterEqual(len([k for k in shown.markers if k.ns == "plan_sweep"]), 3)
        self.status.wait_for(lambda m: False, 0.3)
        self.assertEqual(len(self.entries()), before, "a preview reached the controller")
        # executed as MoveIt would: the trajectory to joint_trajectory_action
        start = len(self.joints.messages)
        state, fjt = self.follow(FollowJointTrajectoryGoal(trajectory=result.trajectory), 60.0)
        self.assertEqual(state, GoalStatus.SUCCEEDED, fjt.error_string)
        self.assertEqual(fjt.error_code, FollowJointTrajectoryResult.SUCCESSFUL, fjt.error_string)
        self.assertGreater(len(self.entries()), before)
        final = self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position
        self.assertLess(max(abs(a - b) for a, b in zip(final, points[-1])), math.radians(0.5))
        closest = self.assert_free_run(self.checker, start, result.duration)
        rospy.loginfo("planning_check: the executed plan came within %.1f mm of the cell", closest * 1e3)
        # said before it ran (issue 46) is what it did: v3 runs the plan's timing -- the time from its first
        # target to its end and the TCP's top speed (joint_states at their stamps) within 10 %
        # (the plan's time, the hold at the start where the plan's first targets come faster than the
        # bus brings them, what it adds later where it still does, and the bus's three cycles to the arm
        # and back: 0.1-0.5 s at 6-30 cycles/s)
        self.assertGreater(result.run_duration, result.duration)
        fed = re.findall(r"([0-9.]+) s (?:hold at the start|more where it brings later ones)", result.run_words)
        latency = result.run_duration - result.duration - sum(float(v) for v in fed)
        self.assertTrue(0.09 < latency < 0.51, result.run_words)
        self.assertIn("protocol v3 runs the plan's timing", result.run_words)
        self.assertNotIn("does not apply", result.run_words)
        self.assertRegex(fjt.error_string, r"; said before it ran: protocol v3 runs the plan's timing: [0-9.]+ s \(the "
                                           r"plan's %.2f s(, a [0-9.]+ s hold at the start while the bus brings its first targets)?(, "
                                           r"[0-9.]+ s more where it brings later ones slower than the plan passes them)? and "
                                           r"the bus's 3 cycles to the arm and back\), the TCP at most [0-9]+ mm/s$"
                                           % result.duration)
        ran = float(re.search(r"ran ([0-9.]+) x the planned", fjt.error_string).group(1)) * result.duration
        first = float(re.search(r"first target left ([0-9.]+) s after the goal arrived", fjt.error_string).group(1))
        waited = re.search(r"the arm stopped [0-9]+ time\(s\) on the way waiting for its next target: the bus",
                           fjt.error_string)
        if waited is None:
            self.assertAlmostEqual(ran - first, result.run_duration, delta=0.1 * result.run_duration,
                                   msg=fjt.error_string)
        else:
            # KNOWN GAP (issue 46, open): a plan whose stream the bus cannot deliver in time (at
            # 19.2 kbit/s with the island: some short, fast plans) ran 1.1-1.4 x what was said before
            # it ran, and only the result says why. The run must still end within 1.5 x and say so.
            rospy.logwarn("planning_check: the arm waited for the bus: ran %.2f s of the %.2f s said", ran - first,
                          result.run_duration)
            self.assertLess(ran - first, 1.5 * result.run_duration, fjt.error_string)
        with self.joints.cond:
            samples = [(m.header.stamp.to_sec(), tuple(m.position)) for m in self.joints.messages[start:]]
        top = top_tcp_speed(self.kin, samples, 0.05)
        # the TCP's top speed: joint_states sample the run at the bus cycle (a late cycle on a loaded
        # machine: 190 ms, seen in CI), so the top measured is an average over each sample's interval;
        # the run said before it ran is averaged the same way -- the plan at its run_times (the hold,
        # later points shifted where the bus brings them later: one start offset no longer fits the
        # plan's own times, 13-26 deg off on the stepped world, 0.4-1.6 deg at run_times), at the run's
        # stamps, from the start that fits the run best
        self.assertEqual(len(result.run_times), len(points))
        self.assertTrue(0.09 < result.run_duration - result.run_times[-1] < 0.51,       # the bus's 3 cycles
                        (result.run_duration, result.run_times[-1]))
        _, off, planned = plan_as_sampled(result.run_times, points, samples)
        expected = top_tcp_speed(self.kin, planned, 0.05)
        said = "said %.0f mm/s, the run said at the run's stamps %.0f mm/s, ran %.0f mm/s" % (
            result.run_peak_tcp_speed, expected, top)
        rospy.loginfo("planning_check: %s (the run at most %.2f deg from the one said)", said, math.degrees(off))
        self.assertLessEqual(expected, 1.05 * result.run_peak_tcp_speed, said)
        if waited is None:
            self.assertAlmostEqual(top, expected, delta=0.1 * expected, msg=said)
        else:
            self.assertLess(top, 1.1 * result.run_peak_tcp_speed, said)

    def test_03_a_box_on_the_path_makes_the_next_plan_go_around_it(self):
        here = tuple(self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position)
        self.assertEqual(self.colliding(self.checker, [here]), [])
        state, first, _ = self.plan(self.named_goal("home", preview_only=True))
        self.assertEqual(first.error_code, PlanResult.SUCCESS, first.error_string)
        old = self.points(first)
        # a box on that path: at the TCP of a sample near its middle, clear of its start and its end
        n = len(old)
        box = None
        # (the plan is a sampling planner's: try the samples from the middle outwards, then a smaller box)
        candidates = [(size, k) for size in (BOX, 0.6 * BOX)
                      for k in sorted(range(n // 6, 5 * n // 6 + 1), key=lambda i: abs(i - n // 2))]
        for size, k in candidates:
            x, y, z = (float(v) for v in self.kin.fk(old[k])[:3, 3])
            candidate = SceneObject("crate", "box", (size, size, size), (x, y, z))
            judge = self.checker.copy()
            scene = self.cell.copy()
            scene.add(candidate)
            judge.set_scene(scene)
            judge.set_padding(0.05)
            if not judge.in_collision(old[0]) and not judge.in_collision(old[-1]):
                box = candidate
                break
        self.assertIsNotNone(box, "no place for the box on the path")
        msg = SceneObjectMsg(name=box.name, shape=SceneObjectMsg.BOX, dimensions=list(box.size),
                             pose=Pose())
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = box.position
        msg.pose.orientation.w = 1.0
        response = self.scene_add(object=msg, replace=False)
        self.assertTrue(response.success, response.message)
        try:
            with_box = self.checker.copy()
            scene = self.cell.copy()
            scene.add(box)
            with_box.set_scene(scene)
            self.assertNotEqual(self.colliding(with_box, old), [], "the old plan should pass through the box")
            # the next plan goes around it
            state, second, _ = self.plan(self.named_goal("home", preview_only=True))
            self.assertEqual(second.error_code, PlanResult.SUCCESS, second.error_string)
            new = self.points(second)
            self.assertEqual(self.colliding(with_box, new), [])
            self.assertLess(max(abs(a - b) for a, b in zip(new[0], here)), 0.01)
            self.assertNotEqual(new, old)
            # and one runs through the plan action's own execution (joint_trajectory_action inside)
            before = len(self.entries())
            start = len(self.joints.messages)
            state, ran, phases = self.plan(self.named_goal("home", preview_only=False))
            self.assertEqual(state, GoalStatus.SUCCEEDED, ran.error_string)
            self.assertEqual(ran.error_code, PlanResult.SUCCESS, ran.error_string)
            self.assertEqual(ran.execution_error_code, FollowJointTrajectoryResult.SUCCESSFUL)
            self.assertIn("; executed: ", ran.error_string)
            self.assertEqual(phases, [PlanFeedback.PHASE_PLANNING, PlanFeedback.PHASE_PREVIEWING,
                                      PlanFeedback.PHASE_EXECUTING])
            self.assertGreater(len(self.entries()), before)
            self.assertEqual(self.colliding(with_box, self.points(ran)), [])
            closest = self.assert_free_run(with_box, start, ran.duration)
            rospy.loginfo("planning_check: around the box, within %.1f mm of the cell", closest * 1e3)
            final = self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position
            home = self.kin.named_states["home"]
            self.assertLess(max(abs(a - b) for a, b in zip(final, home)), math.radians(0.5))
        finally:
            response = self.scene_remove(name=box.name)
            self.assertTrue(response.success, response.message)

    def test_04_a_goal_in_collision_is_refused_naming_link_and_object(self):
        before = len(self.entries())
        state, result, _ = self.plan(self.pose_goal((1100, 0, 200, 0, 90, 0), preview_only=False))
        self.assertEqual(state, GoalStatus.ABORTED)
        self.assertEqual(result.error_code, PlanResult.GOAL_IN_COLLISION, result.error_string)
        self.assertTrue(re.search(r"link_[1-6] with object table", result.error_string), result.error_string)
        self.assertEqual(len(result.trajectory.points), 0)
        self.status.wait_for(lambda m: False, 0.3)
        self.assertEqual(len(self.entries()), before)

    def test_05_the_pose_terminal_plans_around_the_pillar_and_back(self):
        """`pose_terminal --pose ... --type plan --yes` and `--plan home --yes`: the terminal's plan
        through the plan action and joint_trajectory_action, exit 0, the arm where it was sent."""
        self.at_home()
        for argv, where in ((["--pose"] + [str(v) for v in BEHIND] + ["--type", "plan", "--yes",
                                                                     "--velocity-scaling", "1"], BEHIND),
                            (["--plan", "home", "--yes", "--velocity-scaling", "1"], (1120, 0, 725, 0, 45, 0))):
            start = len(self.joints.messages)
            done = subprocess.run(["rosrun", "vr_driver", "pose_terminal"] + argv, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, universal_newlines=True, timeout=60)
            self.assertEqual(done.returncode, 0, done.stdout)
            self.assertRegex(done.stdout, r"Plan: collision-free; duration [0-9.]+ s \([0-9]+ points\), planned in "
                                          r"[0-9]+ ms by RRTConnect")
            self.assertRegex(done.stdout, r"  speed: velocity scaling 1; at its fastest the TCP moves [0-9]+ mm/s, "
                                          r"joint_[1-6] [0-9.]+ deg/s \([0-9]+ % of its limit\)\n(.*\n)*Sent\.")
            self.assertIn("Reached X %g  Y %g  Z %g" % where[:3], done.stdout)
            self.assert_free_run(self.checker, start, 1.0)
        # without --velocity-scaling: the driver's default, said also with --preview (nothing runs)
        done = subprocess.run(["rosrun", "vr_driver", "pose_terminal", "--pose"] + [str(v) for v in BEHIND]
                              + ["--type", "plan", "--preview"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              universal_newlines=True, timeout=60)
        self.assertEqual(done.returncode, 0, done.stdout)
        self.assertRegex(done.stdout, r"  speed: velocity scaling 0.1 \(the driver's default\); at its fastest the TCP "
                                      r"moves [0-9]+ mm/s, joint_[1-6] [0-9.]+ deg/s \(([0-9]|10) % of its limit\)")

    def test_06_cancelling_a_running_plan_stops_the_arm(self):
        """Cancel while the plan runs: joint_trajectory_action stops the arm, the plan goal ends
        cancelled (PREEMPTED) once it is at rest, short of the goal."""
        self.at_home()
        done, running = threading.Event(), threading.Event()
        progress = []

        def transition(handle):
            if handle.get_comm_state() == actionlib.CommState.DONE:
                done.set()

        def feedback(_handle, fb):
            if fb.phase == PlanFeedback.PHASE_EXECUTING:
                progress.append(fb.progress)
                if fb.progress > 0.3:
                    running.set()
        goal = self.pose_goal(BEHIND, preview_only=False)
        goal.velocity_scaling = 0.3                       # slow enough to stop half-way
        handle = self.plan_client.send_goal(goal, transition_cb=transition, feedback_cb=feedback)
        self.assertTrue(running.wait(30.0), "the plan never ran a third of its way: %s" % progress[-3:])
        self.assertFalse(done.is_set(), "the plan ended before the cancel")
        handle.cancel()
        self.assertTrue(done.wait(20.0), "no result after the cancel")
        result = handle.get_result()
        self.assertEqual(handle.get_goal_status(), GoalStatus.PREEMPTED, result.error_string)
        self.assertEqual(result.error_code, PlanResult.PREEMPTED, result.error_string)
        self.assertIn("; stopped: ", result.error_string)
        self.assertTrue(all(b >= a for a, b in zip(progress, progress[1:])), progress)
        # at rest, short of the goal
        first = self.joints.wait_for(lambda m: True, 2.0, after=time.monotonic()).position
        self.status.wait_for(lambda m: False, 0.5)
        later = self.joints.last().position
        self.assertLess(max(abs(a - b) for a, b in zip(first, later)), 1e-3)
        self.assertGreater(self.kin.fk_pose(later).distance_to(ControllerPose(*BEHIND))[0], 50.0)

    def test_07_under_the_emergency_stop_a_plan_is_shown_but_not_run(self):
        """E-stop: a preview still plans (from the joints the driver reports); executing is refused by
        joint_trajectory_action in words, nothing reaches the controller; released, it runs."""
        self.wait_motion_possible()
        before = len(self.entries())
        self.assertTrue(self.set_estop(True).success)
        try:
            self.assertIsNotNone(self.status.wait_for(lambda m: m.e_stopped.val == TriState.TRUE, 2.0,
                                                      after=time.monotonic()), "robot_status.e_stopped never TRUE")
            # a joint goal clear of the wrist singularity (the SRDF's zero has joint_5 = 0: with v3 the
            # controller may take another wrist there, and the driver refuses every plan to it)
            goal = PlanGoal(goal_type=PlanGoal.JOINTS, joint_names=["joint_%d" % i for i in range(1, 7)],
                            positions=[0.3, 0.5, -0.2, 0.0, 0.5, 0.0], allowed_planning_time=5.0, preview_only=True)
            state, result, _ = self.plan(goal)
            self.assertEqual(result.error_code, PlanResult.SUCCESS, result.error_string)
            # no velocity_scaling asked for: the driver's default, 0.1 of the joint speed limits, said
            # with the peak speeds (the TCP's from the trajectory's joints and our FK)
            self.assertEqual(result.velocity_scaling, 0.1)
            self.assertIn("velocity scaling 0.1", result.error_string)
            self.assertRegex(result.peak_joint, r"\Ajoint_[1-6]\Z")
            self.assertGreater(result.peak_joint_fraction, 0.02)
            self.assertLessEqual(result.peak_joint_fraction, 0.1 + 1e-6)
            points = self.points(result)
            steps = zip(points, points[1:], result.trajectory.points, result.trajectory.points[1:])
            chord = max(self.kin.fk_pose(b).distance_to(self.kin.fk_pose(a))[0]
                        / (pb.time_from_start - pa.time_from_start).to_sec() for a, b, pa, pb in steps)
            self.assertGreater(result.peak_tcp_speed, 0.95 * chord)      # a chord's mean speed: at most the peak
            self.assertLess(result.peak_tcp_speed, 1.5 * chord)
            goal.preview_only = False
            state, result, phases = self.plan(goal)
            self.assertEqual(state, GoalStatus.ABORTED, result.error_string)
            self.assertEqual(result.error_code, PlanResult.CONTROL_FAILED, result.error_string)
            self.assertIn("refused by joint_trajectory_action: motion is not possible", result.error_string)
            self.assertIn("emergency stop", result.error_string)
            self.assertEqual(result.execution_error_code, FollowJointTrajectoryResult.INVALID_GOAL)
            self.status.wait_for(lambda m: False, 0.3)
            self.assertEqual(len(self.entries()), before)
        finally:
            self.assertTrue(self.set_estop(False).success)
            self.assertTrue(self.set_drives(True).success)
        self.wait_motion_possible()
        state, result, _ = self.plan(self.named_goal("home", preview_only=False))
        self.assertEqual(result.error_code, PlanResult.SUCCESS, result.error_string)


if __name__ == "__main__":
    rostest.rosrun("vr_driver", "planning", PlanningTest)
