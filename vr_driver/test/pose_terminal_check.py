#!/usr/bin/python3
"""rostest of the pose terminal, driven as a person would drive it: `rosrun vr_driver pose_terminal`
in a pseudo-terminal (pexpect), against the driver and the virtual controller of
launch/driver.launch (a real pty carrying real PROFIBUS telegrams).

Run by test/driver.test, before driver_check.py, against the same launched stack. What the
controller did is read from its execution log on /virtual_controller/executed (one JSON object per
handled target), so "nothing was sent" is checked on the controller's side. Every wait is on a prompt, an output or a message, with a
deadline (pexpect timeouts); nothing sleeps to synchronise."""
from __future__ import annotations

import io
import json
import os
import subprocess
import time
import unittest

import pexpect
import rospy
from vr_driver.ros.support import init_node
import rostest
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool

from vr_driver.kinematics.solver import Kinematics
from vr_driver.msg import RobotStatus, TriState
from vr_driver.poses import ControllerPose

from driver_check import Recorder, top_tcp_speed

PKG = "vr_driver"
FIRST_PROMPT = r"X \[mm, 100\.\.1400\] \([-0-9.]+\): "     # the first prompt of every entry
CONFIRM = r"Send this (PTP|LIN|CIRC) move to the robot\? \[y/N\]: "
PROGRESS = r"(sending|moving) +distance to go +[0-9.]+ mm"
TIMEOUT = 30


class PoseTerminalTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_node("pose_terminal_check")
        cls.executed = Recorder("/virtual_controller/executed", String)
        cls.status = Recorder("/robot_status", RobotStatus)
        cls.true = Recorder("/virtual_controller/true_joints", JointState)
        cls.kin = Kinematics.default()
        rospy.wait_for_service("/virtual_controller/set_estop", 30.0)
        cls.set_estop = rospy.ServiceProxy("/virtual_controller/set_estop", SetBool)
        cls.set_drives = rospy.ServiceProxy("/virtual_controller/set_drives_powered", SetBool)

    def setUp(self):
        self.children = []
        # the virtual controller stamps its entries with the system's monotonic clock (shared by
        # every process): an entry of an earlier test that arrives late is told apart by it
        self.t0 = time.monotonic()

    def tearDown(self):
        for child in self.children:
            if child.isalive():
                child.terminate(force=True)

    # -------------------------------------------------------------- helpers
    def entries(self):
        with self.executed.cond:
            return [json.loads(m.data) for m in self.executed.messages]

    def new_entries(self, before: int, n: int, timeout: float = 15.0):
        """The entries of targets this test started after entry number ``before``, once there are
        at least ``n`` (an entry is on its way a little after the terminal says "Reached")."""
        def mine():
            return [e for e in self.entries()[before:] if e["start_time"] >= self.t0]
        end = time.monotonic() + timeout
        with self.executed.cond:
            while len(mine()) < n:
                left = end - time.monotonic()
                self.assertGreater(left, 0.0, "expected %d new executed entries, have %d: %s"
                                   % (n, len(mine()), self.entries()[before:]))
                self.executed.cond.wait(left)
        return mine()

    def wait_motion_possible(self, timeout=15.0):
        start = len(self.status.messages)
        msg = self.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE, timeout, start=start)
        self.assertIsNotNone(msg, "motion_possible never became TRUE")

    def spawn(self, *args, ready=True):
        """The terminal in a pseudo-terminal; waits for its first prompt when ``ready``."""
        child = pexpect.spawn("rosrun", ["vr_driver", "pose_terminal"] + list(args), encoding="utf-8",
                              timeout=TIMEOUT, dimensions=(50, 160), env=dict(os.environ))
        child.logfile_read = io.StringIO()
        self.children.append(child)
        if ready:
            self.expect(child, r"Controller ready: motion possible")
            self.expect(child, FIRST_PROMPT)
        return child

    def expect(self, child, pattern, timeout=TIMEOUT):
        """child.expect(pattern), failing with the terminal's output so far."""
        try:
            return child.expect(pattern, timeout=timeout)
        except (pexpect.TIMEOUT, pexpect.EOF) as exc:
            self.fail("waited for %r; the terminal showed:\n%s\n(%s)"
                      % (pattern, child.logfile_read.getvalue()[-3000:], type(exc).__name__))

    def move(self, child, line, words=r"Reached"):
        """Type a pose line at the first prompt, confirm, wait for the outcome, then the prompt."""
        child.sendline(line)
        self.expect(child, CONFIRM)
        child.sendline("y")
        self.expect(child, words)
        text = child.before + child.after
        self.expect(child, FIRST_PROMPT)
        return text + child.before

    def quit(self, child):
        child.sendline("quit")
        self.expect(child, r"Bye\.")
        self.expect(child, pexpect.EOF)
        child.close()
        self.assertEqual(child.exitstatus, 0, child.logfile_read.getvalue()[-2000:])

    # -------------------------------------------------------------- tests (run in name order)
    def test_01_defaults_accepted_with_enter(self):
        self.wait_motion_possible()
        before = len(self.entries())
        t = self.spawn()
        t.sendline("")                                   # X: keep 1120
        self.expect(t, r"Y \[mm, -900\.\.900\] \(0\): ")
        t.sendline("120")
        for prompt in (r"Z \[mm, 0\.\.1400\] \(725\): ", r"Rx \[deg, -180\.\.180\] \(0\): ",
                       r"Ry \[deg, -180\.\.180\] \(45\): ", r"Rz \[deg, -180\.\.180\] \(0\): ",
                       r"Move type \[ptp, lin, circ\] \(ptp\): "):
            self.expect(t, prompt)
            t.sendline("")
        self.expect(t, r"Preview: reachable; estimated duration [0-9.]+ s")
        self.expect(t, r"joint target \[deg\]: J1 [-0-9.]+  J2 [-0-9.]+  J3 [-0-9.]+  J4 [-0-9.]+  J5 [-0-9.]+  "
                       r"J6 [-0-9.]+")
        self.expect(t, CONFIRM)
        t.sendline("y")
        self.expect(t, r"Reached X 1120  Y 120  Z 725  Rx 0  Ry 45  Rz 0 \(0\.0 mm")
        self.expect(t, r"X \[mm, 100\.\.1400\] \(1120\): ")
        self.quit(t)
        (entry,) = self.new_entries(before, 1)
        self.assertEqual((entry["move_type"], entry["target"], entry["outcome"]),
                         ("PTP", [1120, 120, 725, 0, 45, 0], "executed"))

    def test_02_bad_values_are_re_prompted_with_the_reason(self):
        self.wait_motion_possible()
        before = len(self.entries())
        t = self.spawn()
        steps = [  # (typed, the reason that must follow, the prompt asked again)
            ("abc", r"X: 'abc' is not a number", FIRST_PROMPT),
            ("1500", r"X = 1500 mm is above the workspace: allowed 100\.\.1400 mm", FIRST_PROMPT),
            ("1000", None, r"Y \[mm, -900\.\.900\] \(0\): "),
            ("nan", r"Y: 'nan' is not a position: a finite number in -900\.\.900 mm is needed", r"Y \[mm"),
            ("-950", r"Y = -950 mm is below the workspace: allowed -900\.\.900 mm", r"Y \[mm"),
            ("0", None, r"Z \[mm, 0\.\.1400\] \(725\): "),
            ("inf", r"Z: 'inf' is not a position", r"Z \[mm"),
            ("1e999", r"Z: inf is not a position", r"Z \[mm"),
            ("12,5", r"Z: '12,5' is not a number", r"Z \[mm"),
            ("800", None, r"Rx \[deg"),
            ("inf", r"Rx: 'inf' is not an angle: a finite number in -180\.\.180 deg is needed", r"Rx \[deg"),
            ("", None, r"Ry \[deg"),
            ("200", r"Ry = 200 deg is above the workspace: allowed -180\.\.180 deg", r"Ry \[deg"),
            ("", None, r"Rz \[deg"),
            ("", None, r"Move type"),
            ("spline", r"move type: 'spline' is not one of ptp, lin, circ", r"Move type"),
            ("lin", None, CONFIRM),
            ("n", r"Not sent\.", FIRST_PROMPT),
        ]
        for typed, reason, prompt in steps:
            t.sendline(typed)
            if reason is not None:
                self.expect(t, reason)
            self.expect(t, prompt)
        # the declined move never reached the controller: the next one is the only new entry
        self.move(t, "1000 0 800 0 45 0 lin")
        self.quit(t)
        self.assertEqual([(e["move_type"], e["target"]) for e in self.new_entries(before, 1)],
                         [("LIN", [1000, 0, 800, 0, 45, 0])])

    def test_03_unreachable_and_invalid_poses_are_refused_before_anything_is_sent(self):
        self.wait_motion_possible()
        before = len(self.entries())
        t = self.spawn()
        t.sendline("1400 0 1400 0 0 0 ptp")                      # inside the box, out of reach
        self.expect(t, r"Refused, nothing was sent: .*unreachable")
        self.expect(t, FIRST_PROMPT)
        self.assertNotIn("[y/N]", t.before)
        self.assertNotIn("(1400)", t.after)                     # a refused entry is not the next default
        t.sendline("1000 150 800 0 45 0 circ")
        self.expect(t, r"a circular move needs a via point")
        self.expect(t, FIRST_PROMPT)
        t.sendline("1000 0 1500 0 45 0 lin")
        self.expect(t, r"Z = 1500 mm is above the workspace")
        self.expect(t, FIRST_PROMPT)
        self.move(t, "1050 0 750 0 45 0 ptp")
        self.quit(t)
        self.assertEqual([e["target"] for e in self.new_entries(before, 1)], [[1050, 0, 750, 0, 45, 0]])

    def test_04_ptp_lin_and_circ_moves_reach_their_targets_with_progress_shown(self):
        self.wait_motion_possible()
        before = len(self.entries())
        t = self.spawn()
        text = self.move(t, "1000 200 800 0 45 0 ptp", r"Reached X 1000  Y 200  Z 800  Rx 0  Ry 45  Rz 0")
        self.assertRegex(text, PROGRESS)
        # a linear move entered field by field (the last target is the default)
        t.sendline("")
        self.expect(t, r"Y \[mm, -900\.\.900\] \(200\): ")
        t.sendline("-150")
        for _ in range(4):
            self.expect(t, r"(Z|Rx|Ry|Rz) \[")
            t.sendline("")
        self.expect(t, r"Move type \[ptp, lin, circ\] \(ptp\): ")
        t.sendline("lin")
        self.expect(t, CONFIRM)
        t.sendline("y")
        self.expect(t, r"moving +distance to go +[0-9.]+ mm")
        self.expect(t, r"Reached X 1000  Y -150  Z 800  Rx 0  Ry 45  Rz 0")
        self.expect(t, FIRST_PROMPT)
        text = self.move(t, "1000 150 800 0 45 0 circ via 1100 0 800",
                         r"Reached X 1000  Y 150  Z 800  Rx 0  Ry 45  Rz 0")
        self.assertRegex(text, r"moving +distance to go +[0-9.]+ mm")
        self.quit(t)
        self.assertEqual([(e["move_type"], e["target"], e["outcome"]) for e in self.new_entries(before, 4)], [
            ("PTP", [1000, 200, 800, 0, 45, 0], "executed"),
            ("LIN", [1000, -150, 800, 0, 45, 0], "executed"),
            ("CIRC_VIA", [1100, 0, 800, 0, 45, 0], "via_stored"),
            ("CIRC_END", [1000, 150, 800, 0, 45, 0], "executed"),
        ])

    def test_05_ctrl_c_during_a_move_stops_the_arm_and_returns_to_the_prompt(self):
        self.wait_motion_possible()
        t = self.spawn()
        first = len(self.entries())
        self.move(t, "1000 -600 800 0 45 0 ptp")
        # the controller's entry for that move may still be on its way when the terminal already
        # says "Reached": wait for it, or it is counted as the stopped move's (a loaded run did)
        self.new_entries(first, 1)
        before = first + 1
        t.sendline("1000 650 800 0 45 0 lin")                    # ~1250 mm at 0.25 m/s: about 5 s
        self.expect(t, CONFIRM)
        t.sendline("y")
        self.expect(t, r"moving +distance to go +[0-9.]+ mm")
        t.sendintr()
        self.expect(t, r"Ctrl-C: stopping the arm")
        self.expect(t, r"Stopped at X [-0-9.]+  Y ([-0-9.]+) ")
        stopped_y = float(t.match.group(1))
        self.expect(t, FIRST_PROMPT)
        (entry,) = self.new_entries(before, 1)
        self.assertEqual(entry["outcome"], "rejected")
        self.assertIn("stop", entry["reason"])
        self.assertGreater(ControllerPose(*entry["final_pose"]).distance_to(
            ControllerPose(1000, 650, 800, 0, 45, 0))[0], 20.0)
        self.assertLessEqual(abs(stopped_y - entry["final_pose"][1]), 0.5)      # the rest pose
        start = len(self.status.messages)
        self.assertIsNotNone(self.status.wait_for(lambda m: m.in_motion.val == TriState.FALSE, 5.0, start=start))
        t.sendline("status")                                     # still usable: the driver is fine
        self.expect(t, r"motion possible: yes")
        self.expect(t, FIRST_PROMPT)
        t.sendline("history")                                    # history keeps the rest pose too
        self.expect(t, r"stopped at X [-0-9.]+  Y ([-0-9.]+) .*\(at rest\)")
        self.assertLessEqual(abs(float(t.match.group(1)) - entry["final_pose"][1]), 0.5)
        self.expect(t, FIRST_PROMPT)
        self.quit(t)

    def test_06_ctrl_c_and_cancel_abandon_an_entry_quit_and_ctrl_d_leave(self):
        self.wait_motion_possible()
        before = len(self.entries())
        t = self.spawn()
        t.sendline("help")
        for word in ("home", "stop", "status", "history", "help", "cancel", "quit"):
            self.expect(t, r"\n  %s " % word)
        self.expect(t, FIRST_PROMPT)
        t.sendline("1000")                                       # half an entry, then Ctrl-C
        self.expect(t, r"Y \[mm")
        t.sendintr()
        self.expect(t, r"Entry abandoned")
        self.expect(t, FIRST_PROMPT)
        t.sendline("1000")                                       # half an entry, then 'cancel'
        self.expect(t, r"Y \[mm")
        t.sendline("200")
        self.expect(t, r"Z \[mm")
        t.sendline("cancel")
        self.expect(t, r"Entry abandoned\.")
        self.expect(t, FIRST_PROMPT)
        t.sendintr()                                             # Ctrl-C at the first prompt: still here
        self.expect(t, r"Entry abandoned \(Ctrl-C\)")
        self.expect(t, FIRST_PROMPT)
        t.sendline("1000")
        self.expect(t, r"Y \[mm")
        t.sendline("quit")                                       # quit inside an entry
        self.expect(t, r"Bye\.")
        self.expect(t, pexpect.EOF)
        t.close()
        self.assertEqual(t.exitstatus, 0)
        self.assertEqual(self.entries()[before:], [])            # nothing abandoned was sent
        t = self.spawn()
        t.sendline("1000")
        self.expect(t, r"Y \[mm")
        t.sendeof()
        self.expect(t, r"Bye\.")
        self.expect(t, pexpect.EOF)
        t.close()
        self.assertEqual(t.exitstatus, 0)

    def test_07_history_status_home_and_stop_commands(self):
        self.wait_motion_possible()
        t = self.spawn()
        t.sendline("home")
        self.expect(t, CONFIRM)
        t.sendline("y")
        self.expect(t, r"Reached X 1120  Y 0  Z 725  Rx 0  Ry 45  Rz 0")
        self.expect(t, FIRST_PROMPT)
        t.sendline("1400 0 1400 0 0 0")
        self.expect(t, r"Refused")
        self.expect(t, FIRST_PROMPT)
        t.sendline("history")
        self.expect(t, r"  1  [0-9:]{8}  PTP to X 1120  Y 0  Z 725  Rx 0  Ry 45  Rz 0\s+-> reached")
        self.expect(t, r"  2  [0-9:]{8}  PTP to X 1400  Y 0  Z 1400  Rx 0  Ry 0  Rz 0\s+-> refused: .*unreachable")
        self.expect(t, FIRST_PROMPT)
        t.sendline("status")
        self.expect(t, r"link: +connected")
        self.expect(t, r"pose: +X 1120  Y 0  Z 725  Rx 0  Ry 45  Rz 0")
        self.expect(t, r"joints \[deg\]: +J1 ")
        self.expect(t, FIRST_PROMPT)
        t.sendline("stop")
        self.expect(t, r"Stop sent: stop sent")           # industrial_msgs/StopMotion: SUCCESS
        self.expect(t, FIRST_PROMPT)
        self.quit(t)

    def test_08_motion_not_possible_is_said_in_words_and_nothing_is_sent(self):
        self.wait_motion_possible()
        t = self.spawn()
        before = len(self.entries())
        try:
            self.assertTrue(self.set_estop(True).success)
            start = len(self.status.messages)
            self.assertIsNotNone(self.status.wait_for(lambda m: m.e_stopped.val == TriState.TRUE, 5.0, start=start))
            t.sendline("1000 0 800 0 45 0 lin")
            self.expect(t, r"Not sent: motion is not possible now: the emergency stop is active")
            self.expect(t, FIRST_PROMPT)
            t.sendline("status")
            self.expect(t, r"motion possible: no \(the emergency stop is active")
            self.expect(t, r"e-stop: PRESSED")
            self.expect(t, FIRST_PROMPT)
        finally:
            self.set_estop(False)
            self.set_drives(True)
        self.wait_motion_possible()
        self.move(t, "1000 0 800 0 45 0 lin")
        self.quit(t)
        self.assertEqual([e["target"] for e in self.new_entries(before, 1)], [[1000, 0, 800, 0, 45, 0]])

    def test_09_one_shot_command_line_and_its_exit_codes(self):
        self.wait_motion_possible()
        before = len(self.entries())

        def run(*args, stdin="", env=None):
            e = dict(os.environ)
            e.update(env or {})
            return subprocess.run(["rosrun", "vr_driver", "pose_terminal"] + list(args), input=stdin,
                                  capture_output=True, text=True, timeout=60, env=e)

        res = run("--pose", "1050", "0", "750", "0", "45", "0", "--type", "lin", "--yes")
        self.assertEqual(res.returncode, 0, res.stdout + res.stderr)
        self.assertIn("Reached X 1050  Y 0  Z 750", res.stdout)
        self.assertRegex(res.stdout, PROGRESS)
        res = run("--pose", "1000", "0", "800", "0", "45", "0", "--preview")
        self.assertEqual(res.returncode, 0, res.stdout + res.stderr)
        self.assertIn("Preview: reachable", res.stdout)
        res = run("--pose", "1000", "0", "800", "0", "45", "0", stdin="n\n")
        self.assertEqual(res.returncode, 1, res.stdout + res.stderr)
        self.assertIn("Not sent.", res.stdout)
        res = run("--pose", "1500", "0", "800", "0", "45", "0", "--yes")
        self.assertEqual(res.returncode, 1, res.stdout + res.stderr)
        self.assertIn("X = 1500 mm is above the workspace", res.stdout)
        res = run("--pose", "1400", "0", "1400", "0", "0", "0", "--yes")
        self.assertEqual(res.returncode, 1, res.stdout + res.stderr)
        self.assertIn("unreachable", res.stdout)
        # a usage error through rosrun (every kind of them: test_pose_input.py, in-process)
        res = run("--pose", "1000", "0", "nan", "0", "45", "0", "--yes")
        self.assertEqual(res.returncode, 2, (res.stdout, res.stderr))
        self.assertIn("usage: pose_terminal", res.stderr)
        self.assertIn("Z: 'nan'", res.stderr)
        res = run("--pose", "1000", "0", "800", "0", "45", "0", "--yes", "--wait", "1", "__ns:=/nowhere")
        self.assertEqual(res.returncode, 3, res.stdout + res.stderr)
        self.assertIn("no driver: the action /nowhere/move_to_pose is not served", res.stderr)
        res = run("--pose", "1000", "0", "800", "0", "45", "0", "--yes", "--wait", "1",
                  env={"ROS_MASTER_URI": "http://localhost:9"})
        self.assertEqual(res.returncode, 3, res.stdout + res.stderr)
        self.assertIn("no ROS master at http://localhost:9", res.stderr)
        # only the one confirmed move reached the controller
        self.assertEqual([(e["move_type"], e["target"]) for e in self.new_entries(before, 1)],
                         [("LIN", [1050, 0, 750, 0, 45, 0])])
        self.assertFalse(self.executed.wait_count(before + 2, 0.5))

    def test_10_the_workspace_comes_from_the_driver_parameters(self):
        saved = rospy.get_param("/interface/workspace")
        try:
            rospy.set_param("/interface/workspace/x", [200.0, 1300.0])
            t = self.spawn(ready=False)
            self.expect(t, r"workspace X 200\.\.1300, Y -900\.\.900, Z 0\.\.1400 mm, angles -180\.\.180 deg "
                           r"\(/interface/workspace\)")
            self.expect(t, r"X \[mm, 200\.\.1300\] \(1120\): ")
            t.sendline("1350 0 725 0 45 0")
            self.expect(t, r"X = 1350 mm is above the workspace: allowed 200\.\.1300 mm")
            self.expect(t, r"X \[mm, 200\.\.1300\]")
            self.quit(t)
        finally:
            rospy.set_param("/interface/workspace", saved)

    def test_11_a_plan_on_v1_is_said_to_run_at_the_programs_speed_and_keeps_it(self):
        """Issue 46: ``plan 900 300 900 0 60 0`` at the driver's default velocity scaling (0.1) on v1:
        before it asks to run, the terminal says the scaling does not apply and the robot program's
        speed does (the documented 10 m/min MOVEP, the virtual G2's default), with the time and the
        top speed -- and the run keeps both within 10 % (the controller's execution log, from the
        first target taken to the last done; the arm's true joints, over 0.2 s windows)."""
        self.wait_motion_possible()
        before = len(self.entries())
        with self.true.cond:
            mark = len(self.true.messages)
        t = self.spawn()
        t.sendline("plan 900 300 900 0 60 0")
        self.expect(t, r"the run: velocity scaling 0\.1 \(the driver's default\) does not apply on this protocol: "
                       r"the robot program's speed does \(the TCP at most [0-9]+ mm/s")
        self.expect(t, r"protocol v1 runs (it|its ([0-9]+) targets) at the robot program's own speed, MOVEP 10 m/min "
                       r"\(167 mm/s\), not a plan's timing, and stops at (the target|each): ([0-9.]+) s \(")
        n = int(t.match.group(2) or 1)
        said = float(t.match.group(4))
        self.expect(t, r"the TCP at most ([0-9]+) mm/s")
        top_said = float(t.match.group(1))
        self.expect(t, r"Run this planned motion on the robot\? \[y/N\]: ")
        t.sendline("y")
        self.expect(t, r"Reached", timeout=60)
        self.expect(t, FIRST_PROMPT)
        self.quit(t)
        entries = self.new_entries(before, n)
        self.assertTrue(all(e["outcome"] == "executed" and e["move_type"] == "PTP" for e in entries), entries)
        took = entries[-1]["time"] - entries[0]["start_time"]
        self.assertAlmostEqual(took, said, delta=0.1 * said, msg="said %.2f s, ran %.2f s" % (said, took))
        with self.true.cond:
            samples = [(m.header.stamp.to_sec(), tuple(m.position)) for m in self.true.messages[mark:]]
        top = top_tcp_speed(self.kin, samples, 0.2)
        self.assertAlmostEqual(top, top_said, delta=0.1 * top_said, msg="said %.0f mm/s, ran %.0f mm/s" % (top_said, top))


if __name__ == "__main__":
    rostest.rosrun(PKG, "pose_terminal", PoseTerminalTest)
