"""The ROS-Industrial driver interface of the node `interface` (issue 26), MD5-identical to
industrial_msgs / control_msgs so ROS-Industrial clients (industrial_robot_client, its
joint_trajectory_action) use it unchanged. ROS adapter only: the decisions are the core's.

- ``feedback_states`` (control_msgs/FollowJointTrajectoryFeedback): with each ``joint_states``
  sample, same stamp, only while the link is up; desired / actual / error from
  :class:`vr_driver.driver.joints.feedback_states.DesiredJoints`.
- ``stop_motion`` (industrial_msgs/StopMotion): drop the queue, stop the target in flight.
- ``start_motion`` (industrial_msgs/StartMotion): the G2's drives and program are switched at the
  pendant and stop_motion latches nothing, so there is nothing to re-enable: SUCCESS when a motion
  command would be accepted now, FAILURE otherwise, the reason (why_no_motion) logged.
- ``joint_path_command`` service (industrial_msgs/CmdJointTrajectory): the node's one validated
  joint path function (the topic's too); SUCCESS = accepted and queued, FAILURE = refused.
- ``get_robot_info`` (industrial_msgs/GetRobotInfo): the G2 controller (protocol, card, address),
  the VR-006L arm, the driver's version; serial numbers are not known to the driver (empty).
- ``controller_joint_names`` in the node's namespace (ROS-Industrial nodes read it there).
"""
from __future__ import annotations

from typing import Callable, Sequence, Tuple

import rospy
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from vr_driver.msg import DeviceInfo, FollowJointTrajectoryFeedback, ServiceReturnCode
from vr_driver.srv import (CmdJointTrajectory, CmdJointTrajectoryResponse, GetRobotInfo, GetRobotInfoResponse,
                           StartMotion, StartMotionResponse, StopMotion, StopMotionResponse)

from ..driver import DriverStatus
from ..driver.joints.feedback_states import DesiredJoints
from ..params import ParamError

#: the message type of feedback_states: the action's own feedback message, whose MD5 is
#: control_msgs/FollowJointTrajectoryFeedback's (vr_driver/test/test_messages.py)
FEEDBACK_STATES_TYPE = FollowJointTrajectoryFeedback
SUCCESS = ServiceReturnCode(val=ServiceReturnCode.SUCCESS)
FAILURE = ServiceReturnCode(val=ServiceReturnCode.FAILURE)
CONTROLLER_MODEL = "Panasonic G2"
ROBOT_MODEL = "Panasonic VR-006L"


def package_version() -> str:
    """vr_driver's version from its package.xml ("" when it cannot be read)."""
    try:
        import rospkg
        return rospkg.RosPack().get_manifest("vr_driver").version or ""
    except Exception:  # an info field only: never fail the service for it
        return ""


def publish_joint_names_param(names: Sequence[str]) -> None:
    """``controller_joint_names`` in the node's namespace (as well as ``~controller_joint_names``).
    Already set there to other names (e.g. a ROS-Industrial launch's joint_names.yaml): a ParamError
    naming both, nothing set -- two lists of joint names would drive the arm by the wrong one."""
    key = rospy.resolve_name("controller_joint_names")
    names = list(names)
    if rospy.has_param(key):
        there = rospy.get_param(key)
        if not isinstance(there, (list, tuple)) or list(there) != names:
            raise ParamError("controller_joint_names", there,
                             "%s is already set, to other names than the driver's %s (a joint_names "
                             "file of another robot, or left on the master by an earlier launch: "
                             "rosparam delete %s)" % (key, names, key))
        return
    rospy.set_param(key, names)


class IndustrialInterface:
    """Publishers and services of the ROS-Industrial interface; ``joint_path(msg) -> (accepted,
    reason)`` is the node's validated joint path (shared with the joint_path_command topic)."""

    def __init__(self, core, params, joint_path: Callable[[JointTrajectory], Tuple[bool, str]]):
        self.core = core
        self.params = params
        self.names = list(params.controller_joint_names)
        self.joint_path = joint_path
        self.desired = DesiredJoints()
        publish_joint_names_param(self.names)
        self.feedback_pub = rospy.Publisher("feedback_states", FEEDBACK_STATES_TYPE, queue_size=10)
        self.services = [
            rospy.Service("stop_motion", StopMotion, self._stop_motion),
            rospy.Service("start_motion", StartMotion, self._start_motion),
            rospy.Service("joint_path_command", CmdJointTrajectory, self._joint_path_command),
            rospy.Service("get_robot_info", GetRobotInfo, self._get_robot_info),
        ]
        self.version = package_version()

    def follow(self, run) -> None:
        """A planner trajectory started (action, joint path topic or service): feedback_states'
        desired is its plan from now on."""
        self.desired.follow(run)

    # ------------------------------------------------------------------ feedback_states
    def publish_feedback(self, status: DriverStatus, stamp: rospy.Time) -> None:
        """With each joint_states sample (the bus thread), the same stamp."""
        sample = self.desired.sample(status)
        if sample is None:
            return
        fb = FEEDBACK_STATES_TYPE(joint_names=self.names)
        fb.header.stamp = stamp
        fb.desired = JointTrajectoryPoint(positions=list(sample.desired))
        fb.actual = JointTrajectoryPoint(positions=list(sample.actual))
        fb.error = JointTrajectoryPoint(positions=list(sample.error))
        self.feedback_pub.publish(fb)

    # ------------------------------------------------------------------ services
    def _stop_motion(self, _req) -> StopMotionResponse:
        try:
            n = self.core.stop_motion("stop_motion service called")
        except Exception as exc:  # the caller must learn that the stop was not handed over
            rospy.logerr("stop_motion failed: %s", exc)
            return StopMotionResponse(code=FAILURE)
        rospy.loginfo("stop_motion: stop sent; %d job(s) ended", n)
        return StopMotionResponse(code=SUCCESS)

    def _start_motion(self, _req) -> StartMotionResponse:
        status = self.core.status().stale(self.core.clock(), self.params.link_timeout)
        if status.motion_possible:
            return StartMotionResponse(code=SUCCESS)
        rospy.logwarn("start_motion: motion is not possible: %s", status.why_no_motion())
        return StartMotionResponse(code=FAILURE)

    def _joint_path_command(self, req) -> CmdJointTrajectoryResponse:
        accepted, _reason = self.joint_path(req.trajectory)
        return CmdJointTrajectoryResponse(code=SUCCESS if accepted else FAILURE)

    def _get_robot_info(self, _req) -> GetRobotInfoResponse:
        sc = self.core.slave_config
        wire = self.core.wire
        controller = DeviceInfo(
            model="%s, robot program protocol %s" % (CONTROLLER_MODEL, wire.name),
            serial_number="",
            hw_version="PROFIBUS-DP slave card, ident 0x%04X" % sc.ident,
            sw_version="vr_driver %s; protocol %s" % (self.version or "(version unknown)", wire.describe()),
            address="PROFIBUS-DP slave %d on %s at %d bit/s" % (sc.address, self.core.bus.phy.device,
                                                                self.core.bus.baud))
        robot = DeviceInfo(model=ROBOT_MODEL, serial_number="", hw_version="", sw_version="",
                           address="joints %s" % " ".join(self.names))
        return GetRobotInfoResponse(controller=controller, robots=[robot], code=SUCCESS)

    def shutdown(self) -> None:
        for service in self.services:
            service.shutdown()
