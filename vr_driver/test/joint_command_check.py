#!/usr/bin/python3
"""rostest of the joint_command topic (test/joint_command.test: protocol v3; driver.test's joint_command_v1:
protocol v1), written against the ROS-Industrial driver specification, not against this driver's
code: it publishes trajectory_msgs/JointTrajectory of one point on ``joint_command`` and reads
``joint_states``, the ``robot_description`` (joint limits) and standard ``/diagnostics``.

Streaming protocol (~streams true):
- a sine on joint_1 (10 deg, 0.5 Hz) commanded at 50 Hz for 3 s: the arm follows it within 1 deg once
  the commanded sine is shifted by the measured lag, the lag is bounded (printed), nothing refused;
- after the last command the arm is at rest at the last target within the command timeout plus one
  bus cycle;
- bad commands (a NaN, a jump beyond the joint speed limit, an unknown joint, a target outside the
  workspace) are refused, counted, and change nothing: the arm stays put.
Protocol v1 (~streams false): commands are refused with the reason (log and diagnostics); the arm
stays put.
"""
from __future__ import annotations

import json
import math
import os
import re
import threading
import time
import unittest

import rospy
from vr_driver.ros.support import init_node
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

PKG = "vr_driver"
DEG = math.pi / 180.0
AMPLITUDE = 10.0 * DEG
FREQUENCY = 0.5
RATE = 50.0
DURATION = 3.0


class Samples:
    """joint_states as (stamp [s], positions) in the order of ``names`` once known."""

    def __init__(self):
        self.cond = threading.Condition()
        self.names = None
        self.items = []
        self.sub = rospy.Subscriber("/joint_states", JointState, self._cb, queue_size=200, tcp_nodelay=True)

    def _cb(self, msg):
        with self.cond:
            if self.names is None:
                self.names = list(msg.name)
            index = [msg.name.index(n) for n in self.names]
            self.items.append((msg.header.stamp.to_sec(), [msg.position[i] for i in index]))
            self.cond.notify_all()

    def wait(self, predicate, timeout):
        end = time.monotonic() + timeout
        with self.cond:
            while not predicate(self.items):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self.cond.wait(left)
            return True

    def since(self, t):
        with self.cond:
            return [(s, q) for s, q in self.items if s >= t]

    def latest(self):
        with self.cond:
            return list(self.items[-1][1])


class Diagnostics:
    """The values of the diagnostic status whose name ends in 'joint_command'."""

    def __init__(self):
        self.cond = threading.Condition()
        self.values = None
        self.stamp = 0.0                     # when the node published them (ROS time [s])
        self.sub = rospy.Subscriber("/diagnostics", DiagnosticArray, self._cb, queue_size=50)

    def _cb(self, msg):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            # (diagnostic_updater first sends every task as "Node starting up", without values)
            if status.name.endswith("joint_command") and "refused" in values:
                with self.cond:
                    self.values = values
                    self.stamp = msg.header.stamp.to_sec()
                    self.cond.notify_all()

    def wait(self, predicate, timeout):
        end = time.monotonic() + timeout
        with self.cond:
            while self.values is None or not predicate(self.values):
                left = end - time.monotonic()
                if left <= 0:
                    return self.values
                self.cond.wait(left)
            return self.values


class Rosout:
    """The /rosout lines (stamp [s], text), with a wait for a line."""

    def __init__(self):
        self.cond = threading.Condition()
        self.lines = []
        self.sub = rospy.Subscriber("/rosout", Log, self._cb, queue_size=200)

    def _cb(self, msg):
        with self.cond:
            self.lines.append((msg.header.stamp.to_sec(), msg.msg))
            self.cond.notify_all()

    def matching(self, text, since=0.0):
        with self.cond:
            return [line for t, line in self.lines if text in line and t >= since]

    def wait(self, text, timeout, since=0.0):
        """The lines containing ``text`` stamped at or after ``since``, once there is one (else [])."""
        end = time.monotonic() + timeout
        with self.cond:
            while not self.matching(text, since):
                left = end - time.monotonic()
                if left <= 0:
                    return []
                self.cond.wait(left)
            return self.matching(text, since)


def urdf_limits(names):
    """(lower, upper, velocity) per joint from robot_description."""
    from urdf_parser_py.urdf import URDF
    robot = URDF.from_xml_string(rospy.get_param("/robot_description"))
    joints = {j.name: j for j in robot.joints}
    return ([joints[n].limit.lower for n in names], [joints[n].limit.upper for n in names],
            [joints[n].limit.velocity for n in names])


class JointCommandTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_node("joint_command_check")
        cls.bus_rate = rospy.get_param("~bus_rate")
        cls.streams = rospy.get_param("~streams")
        cls.js = Samples()
        cls.diag = Diagnostics()
        cls.rosout = Rosout()
        cls.pub = rospy.Publisher("/joint_command", JointTrajectory, queue_size=10, tcp_nodelay=True)
        assert cls.js.wait(lambda items: len(items) > 10, 30.0), "no joint_states"
        cls.names = list(cls.js.names)
        cls.lower, cls.upper, cls.vmax = urdf_limits(cls.names)
        cls.timeout = rospy.get_param("/interface/joint_command_timeout")
        end = time.monotonic() + 20.0
        while cls.pub.get_num_connections() == 0 and time.monotonic() < end:
            time.sleep(0.05)                  # (polling the connection count: no event for it)
        assert cls.pub.get_num_connections() > 0, "nobody subscribes joint_command"
        assert cls.diag.wait(lambda v: True, 30.0) is not None, "no joint_command diagnostics"

    # ------------------------------------------------------------------ helpers
    def command(self, positions, names=None, time_from_start=0.0):
        msg = JointTrajectory()
        msg.header.stamp = rospy.Time.now()
        msg.joint_names = list(names or self.names)
        msg.points = [JointTrajectoryPoint(positions=list(positions),
                                           time_from_start=rospy.Duration(time_from_start))]
        self.pub.publish(msg)
        return msg.header.stamp.to_sec()

    def refused(self):
        values = self.diag.wait(lambda v: True, 5.0)
        return int(values["refused"])

    def at_rest(self, seconds=0.4):
        """The arm's joints once it stood still for ``seconds`` (joint_states within 0.0005 deg)."""
        def still(items):
            if not items:
                return False
            t_end = items[-1][0]
            recent = [q for s, q in items if s >= t_end - seconds]
            first = [s for s, _q in items if s >= t_end - seconds]
            return (first and first[0] - items[0][0] >= seconds and len(recent) >= 3 and
                    max(abs(a - b) for q in recent for a, b in zip(q, recent[0])) <= 0.0005 * DEG)
        self.assertTrue(self.js.wait(still, 10.0), "the arm never came to rest")
        return self.js.latest()

    # ------------------------------------------------------------------ streaming protocols
    def sine(self):
        """Commands the sine on joint_1 from rest at RATE for DURATION: (q0, [(publish time,
        positions)], first and last publish time, the refusal count before)."""
        q0 = self.at_rest()
        refused_before = self.refused()
        sent = []                                                  # (publish time, positions)
        period = 1.0 / RATE
        start = time.monotonic()
        t0 = None
        k = 0
        while k * period <= DURATION + 1e-9:
            wait = start + k * period - time.monotonic()
            if wait > 0:
                time.sleep(wait)                                   # the publishing rate itself
            now = rospy.Time.now().to_sec()
            t0 = now if t0 is None else t0
            q = list(q0)
            q[0] = q0[0] + AMPLITUDE * math.sin(2 * math.pi * FREQUENCY * (now - t0))
            self.command(q, time_from_start=period)
            sent.append((now, q))
            k += 1
        return q0, sent, t0, sent[-1][0], refused_before

    def test_01_a_sine_on_joint_1_at_50_hz_is_followed(self):
        if not self.streams:
            self.skipTest("protocol v1: see test_10")
        # the driver must see one stream: a command later than joint_command_timeout (0.2 s) ends it
        # at its last point by design, and a loaded machine can hold this client back that long.
        # Such a run says nothing about following: it is run again (at most 3 runs; the driver logs
        # the start and the end of each stream)
        for attempt in range(1, 4):
            q0, sent, t0, t_last, refused_before = self.sine()
            ended = self.rosout.wait("the stream ends", 15.0, since=t_last)
            self.assertTrue(ended, "the driver never ended the stream after the last command")
            streams = len(self.rosout.matching("joint_command: stream started", since=t0 - 0.05))
            if streams == 1:
                break
            print("joint_command: run %d reached the driver as %d streams (a command came later than "
                  "joint_command_timeout: this client was held back)" % (attempt, streams))
        self.assertEqual(streams, 1, "3 runs of the sine were each cut into streams")
        period = 1.0 / RATE

        def commanded(t):
            return q0[0] + AMPLITUDE * math.sin(2 * math.pi * FREQUENCY * (min(max(t, t0), t_last) - t0))
        # the arm at rest at the last target within the command timeout plus one bus cycle -- and the
        # time the bus stood still around the end, a command late and the spread of the commands'
        # age on arrival (measured below, as for the following): a loaded machine's, not the driver's
        nominal = t_last + self.timeout + 1.0 / self.bus_rate
        self.assertTrue(self.js.wait(lambda items: items[-1][0] >= nominal + 1.5, 5.0))
        # followed: the samples during the stream against the commanded sine shifted by the lag
        during = [(s, q) for s, q in self.js.since(t0 + 0.3) if s <= t_last]
        # (one sample per record, at most: a loaded machine slows the bus and the publisher skips
        # records; a quarter of the nominal records is plenty for the fit)
        self.assertGreaterEqual(len(during), int(0.25 * self.bus_rate * (t_last - t0 - 0.3)),
                                "too few joint_states samples")

        def error(lag):
            return max(abs(q[0] - commanded(s - lag)) for s, q in during)

        def squares(lag):
            return sum((q[0] - commanded(s - lag)) ** 2 for s, q in during)
        # the lag: the shift that fits the samples best on the whole (least squares); the shift of
        # the smallest worst error followed the longest stall of the bus instead (0.082 s under load)
        lags = [0.002 * i for i in range(0, 251)]
        lag = min(lags, key=squares)
        worst = error(lag)
        others = max(abs(a - b) for _s, q in during for a, b in zip(q[1:], q0[1:]))
        # the bus as it ran: joint_states has one sample per controller record, one record per
        # cycle (a record the publisher skipped makes a gap of two). Deadlines count these cycles,
        # and a stall of the bus (a gap beyond two cycles: the driver or the controller had no CPU)
        # lets the arm fall behind the sine by its speed times the stall, then catch up
        cycle = 1.0 / self.bus_rate
        stamps = [s for s, _q in during]
        cycle_seen = (stamps[-1] - stamps[0]) / (len(stamps) - 1)

        def standing_still(times):
            """The longest gap between records beyond two cycles [s] (0: none)."""
            return max([0.0] + [b - a - 2 * cycle for a, b in zip(times, times[1:])])
        stall = standing_still(stamps)
        # the same for this test's own commands: one late by a sleep that overran leaves the arm a
        # step behind the sine until the next
        late = max(0.0, max(b[0] - a[0] for a, b in zip(sent, sent[1:])) - period)
        # and how late the commands reached the driver's callback (their age on arrival, which the
        # driver measures from the stamps and shows in /diagnostics): the transport and the node's
        # own threads, beyond what the driver can make up. Its spread shifts single commands in time
        values = self.diag.wait(lambda v: self.diag.stamp >= nominal, 10.0)
        self.assertGreaterEqual(self.diag.stamp, nominal, "no /diagnostics after the stream")
        ages = re.match(r"(-?[\d.]+) \.\. (-?[\d.]+) \((\d+) stamped\)",
                        values["command age on arrival, last stream [ms]"])
        self.assertIsNotNone(ages, values)
        age_min, age_max = float(ages.group(1)) / 1e3, float(ages.group(2)) / 1e3
        self.assertGreaterEqual(int(ages.group(3)), 0.25 * len(sent), "too few commands reached the driver")
        age_spread = max(0.0, age_max - age_min)
        # the end: the bus standing still from the last command on (beyond two cycles between records)
        end = [s for s, _q in self.js.since(t_last - 0.1) if s <= nominal + 1.0]
        end_stall = standing_still(end)
        settle = nominal + end_stall + late + age_spread
        after = [q for s, q in self.js.since(settle)]
        last = sent[-1][1]
        off = max(abs(a - b) for q in after for a, b in zip(q, last)) if after else math.inf
        speed = AMPLITUDE * 2 * math.pi * FREQUENCY
        print("joint_command: %d commands at %g Hz over %.2f s on a %g Hz bus (ran at a %.2f ms cycle, "
              "longest stall %.3f s, a command %.3f s late, %.1f .. %.1f ms old on arrival); lag %.3f s (= two "
              "%.3f s steps + %.1f bus cycles), %.3f deg off the shifted sine, other joints %.4f deg; at rest at "
              "the last target %.3f s after it (%.4f deg off)"
              % (len(sent), RATE, t_last - t0, self.bus_rate, cycle_seen * 1000, stall, late, age_min * 1e3,
                 age_max * 1e3, lag, period, (lag - 2 * period) / cycle_seen, worst / DEG, others / DEG,
                 settle - t_last, off / DEG))
        self.assertGreaterEqual(len(after), 10)
        self.assertLessEqual(off, 0.1 * DEG, "%.4f deg from the last target after %.3f s (the command timeout "
                             "%.3f s + a bus cycle + the bus standing still %.3f s at the end + a command %.3f s "
                             "late + %.3f s spread of the commands' age on arrival)"
                             % (off / DEG, settle - t_last, self.timeout, end_stall, late, age_spread))
        spread = max(abs(a - b) for q in after for a, b in zip(q, after[0]))
        self.assertLessEqual(spread, 0.0005 * DEG, "still moving %.3f s after the last command"
                             % (settle - t_last))
        allowed = 1.0 * DEG + speed * (stall + late + age_spread)
        if worst > allowed:
            # the run's samples for a look afterwards (a fresh clone once measured a lag of 0.218 s,
            # 11.7 deg off, with no stall, no late command and no wait reported: cause not found)
            dump = os.path.join(os.environ.get("ROS_HOME", "/tmp"), "joint_command_sine_failure.json")
            try:
                with open(dump, "w") as fh:
                    json.dump({"t0": t0, "t_last": t_last, "lag": lag, "bus_rate": self.bus_rate, "sent": sent,
                               "joint_states": self.js.since(t0 - 0.5),
                               "rosout": self.rosout.matching("", since=t0 - 0.5)}, fh, default=str)
                print("joint_command: the run's commands and joint_states are in %s" % dump)
            except (OSError, TypeError, ValueError) as exc:        # never hide the verdict below
                print("joint_command: could not keep the run's samples: %s" % exc)
        self.assertLessEqual(worst, allowed, "%.3f deg off the sine shifted by %.3f s (allowed %.3f deg: 1 deg + "
                             "%.3f s of the bus standing still + a command %.3f s late + %.3f s spread of the "
                             "commands' age on arrival)" % (worst / DEG, lag, allowed / DEG, stall, late, age_spread))
        self.assertLessEqual(others, 0.1 * DEG)
        # the lag: the controller blends only into a target it already has, so the arm runs one
        # command behind -- two steps (time_from_start) -- plus the way there and back (the bus
        # cycle that carries it, the program loop that reads it, the record that reports it): at
        # most 4 bus cycles as the bus ran (measured: 1 to 2 idle, 2 to 3.2 beside two CPU hogs);
        # one command more behind would be 2 steps = 4 cycles more
        # -- after the command reached the driver (its oldest age on arrival: a loaded machine's
        # transport and callbacks, measured, not the driver's doing)
        self.assertLessEqual(lag, 2 * period + 4.0 * cycle_seen + max(0.0, age_max),
                             "lag %.3f s: two %.3f s steps + %.1f cycles of %.2f ms + %.3f s on the way"
                             % (lag, period, (lag - 2 * period - max(0.0, age_max)) / cycle_seen,
                                cycle_seen * 1000, max(0.0, age_max)))
        self.assertEqual(self.refused(), refused_before, self.diag.values)

    def assert_refused(self, positions, kind, names=None, time_from_start=0.0):
        q_before = self.at_rest()
        key = "refused %s" % kind
        n = int(self.diag.wait(lambda v: True, 5.0)[key])
        self.command(positions, names, time_from_start)
        values = self.diag.wait(lambda v: int(v[key]) >= n + 1, 15.0)
        self.assertEqual(int(values[key]), n + 1, values)
        self.assertIn(kind, values["last refusal"])
        t = rospy.Time.now().to_sec()
        self.assertTrue(self.js.wait(lambda items: items[-1][0] >= t + 0.5, 5.0))
        moved = max(abs(a - b) for _s, q in self.js.since(t - 0.5) for a, b in zip(q, q_before))
        self.assertLessEqual(moved, 0.0005 * DEG, "the arm moved %.4f deg after a refused command"
                             % (moved / DEG))
        return values["last refusal"]

    def test_02_bad_commands_are_refused_and_change_nothing(self):
        if not self.streams:
            self.skipTest("protocol v1: see test_10")
        q = self.at_rest()
        bad = list(q)
        bad[3] = float("nan")
        self.assert_refused(bad, "not_finite")
        jump = list(q)
        jump[1] += 0.6                                          # 0.6 rad in 0.02 s: 30 rad/s
        text = self.assert_refused(jump, "speed", time_from_start=0.02)
        self.assertIn(self.names[1], text)
        names = list(self.names)
        names[5] = "joint_7"
        text = self.assert_refused(q, "names", names=names)
        self.assertIn("joint_7", text)
        outside = list(q)
        outside[0] += 0.3                                       # Y = 1120 mm sin(0.3) = 331 > 300
        self.assert_refused(outside, "workspace", time_from_start=0.2)
        above = list(q)
        above[0] = self.upper[0] + 0.01
        self.assert_refused(above, "limits", time_from_start=0.2)

    # ------------------------------------------------------------------ protocol v1
    def test_10_v1_refuses_with_the_reason(self):
        if self.streams:
            self.skipTest("a streaming protocol: see test_01")
        q = self.at_rest()
        target = list(q)
        target[0] += 0.01
        text = self.assert_refused(target, "protocol", time_from_start=0.1)
        self.assertIn("cannot stream", text)
        self.assertTrue(self.rosout.wait("cannot stream", 5.0), "no log line with the reason")


if __name__ == "__main__":
    rostest.rosrun(PKG, "joint_command_check", JointCommandTest)
