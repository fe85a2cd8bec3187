"""The ``joint_command`` topic of the node `interface` (ROS adapter only; the rules are
:mod:`vr_driver.driver.checks.joint_command`'s): trajectory_msgs/JointTrajectory of one point, streamed on
the fly (industrial_robot_client's streamer, MoveIt Servo with ``command_out_type:
trajectory_msgs/JointTrajectory``, ``rosrun vr_driver jog``).

A refused command is logged with its reason, throttled (one line a second at most: a servo loop
sends 50 a second), and counted in /diagnostics (status ``joint_command``: accepted, refused per
rule, the last refusal). A command stamped by its sender (``header.stamp``, as MoveIt Servo does)
has its age on arrival measured: /diagnostics shows the oldest and the newest of the current (or
last) stream's -- how late the transport and the node's own callbacks hand commands over, which
the arm's lag behind the sender includes and the driver cannot make up.
"""
from __future__ import annotations

import math
from typing import Any, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from trajectory_msgs.msg import JointTrajectory

from ..driver import DriverCore
from ..driver.checks.joint_command import REFUSAL_KINDS, JointCommandRefused

#: s between two log lines of refused commands
LOG_PERIOD = 1.0


class CommandAges:
    """The age on arrival [s] of the stamped commands of one stream: the youngest and the oldest."""

    def __init__(self) -> None:
        self.stream = -1
        self.count = 0
        self.least = math.inf
        self.most = -math.inf

    def add(self, stream: int, age: float) -> None:
        if stream != self.stream:
            self.stream, self.count, self.least, self.most = stream, 0, math.inf, -math.inf
        self.count += 1
        self.least = min(self.least, age)
        self.most = max(self.most, age)

    def words(self) -> str:
        if not self.count:
            return "-"
        return "%.1f .. %.1f (%d stamped)" % (1e3 * self.least, 1e3 * self.most, self.count)


class JointCommandSubscriber:
    def __init__(self, core: DriverCore, diag: Optional[Any] = None, topic: str = "joint_command") -> None:
        self.core = core
        self._refused_seen = 0
        self.ages = CommandAges()
        # queue 1: a command that waited behind a newer one is stale (the newest wins anyway)
        self.sub = rospy.Subscriber(topic, JointTrajectory, self._on_command, queue_size=1,
                                    tcp_nodelay=True)
        if diag is not None:
            diag.add("joint_command", self._diag)

    def _on_command(self, msg: JointTrajectory) -> None:
        stamp = msg.header.stamp
        age = (rospy.Time.now() - stamp).to_sec() if not stamp.is_zero() else None
        try:
            self.core.joint_commander.trajectory(msg.joint_names, msg.points)
            if age is not None:
                self.ages.add(self.core.joint_commander.counters().streams, age)
        except JointCommandRefused as exc:
            rospy.logwarn_throttle(LOG_PERIOD, "%s" % exc)
        except Exception as exc:  # never let a bad message kill the subscriber thread
            rospy.logerr_throttle(LOG_PERIOD, "joint_command: unexpected error: %s" % exc)

    def _diag(self, stat):
        c = self.core.joint_commander.counters()
        new = c.refused_total - self._refused_seen
        self._refused_seen = c.refused_total
        if new:
            stat.summary(DiagnosticStatus.WARN, "%d command(s) refused since the last report: %s"
                         % (new, c.last_refusal))
        else:
            stat.summary(DiagnosticStatus.OK, "%d accepted, %d refused" % (c.accepted, c.refused_total))
        stat.add("accepted", str(c.accepted))
        stat.add("refused", str(c.refused_total))
        for kind in REFUSAL_KINDS:
            stat.add("refused %s" % kind, str(c.refused[kind]))
        stat.add("streams", str(c.streams))
        stat.add("last refusal", c.last_refusal or "-")
        stat.add("joint_command_timeout [s]", "%g" % self.core.params.joint_command_timeout)
        stat.add("command age on arrival, last stream [ms]", self.ages.words())
        return stat
