"""ROS node `jog`: jog the VR-006L joint by joint from the keyboard, through the driver's
``joint_command`` topic (the keys and the logic: :mod:`vr_driver.terminal.jog`).

    rosrun vr_driver jog                    the driver in this namespace
    rosrun vr_driver jog __ns:=arm1         the driver in /arm1 (two_arms.launch)
    rosrun vr_driver jog _rate:=20          publish at 20 Hz (default)
    rosrun vr_driver jog _hold:=0.8         a move stops 0.8 s after its key's last repeat (default;
                                            0: latched -- it runs until space, a limit or the reverse key)

It reads the arm's joints from ``joint_states``, the joint names from ``controller_joint_names``
(the driver's namespace; default joint_1..joint_6), the limits from the model, and publishes a
trajectory_msgs/JointTrajectory of one point (time_from_start = one period) at ``~rate`` while a
joint moves. Needs protocol v2 or v3 (v1 refuses joint_command; the driver logs why). The
terminal is restored on every exit (q, Ctrl-C, Ctrl-D, a ROS shutdown, an error).
"""
from __future__ import annotations

import os
import select
import sys
import termios
import threading
import time
import tty
from typing import List, Optional

import rospy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..params import DEFAULT_JOINT_NAMES
from ..terminal.jog import Jogger, decode_keys
from ..terminal.sent_move import ctrl_c_raises
from .support import init_node

HELP = ("keys: 1-6 joint, +/- (or arrows left/right) move, [ ] (or arrows down/up) speed, "
        "space stop, q quit")


class JogNode:
    def __init__(self, rate: float, hold: float = 0.8) -> None:
        from ..kinematics.solver import Kinematics
        names = rospy.get_param("controller_joint_names", list(DEFAULT_JOINT_NAMES))
        self.names = tuple(str(n) for n in names)
        limits = Kinematics.default().limits
        self.jogger = Jogger(self.names, tuple(limits.lower), tuple(limits.upper), rate, hold=hold)
        self.rate = rate
        self._lock = threading.Lock()
        self._joints: Optional[List[float]] = None
        self.pub = rospy.Publisher("joint_command", JointTrajectory, queue_size=1, tcp_nodelay=True)
        self.sub = rospy.Subscriber("joint_states", JointState, self._on_joints, queue_size=1)

    def _on_joints(self, msg: JointState) -> None:
        index = {n: i for i, n in enumerate(msg.name)}
        if all(n in index for n in self.names):
            with self._lock:
                self._joints = [msg.position[index[n]] for n in self.names]

    def joints(self) -> Optional[List[float]]:
        with self._lock:
            return None if self._joints is None else list(self._joints)

    def publish(self, target: List[float]) -> None:
        msg = JointTrajectory()
        msg.header.stamp = rospy.Time.now()
        msg.joint_names = list(self.names)
        msg.points = [JointTrajectoryPoint(positions=target,
                                           time_from_start=rospy.Duration(1.0 / self.rate))]
        self.pub.publish(msg)

    def run(self, fd: int) -> None:
        say(HELP)
        say("joint %s selected; speed %g deg/s" % (self.names[0], self.jogger.speed * 57.29577951308232))
        period = 1.0 / self.rate
        while not rospy.is_shutdown() and not self.jogger.done:
            ready, _, _ = select.select([fd], [], [], period)
            if ready:
                data = os.read(fd, 64).decode("utf-8", "replace")
                if not data:                          # end of input
                    self.jogger.key("ctrl-d")
                for key in decode_keys(data):
                    line = self.jogger.key(key, time.monotonic())
                    if line:
                        say(line)
            target, line = self.jogger.tick(self.joints(), time.monotonic())
            if target is not None:
                self.publish(target)
            if line:
                say(line)


def say(line: str) -> None:
    sys.stdout.write(line + "\r\n")
    sys.stdout.flush()


def main(argv: Optional[List[str]] = None) -> int:
    ctrl_c_raises()                      # Ctrl-C ends jogging, even where SIGINT came in ignored
    init_node("jog", anonymous=True, disable_signals=True)
    rate = float(rospy.get_param("~rate", 20.0))
    if not 1.0 <= rate <= 200.0:
        sys.stderr.write("jog: ~rate %g must be in [1, 200] Hz\n" % rate)
        return 2
    hold = float(rospy.get_param("~hold", 0.8))
    if not 0.0 <= hold <= 5.0:
        sys.stderr.write("jog: ~hold %g must be in [0, 5] s (0: latched)\n" % hold)
        return 2
    if not sys.stdin.isatty():
        sys.stderr.write("jog: needs a terminal (stdin is not one)\n")
        return 2
    node = JogNode(rate, hold)
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd)                 # keys one by one, no echo; Ctrl-C stays a signal
        node.run(fd)
    except KeyboardInterrupt:
        pass
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        rospy.signal_shutdown("jog ended")
    say("bye (the arm holds at its last target)")
    return 0
