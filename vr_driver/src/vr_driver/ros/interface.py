"""ROS node `interface`: the thin ROS edge of :class:`vr_driver.driver.DriverCore`.

Publishes robot_status, joint_states, tool_pose, /diagnostics and ~markers; serves the
move_to_pose action; subscribes joint_path_command. The ROS-Industrial part (feedback_states,
stop_motion, start_motion, the joint_path_command service, get_robot_info) is
:mod:`vr_driver.ros.industrial`. The I/O line
(set_io, get_io, io_states) is :mod:`vr_driver.ros.io_server`; the node's own /diagnostics tasks
(link, controller, bus) are :mod:`vr_driver.ros.diagnostics`. All decisions
(validation, preview, handshake, reconnect) are in the ROS-free core.
"""
from __future__ import annotations

import faulthandler
import signal
import sys
from typing import List, Optional, Tuple

import actionlib
import rospy
from geometry_msgs.msg import Point, PoseStamped
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from vr_driver.msg import (CartesianPose, MoveToPoseAction, MoveToPoseFeedback, MoveToPoseGoal,
                           MoveToPoseResult, RobotMode, RobotStatus, TriState)

from ..driver import (DriverCore, DriverError, DriverStatus, JobPhase, LinkState, MoveJob, MoveRequest,
                     SubmitMode)
from ..errors import MissingDependency, VrDriverError
from .diagnostics import DriverDiagnostics
from .goal_runner import Goal, GoalRunner
from .graph_watch import SenderWatch
from .industrial import IndustrialInterface
from .io_server import IoServer
from .joint_command import JointCommandSubscriber
from .scene_server import SceneServer
from .plan_server import PlanServer
from ..params import DriverParams, ParamError
from ..poses import ControllerPose, MoveType
from ..protocol.common import StatusBits
from .trajectory_server import TrajectoryServer, trajectory_from_msg
from .support import init_node, route_to_rosout, stop_on_signals, wait_for_shutdown

_MOVE_TYPES = {MoveToPoseGoal.PTP: MoveType.PTP, MoveToPoseGoal.LIN: MoveType.LIN,
               MoveToPoseGoal.CIRC: MoveType.CIRC}


def tristate(value: Optional[bool]) -> TriState:
    return TriState(val=TriState.UNKNOWN if value is None else (TriState.TRUE if value else TriState.FALSE))


def robot_status_msg(status: DriverStatus, stamp: rospy.Time) -> RobotStatus:
    """RobotStatus from a core snapshot. Link down: in_error TRUE, motion_possible FALSE, the rest
    UNKNOWN (the driver cannot tell)."""
    msg = RobotStatus()
    msg.header.stamp = stamp
    fb = status.feedback
    if fb is None:
        msg.mode = RobotMode(val=RobotMode.UNKNOWN)
        for name in ("e_stopped", "drives_powered", "in_motion"):
            setattr(msg, name, tristate(None))
        msg.motion_possible = tristate(False)
        msg.in_error = tristate(True)
    else:
        bits = fb.status
        msg.mode = RobotMode(val=RobotMode.AUTO if bits & StatusBits.PROGRAM_RUNNING else RobotMode.MANUAL)
        msg.e_stopped = tristate(bool(bits & StatusBits.ESTOP))
        msg.drives_powered = tristate(bool(bits & StatusBits.DRIVES_POWERED))
        msg.in_motion = tristate(bool(bits & StatusBits.IN_MOTION))
        msg.in_error = tristate(bool(bits & StatusBits.ERROR) or status.error_code != 0)
        msg.motion_possible = tristate(status.motion_possible)
    msg.error_code = status.error_code
    return msg


def cartesian(pose: Optional[ControllerPose]) -> CartesianPose:
    if pose is None:
        return CartesianPose()
    return CartesianPose(*pose.as_tuple())


def pose_from_msg(msg: CartesianPose, what: str) -> ControllerPose:
    """A ControllerPose from the message; PoseError names ``what`` (target / via) and the field."""
    try:
        return ControllerPose.from_sequence((msg.x, msg.y, msg.z, msg.rx, msg.ry, msg.rz))
    except VrDriverError as exc:
        raise type(exc)("%s: %s" % (what, exc)) from None


