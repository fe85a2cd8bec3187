#!/usr/bin/python3
"""rostest (issue 18): the driver on the virtual multi-drop line -- the virtual controller and the
virtual I/O island joined by the line hub, real telegrams over ptys.

- ``set_io gripper_close 1`` while the arm moves -> ``gripper_closed`` reads 1 in io_states and
  through get_io within a bounded time; the move succeeds, no link loss, no stalled cycle;
- every refusal (unknown name, a value that does not fit, an input, a station not in
  Data_Exchange) returns success false with its reason and changes no output byte (the island's
  own output image, its ``~outputs`` topic, and get_io of the output);
- the island killed mid-motion -> its signals offline within link_timeout (+ slack for a loaded
  machine), the move succeeds, robot_status keeps motion_possible TRUE; the island back (respawned)
  -> online, outputs at their safe values (the refused write was never queued);
- the master falls silent (the driver's process stopped with SIGSTOP: killing the `interface` node,
  required in driver.launch, would end this rostest with it; its bus process goes on for
  bus_node_timeout, sends the stop for bus_stop_hold, then closes the port) -> the island's outputs
  at their safe values within its DP watchdog (300 ms, + slack) after that; SIGCONT -> the driver
  takes the island back.
Run by test/driver.test, second of its checks (before anything there may lose the link)."""
from __future__ import annotations

import os
import signal
import threading
import time
import unittest
from xmlrpc.client import ServerProxy

import actionlib
import rosgraph
import rosnode
import rospy
from vr_driver.ros.support import init_node
import rostest
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String

from vr_driver.params import DriverParams
from vr_driver.msg import CartesianPose, IOStates, MoveToPoseAction, MoveToPoseGoal, RobotStatus, TriState
from vr_driver.srv import GetIO, SetIO

from driver_check import Recorder

PKG = "vr_driver"
SLACK = 1.0          # s on top of a time limit: delivery of the topic on a loaded 2-core machine
TARGETS = [(1000, 650, 800, 0, 45, 0), (1000, -650, 800, 0, 45, 0)]


def signals(msg):
    return {s.name: s for s in msg.signals}


def all_online(msg, online=True):
    return bool(msg.signals) and all(s.online == online for s in msg.signals)


def station_status(msg, name):
    for status in msg.status:
        if status.name.endswith("I/O station " + name):
            return status, {kv.key: kv.value for kv in status.values}
    return None


