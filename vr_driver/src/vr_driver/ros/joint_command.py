"""The ``joint_command`` topic of the node `interface` (ROS adapter only; the rules are
:mod:`vr_driver.driver.joint_command`'s): trajectory_msgs/JointTrajectory of one point, streamed on
the fly (industrial_robot_client's streamer, MoveIt Servo with ``command_out_type:
trajectory_msgs/JointTrajectory``, ``rosrun vr_driver jog``).

A refused command is logged with its reason, throttled (one line a second at most: a servo loop
sends 50 a second), and counted in /diagnostics (status ``joint_command``: accepted, refused per
rule, the last refusal).
"""
from __future__ import annotations

from typing import Any, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from trajectory_msgs.msg import JointTrajectory

from ..driver import DriverCore
from ..driver.joint_command import REFUSAL_KINDS, JointCommandRefused

#: s between two log lines of refused commands
LOG_PERIOD = 1.0


class JointCommandSubscriber:
    def __init__(self, core: DriverCore, diag: Optional[Any] = None, topic: str = "joint_command") -> None:
        self.core = core
        self._refused_seen = 0
        # queue 1: a command that waited behind a newer one is stale (the newest wins anyway)
        self.sub = rospy.Subscriber(topic, JointTrajectory, self._on_command, queue_size=1,
                                    tcp_nodelay=True)
        if diag is not None:
            diag.add("joint_command", self._diag)

    def _on_command(self, msg: JointTrajectory) -> None:
        try:
            self.core.joint_commander.trajectory(msg.joint_names, msg.points)
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
        return stat