class InterfaceNode:
    def __init__(self, params: DriverParams):
        self.params = params
        self.core = DriverCore(params)
        self.names = list(params.controller_joint_names)
        self.status_pub = rospy.Publisher("robot_status", RobotStatus, queue_size=10)
        self.joint_pub = rospy.Publisher("joint_states", JointState, queue_size=10)
        self.pose_pub = rospy.Publisher("tool_pose", PoseStamped, queue_size=10)
        self.marker_pub = rospy.Publisher("~markers", MarkerArray, queue_size=2, latch=True)
        # /diagnostics: link, controller and bus (ros/diagnostics.py); the parts below add theirs
        self.diagnostics = DriverDiagnostics(self.core, params.diagnostics_period)
        self.diag = self.diagnostics.updater
        self.io_server = IoServer(self.core, params, self.diag)      # set_io, get_io, io_states
        # a plain ActionServer: a preview_only goal runs beside a moving goal and never preempts it
        # (SimpleActionServer would cancel the running move for any new goal, previews included);
        # a new motion goal preempts the running one at its arrival (the arm is stopped first) and
        # takes the core's ticket then, so that the newest goal wins however long each takes to plan
        self.goals = GoalRunner("move_to_pose", self._execute,
                                lambda text: MoveToPoseResult(success=False, reason=text),
                                exclusive=lambda goal: not goal.preview_only,
                                ticket=lambda _goal: self.core.claim_ticket())
        self.server = actionlib.ActionServer("move_to_pose", MoveToPoseAction, goal_cb=self.goals.on_goal,
                                             cancel_cb=self.goals.on_cancel, auto_start=False)
        # feedback_states, stop_motion, start_motion, joint_path_command (service), get_robot_info
        self.industrial = IndustrialInterface(self.core, params, self.joint_path)
        # FollowJointTrajectory under the ROS-Industrial name (MoveIt's controller manager)
        self.trajectory_server = TrajectoryServer(self.core, params.joint_states_rate,
                                                  show=self._line_marker if params.publish_markers else None)
        self.trajectory_server.on_run = self.industrial.follow
        # collision-aware planning (ros/plan_server.py): advertised in start() when OMPL etc. are there
        self.plan_server = PlanServer(self.core, params, "joint_trajectory_action")
        # joint_path_command and joint_command (ros/joint_command.py: joint targets streamed on the
        # fly) are subscribed in start(), with the other ways in for motion, once the rest is up
        self.path_sub: Optional[rospy.Subscriber] = None
        self.joint_command: Optional[JointCommandSubscriber] = None
        # the collision scene: ~scene/add, remove, list, load, ~scene_markers (ros/scene_server.py)
        self.scene_server = SceneServer(self.core, params, self.diag)
        self._last_link = None
        self._last_status_key = None
        self._last_record: Optional[float] = None     # record_time of the last joint_states sample

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """The bus, robot_status and /diagnostics first; then the plan action; the ways in for motion
        last (move_to_pose, joint_trajectory_action, joint_path_command, joint_command), so that no
        motion runs while the node still starts: the plan action's start (its worker process, its
        own kinematics, an action client and server) took the interpreter for a few hundred ms on a
        loaded machine, and a joint_command stream that began before it lost its commands then
        (refused as "busy", its own stream taken for another) and a trajectory's first targets came
        late (the arm stopped at its first point)."""
        self.core.add_listener(self._on_status)
        self.core.start()
        self.io_server.start()
        # robot_status must not wait for the plan action (driver.test saw no robot_status for 2 s
        # after the link was up when the timers were made after it)
        self.timers = [
            rospy.Timer(rospy.Duration(1.0 / self.params.status_rate), self._publish_status),
            # force_update: Updater.update() compares against its own period (and re-reads it from
            # ~diagnostic_period), so a timer of the same period skipped every other call (0.67 Hz)
            rospy.Timer(rospy.Duration(self.params.diagnostics_period), lambda _e: self.diag.force_update()),
        ]
        # it waits for its worker process to be ready (1-2 s, longer on a loaded machine)
        self.plan_server.start()
        self.server.start()
        self.trajectory_server.start()
        self.path_sub = rospy.Subscriber("joint_path_command", JointTrajectory, self._joint_path,
                                         queue_size=1)
        self.joint_command = JointCommandSubscriber(self.core, self.diag)
        # a sender on another machine this node cannot reach back is said in the log (doc/network.md)
        self.sender_watch = SenderWatch(rospy.get_name())
        self.sender_watch.start()
        # a shutdown hook (e.g. rosnode kill) only asks; main() does the real stop
        rospy.on_shutdown(self.core.request_stop)
        sc = self.core.slave_config
        rospy.loginfo("interface: driving slave %d on %s at %d bit/s, %g Hz bus cycle, card watchdog %s, "
                      "link_timeout %g s (effective values: launch arguments > parameter file > defaults)",
                      sc.address, self.core.bus.phy.device, self.core.bus.baud,
                      self.core.bus.cycle_rate_hz, "%d ms" % sc.watchdog_ms if sc.watchdog_ms else "OFF",
                      self.params.link_timeout)
        if not sc.watchdog_ms:
            rospy.logwarn("interface: the controller card's watchdog is OFF (watchdog_ms: 0, "
                          "allow_no_watchdog: true): if this node dies or hangs, the arm does NOT stop")

    def shutdown(self) -> None:
        for timer in getattr(self, "timers", []):
            timer.shutdown()
        self.io_server.shutdown()
        if getattr(self, "sender_watch", None) is not None:
            self.sender_watch.stop()
        plan_server = getattr(self, "plan_server", None)
        if plan_server is not None:
            plan_server.shutdown()          # its worker ends by EOF anyway; this ends it now
        self.core.stop()

    # ------------------------------------------------------------------ publishing
    def _on_status(self, status: DriverStatus) -> None:
        """Bus thread: publish robot_status at once when it changes (besides the fixed rate), and
        log link state changes once, in words. The snapshot is read as of now (a stop of the
        process between the snapshot and this call must not publish old good news)."""
        stamp = rospy.Time.now()                 # first: the status is then at least this new
        status = status.stale(self.core.clock(), self.params.link_timeout)
        msg = robot_status_msg(status, stamp)
        key = (msg.mode.val, msg.e_stopped.val, msg.drives_powered.val, msg.motion_possible.val,
               msg.in_motion.val, msg.in_error.val, msg.error_code)
        if key != self._last_status_key:
            self._last_status_key = key
            self.status_pub.publish(msg)
        self._publish_joints(status, stamp)
        if status.link is not self._last_link:
            self._last_link = status.link
            if status.link is LinkState.CONNECTED:
                rospy.loginfo("controller connected: %s", status.feedback.describe() if status.feedback else "")
            else:
                rospy.logwarn("controller link %s: %s", status.link.value, status.link_reason)

    def _publish_status(self, _event=None) -> None:
        stamp = rospy.Time.now()                 # first: the status is then at least this new
        self.status_pub.publish(robot_status_msg(self.core.status(), stamp))

    def _publish_joints(self, status: DriverStatus, now: rospy.Time) -> None:
        """One joint_states (and tool_pose) message per new controller record, at most
        ``joint_states_rate`` a second, stamped with the time the controller took the record (the
        bus thread: ``now`` is ROS time read at the core's clock time ``status.time`` or later)."""
        if not status.joints_valid or status.joints is None or status.pose is None \
                or status.record_time is None:
            return                           # no position feedback while the link is down
        if self._last_record is not None and \
                status.record_time - self._last_record < 0.9 / self.params.joint_states_rate:
            return                           # the same record again, or one too soon after it
        self._last_record = status.record_time
        stamp = now - rospy.Duration.from_sec(max(0.0, self.core.clock() - status.record_time))
        js = JointState()
        js.header.stamp = stamp
        js.name = self.names
        js.position = list(status.joints)
        self.joint_pub.publish(js)
        self.industrial.publish_feedback(status, stamp)
        (px, py, pz), (qx, qy, qz, qw) = status.pose.to_ros()
        ps = PoseStamped()
        ps.header.stamp = stamp
        ps.header.frame_id = self.params.base_frame
        ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = px, py, pz
        ps.pose.orientation.x, ps.pose.orientation.y = qx, qy
        ps.pose.orientation.z, ps.pose.orientation.w = qz, qw
        self.pose_pub.publish(ps)

    def _publish_markers(self, job: MoveJob) -> None:
        """Goal arrow and previewed TCP path on ~markers (a failure here never blocks a move)."""
        if not self.params.publish_markers:
            return
        try:
            self.marker_pub.publish(self._markers(job))
        except Exception as exc:  # markers are a display aid only
            rospy.logwarn("could not publish the preview markers: %s", exc)

    def _line_marker(self, ns, points, rgb) -> None:
        """A TCP line strip on ~markers (namespace ``ns``): the planned and the executed path of
        a joint_trajectory_action goal."""
        line = Marker()
        line.header.stamp, line.header.frame_id = rospy.Time.now(), self.params.base_frame
        line.ns, line.id, line.type, line.action = ns, 0, Marker.LINE_STRIP, Marker.ADD
        line.pose.orientation.w = 1.0
        line.scale.x = 0.004
        line.color.r, line.color.g, line.color.b, line.color.a = rgb[0], rgb[1], rgb[2], 1.0
        line.points = [Point(x, y, z) for x, y, z in points]
        self.marker_pub.publish(MarkerArray(markers=[line]))

    def _markers(self, job: MoveJob) -> MarkerArray:
        stamp = rospy.Time.now()
        frame = self.params.base_frame
        goal = Marker()
        goal.header.stamp, goal.header.frame_id = stamp, frame
        goal.ns, goal.id, goal.type, goal.action = "goal", 0, Marker.ARROW, Marker.ADD
        (px, py, pz), (qx, qy, qz, qw) = job.preview.target.to_ros()
        goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = px, py, pz
        goal.pose.orientation.x, goal.pose.orientation.y = qx, qy
        goal.pose.orientation.z, goal.pose.orientation.w = qz, qw
        goal.scale.x, goal.scale.y, goal.scale.z = 0.1, 0.01, 0.01
        goal.color.r, goal.color.g, goal.color.a = 1.0, 0.5, 1.0
        path = Marker()
        path.header.stamp, path.header.frame_id = stamp, frame
        path.ns, path.id, path.type, path.action = "path", 0, Marker.LINE_STRIP, Marker.ADD
        path.pose.orientation.w = 1.0
        path.scale.x = 0.004
        path.color.g, path.color.b, path.color.a = 0.8, 1.0, 1.0
        for pose in job.preview.trajectory.poses():
            x, y, z = pose.position_m
            path.points.append(Point(x, y, z))
        return MarkerArray(markers=[goal, path])

    # ------------------------------------------------------------------ commands
    def _request_from_goal(self, goal: MoveToPoseGoal) -> MoveRequest:
        if goal.move_type not in _MOVE_TYPES:
            raise DriverError("move_type %d is unknown (1 PTP, 2 LIN, 3 CIRC)" % goal.move_type)
        kind = _MOVE_TYPES[goal.move_type]
        target = pose_from_msg(goal.target, "target")
        via = pose_from_msg(goal.via, "via") if goal.has_via else None
        if kind is MoveType.CIRC and via is None:
            raise DriverError("a CIRC goal needs has_via = true and a via pose")
        if kind is not MoveType.CIRC and goal.has_via:
            raise DriverError("has_via is only allowed with CIRC goals")
        return MoveRequest(kind, target, via, preview_only=goal.preview_only)

    def _execute(self, goal: Goal) -> None:
        """One move_to_pose goal (its thread; :class:`GoalRunner` ends it if this raises)."""
        cancel = goal.cancel
        result = MoveToPoseResult()
        feedback = MoveToPoseFeedback(phase=MoveToPoseFeedback.PHASE_VALIDATING)
        status = self.core.status()
        feedback.current = cartesian(status.pose)
        goal.publish_feedback(feedback)
        try:
            request = self._request_from_goal(goal.get_goal())
            if request.preview_only:
                preview = self.core.preview(request)
                job = None
            else:
                # PREEMPT: stops the running move and drops the queue; a goal older than the
                # newest ticket is superseded by the core, never run
                job = self.core.submit(request, mode=SubmitMode.PREEMPT, ticket=goal.ticket)
                preview = job.preview
        except (VrDriverError, ValueError, TypeError) as exc:
            result.success = False
            result.reason = "refused: %s" % exc
            result.reached = cartesian(status.pose)
            rospy.logwarn("move_to_pose %s", result.reason)
            goal.set_aborted(result, result.reason)
            return
        result.joint_target = list(preview.joint_target)
        announced = self.core.announce_move(preview)     # v1: at the program's speed, with its handshake
        result.estimated_duration = announced.duration
        feedback.phase = MoveToPoseFeedback.PHASE_PREVIEW
        goal.publish_feedback(feedback)
        if job is None:
            result.success = True
            result.reached = cartesian(status.pose)
            result.reason = announced.words
            goal.set_succeeded(result, "preview only: reachable, %.2f s; %s" % (announced.duration, announced.words))
            return
        self._publish_markers(job)
        period = 1.0 / max(5.0, min(50.0, self.params.joint_states_rate))
        cancelled = False
        while not job.done:
            phase = job.phase
            if rospy.is_shutdown():
                self.core.cancel(job, "driver shutting down")
                break
            if cancel.is_set() and not cancelled:
                cancelled = True
                self.core.cancel(job, "preempted by a new goal" if goal.preempted
                                 else "goal cancelled by the client")
                feedback.phase = MoveToPoseFeedback.PHASE_STOPPING
            elif job.phase is JobPhase.STOPPING:
                feedback.phase = MoveToPoseFeedback.PHASE_STOPPING
            elif not cancelled:
                feedback.phase = (MoveToPoseFeedback.PHASE_MOVING if job.phase is JobPhase.MOVING
                                  else MoveToPoseFeedback.PHASE_SENDING)
            s = self.core.status()
            if s.pose is not None:
                feedback.current = cartesian(s.pose)
                feedback.distance_to_go, feedback.angle_to_go = s.pose.distance_to(preview.target)
            goal.publish_feedback(feedback)
            job.wait_change(phase, period)          # wakes at once on a phase change
        res = job.wait(5.0)
        s = self.core.status()
        # a stopped goal's ``reached`` is where the arm came to rest (the core waits for it)
        reached = res.reached if res is not None and res.reached is not None else s.pose
        result.reached = cartesian(reached)
        result.success = bool(res is not None and res.success)
        result.reason = res.reason if res is not None else "no result"
        if result.success:
            goal.set_succeeded(result)
        elif cancelled or (res is not None and res.phase is JobPhase.CANCELLED):
            goal.set_canceled(result, result.reason)
        else:
            rospy.logwarn("move_to_pose failed: %s", result.reason)
            goal.set_aborted(result, result.reason)

    def _joint_path(self, msg: JointTrajectory) -> None:
        """The joint_path_command topic: :meth:`joint_path`, a refusal logged."""
        self.joint_path(msg)

    def joint_path(self, msg: JointTrajectory) -> Tuple[bool, str]:
        """The one validated joint path of the joint_path_command topic and service: (accepted,
        what happened / why refused); a refusal sends nothing. Empty = stop."""
        if not msg.points:
            self.core.stop_motion("empty joint path: stop requested")
            return True, "empty joint path: stop requested"
        if self.core.streaming:
            # protocol v2 / v3: the same path as joint_trajectory_action (validated with its
            # timing, streamed; it replaces the rest of a running path)
            try:
                traj = self.trajectory_server.check(trajectory_from_msg(msg))
                run = self.core.submit_trajectory(traj)
            except (VrDriverError, ValueError, TypeError) as exc:
                rospy.logerr("joint_path_command refused: %s", exc)
                return False, "refused: %s" % exc
            self.industrial.follow(run)
            text = "%d points over %.2f s streamed" % (len(traj.positions) - 1, run.traj.duration)
            rospy.loginfo("joint_path_command: %s", text)
            return True, text
        points = [list(p.positions) for p in msg.points]
        try:
            jobs = self.core.submit_joint_path(msg.joint_names, points)
        except (VrDriverError, ValueError, TypeError) as exc:
            rospy.logerr("joint_path_command refused: %s", exc)
            return False, "refused: %s" % exc
        if jobs:
            rospy.loginfo("joint_path_command: %d points queued", len(jobs))
            self._publish_markers(jobs[-1])
        return True, "%d points queued" % len(jobs)


def main(argv: Optional[List[str]] = None) -> int:
    # `kill -USR1 <pid>` prints every thread's stack to stderr (for a node that seems stuck)
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    # the bus thread shares the interpreter with planning (goals, joint paths): hand the GIL over
    # every millisecond instead of every 5 so that a long validation delays a bus cycle less
    sys.setswitchinterval(0.001)
    stop = stop_on_signals()
    init_node("interface", disable_signals=True)
    route_to_rosout("vr_driver", "pyprofibus_vendor")
    try:
        params = DriverParams.from_dict(rospy.get_param("~", {}))
        node = InterfaceNode(params)
    except (ParamError, MissingDependency) as exc:     # MissingDependency: a scene without pinocchio / coal
        rospy.logfatal("interface: %s", exc)
        sys.stderr.write("interface: %s\n" % exc)
        return 2
    try:
        node.start()
        why = wait_for_shutdown(stop)
    finally:
        node.shutdown()
        rospy.signal_shutdown("interface stopped")
    rospy.loginfo("interface: stopped (%s)", why)
    return 0