class IoLineTest(unittest.TestCase):
    def setUp(self):
        init_node("io_line_check")
        self.io = Recorder("/io_states", IOStates)
        self.status = Recorder("/robot_status", RobotStatus)
        self.outputs = Recorder("/virtual_io_island/outputs", String)
        self.diag = Recorder("/diagnostics", DiagnosticArray)
        for name in ("/set_io", "/get_io"):
            rospy.wait_for_service(name, 30.0)
        self.set_io = rospy.ServiceProxy("/set_io", SetIO)
        self.get_io = rospy.ServiceProxy("/get_io", GetIO)
        self.client = actionlib.SimpleActionClient("/move_to_pose", MoveToPoseAction)
        self.assertTrue(self.client.wait_for_server(rospy.Duration(30.0)))
        self.link_timeout = rospy.get_param("/interface/link_timeout")
        self.assertIsNotNone(self.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE, 30.0),
                             "the arm never became ready")
        self.assertIsNotNone(self.io.wait_for(all_online, 30.0), "the island never came online")

    def island_outputs(self, pred, timeout, after=0.0):
        return self.outputs.wait_for(lambda m: pred(m.data), timeout, after=after)

    def move(self, k):
        moving = threading.Event()
        self.client.send_goal(MoveToPoseGoal(target=CartesianPose(*TARGETS[k % 2]), move_type=MoveToPoseGoal.LIN),
                              feedback_cb=lambda fb: fb.phase == "moving" and moving.set())
        self.assertTrue(moving.wait(15.0), "the goal never started moving")

    def finish_move(self):
        self.assertTrue(self.client.wait_for_result(rospy.Duration(60.0)))
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_result().reason)

    def link_counters(self):
        msg = self.diag.wait_for(lambda m: any(kv.key == "link stalled cycles" for s in m.status for kv in s.values),
                                 10.0, after=time.monotonic())
        self.assertIsNotNone(msg, "no link diagnostics")
        values = {kv.key: kv.value for s in msg.status for kv in s.values}
        return int(values["link losses"]), int(values["link stalled cycles"])

    def test_io_line(self):
        # ---- the island's diagnostics: online, DP state, no losses
        diag = self.diag.wait_for(lambda m: station_status(m, "io_island") is not None
                                  and station_status(m, "io_island")[1].get("online") == "true", 15.0)
        self.assertIsNotNone(diag, "no /diagnostics status of the island")
        values = station_status(diag, "io_island")[1]
        self.assertEqual((values["DP state"], values["losses"], values["address"]), ("DATA_EXCHANGE", "0", "8"))

        # ---- refusals: the reason, no output byte changed
        self.assertIsNotNone(self.island_outputs(lambda d: d == "00 00 DATA_EXCH", 10.0))
        seen = len(self.outputs.messages)
        for signal_name, value, words in [("gripper_opn", "1", "unknown signal"),
                                          ("gripper_close", "2", "not a bit value"),
                                          ("gripper_close", "", "not a bit value"),
                                          ("gripper_closed", "1", "is an input")]:
            res = self.set_io(signal_name, value)
            self.assertFalse(res.success, (signal_name, value))
            self.assertIn(words, res.message)
        self.assertEqual(self.get_io("gripper_close").value, "0")
        res = self.get_io("no_such_signal")
        self.assertFalse(res.success)
        self.assertIn("unknown signal", res.message)
        self.assertEqual(self.outputs.last().data, "00 00 DATA_EXCH")
        self.assertEqual([m.data for m in self.outputs.messages[seen:]], [], "a refused write changed the outputs")

        # ---- gripper while the arm moves
        self.move(0)
        sent = time.monotonic()
        res = self.set_io("gripper_close", "1")
        self.assertTrue(res.success, res.message)
        closed = self.io.wait_for(lambda m: signals(m)["gripper_closed"].value == "1", 0.3 + 3.0, after=sent)
        self.assertIsNotNone(closed, "gripper_closed never read 1 in io_states")
        self.assertLess(self.io.times[self.io.messages.index(closed)] - sent, 0.3 + SLACK + 0.5)
        self.assertEqual(self.get_io("gripper_closed").value, "1")
        self.assertIsNotNone(self.island_outputs(lambda d: d == "01 00 DATA_EXCH", 5.0))
        self.assertEqual(self.client.get_state(), GoalStatus.ACTIVE, "the move should still run")
        self.finish_move()
        self.assertEqual(self.link_counters(), (0, 0))

        # ---- the island killed mid-motion: offline in link_timeout, the arm keeps going
        ready = self.status.wait_for(lambda m: m.motion_possible.val == TriState.TRUE, 5.0, after=time.monotonic())
        self.assertIsNotNone(ready)
        status_from = len(self.status.messages)
        self.move(1)
        killed = time.monotonic()
        self.assertEqual(rosnode.kill_nodes(["/virtual_io_island"])[0], ["/virtual_io_island"])
        offline = self.io.wait_for(lambda m: all_online(m, False), self.link_timeout + 5.0, after=killed)
        self.assertIsNotNone(offline, "the island's signals never went offline")
        offline_at = self.io.times[self.io.messages.index(offline)]
        self.assertLess(offline_at - killed, self.link_timeout + SLACK)
        self.assertTrue(all(s.value == "" for s in offline.signals), "an old value shown as live")
        res = self.set_io("gripper_close", "1")
        self.assertFalse(res.success)
        self.assertIn("not in Data_Exchange", res.message)
        res = self.get_io("gripper_closed")
        self.assertFalse(res.success)
        self.assertIn("offline", res.message)
        diag = self.diag.wait_for(lambda m: station_status(m, "io_island") is not None
                                  and station_status(m, "io_island")[1].get("online") == "false", 10.0, after=killed)
        self.assertIsNotNone(diag, "diagnostics never showed the island offline")
        self.assertEqual(station_status(diag, "io_island")[1]["outputs safe"], "true")

        # ---- the island back (respawned): online, outputs at their safe values, nothing queued
        back = self.io.wait_for(all_online, 30.0, after=offline_at)
        self.assertIsNotNone(back, "the island never came back online")
        self.assertEqual(signals(back)["gripper_close"].value, "0")
        self.assertEqual(self.get_io("gripper_close").value, "0")
        self.assertEqual(self.island_outputs(lambda d: "DATA_EXCH" in d, 10.0, after=offline_at).data,
                         "00 00 DATA_EXCH")
        self.finish_move()
        statuses = self.status.messages[status_from:]
        self.assertTrue(statuses)
        self.assertTrue(all(m.motion_possible.val == TriState.TRUE for m in statuses),
                        "robot_status lost motion_possible while the island was away")
        self.assertEqual(self.link_counters(), (0, 0))
        diag = self.diag.wait_for(lambda m: station_status(m, "io_island") is not None
                                  and station_status(m, "io_island")[1].get("online") == "true", 10.0,
                                  after=time.monotonic())
        self.assertIsNotNone(diag)
        self.assertGreaterEqual(int(station_status(diag, "io_island")[1]["losses"]), 1)

        # ---- the master falls silent: the island's watchdog puts its outputs to the safe state
        self.assertTrue(self.set_io("gripper_close", "1").success)
        self.assertIsNotNone(self.island_outputs(lambda d: d == "01 00 DATA_EXCH", 5.0))
        uri = rosgraph.Master("/io_line_check").lookupNode("/interface")
        pid = ServerProxy(uri).getPid("/io_line_check")[2]
        # the node's bus process falls silent only after bus_node_timeout + bus_stop_hold (5 s by
        # default: the 5 s this waited before the bus had a process of its own ran out)
        silent = (rospy.get_param("/interface/bus_node_timeout", DriverParams.bus_node_timeout)
                  + rospy.get_param("/interface/bus_stop_hold", DriverParams.bus_stop_hold))
        stopped = time.monotonic()
        os.kill(pid, signal.SIGSTOP)
        try:
            safe = self.island_outputs(lambda d: d.startswith("00 00") and "DATA_EXCH" not in d, silent + 5.0,
                                       after=stopped)
        finally:
            os.kill(pid, signal.SIGCONT)
        self.assertIsNotNone(safe, "the island's outputs did not go safe when the master fell silent")
        self.assertLess(self.outputs.times[self.outputs.messages.index(safe)] - stopped, 0.3 + SLACK)
        # the driver resumes: the island is back with its outputs at the safe values
        resumed = time.monotonic()
        self.assertIsNotNone(self.io.wait_for(all_online, 30.0, after=resumed))
        self.assertEqual(self.get_io("gripper_close").value, "0")


if __name__ == "__main__":
    rostest.rosrun(PKG, "io_line", IoLineTest)
