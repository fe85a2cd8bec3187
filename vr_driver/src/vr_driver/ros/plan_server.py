"""`plan`: the collision-aware planning action of the node `interface` (vr_driver/Plan.action). ROS
adapter only: the planning is :class:`vr_driver.driver.planning.planning.PlanActionCore` (OMPL, TOPP-RA, a
snapshot of the driver's collision checker and scene, the workspace box), run in a worker process of
its own by :class:`vr_driver.driver.planning.plan_process.PlanningProcess` -- never in the node's interpreter,
whose bus thread a plan would starve (OMPL holds the interpreter lock for seconds); execution is the node's own
``joint_trajectory_action`` -- the planned trajectory is sent to it as a FollowJointTrajectory goal, as
MoveIt's controller manager would, so it is validated, collision-checked, streamed and supervised by
the trajectory server and its result is the driver's.

- goal -> PlanGoal (joints / named state / CartesianPose in mm, deg) -> planned by the worker process
  (started once, with the action; one plan at a time) against the driver's scene and the arm's
  joints as they are when the plan starts, this goal's thread waiting for it;
- feedback: phase ``planning`` (progress 0), ``previewing`` (the plan is drawn on the latched
  ``~plan_markers``: the TCP path, the arm's sweep as stick figures at a few samples, the end),
  ``executing`` (progress = the elapsed fraction of the planned duration);
- result: the trajectory, planning time, duration, the TCP pose at the end, error_code (the values of
  moveit_msgs/MoveItErrorCodes) and error_string in words (a start or goal in collision names the
  link and the object); on execution the trajectory action's error_code and error_string;
- the speed, said before anything moves (in the result, its error_string and the log): the velocity
  scaling the plan was timed with (the goal's, else the parameter ``velocity_scaling``, 0.1 by
  default), the TCP's peak speed and the joint closest to its speed limit (:func:`peak_speeds`);
- cancel while planning: the worker is stopped (a new one starts for the next goal) and the goal
  ends cancelled at once; while executing: the trajectory goal is cancelled (the arm stops, the goal
  ends at rest). A worker that dies ends its plan with PLANNING_FAILED, in words.

Without OMPL or TOPP-RA (or, with collision_check on, without the checker's libraries) the action is
not advertised and the node says why once (MissingDependency's words, reported by the worker as it
starts: the node never imports OMPL or TOPP-RA); nothing else changes.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, NamedTuple, Optional, Sequence

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from vr_driver.msg import (CartesianPose, FollowJointTrajectoryAction, FollowJointTrajectoryGoal, PlanAction,
                           PlanFeedback, PlanGoal as PlanGoalMsg, PlanResult)

from ..driver.planning import planning as core_planning
from ..driver.motion.announced import scaling_words
from ..driver.planning.plan_process import PlanningProcess
from ..driver.planning.planning import PlanGoal, PlanOutcome, arm_points
from ..errors import MissingDependency, VrDriverError
from ..poses import ControllerPose
from .goal_runner import Goal, GoalRunner

#: stick figures of the arm drawn along a plan (start and end included)
SWEEP_POSES = 7
#: [s] the time step of the central difference that gives the TCP's speed at a sample
_SPEED_STEP = 1e-3


class PeakSpeeds(NamedTuple):
    """How fast a trajectory runs: the TCP's peak speed [mm/s] and the joint that comes closest to
    its speed limit (its index in chain order, its peak speed [rad/s], that speed / its limit)."""

    tcp: float
    joint: int
    joint_speed: float
    joint_fraction: float


def peak_speeds(kin: Any, positions: Sequence[Sequence[float]],
                velocities: Sequence[Sequence[float]]) -> PeakSpeeds:
    """The peaks over a trajectory's samples (joint positions [rad] and velocities [rad/s], chain
    order): the TCP's speed at each sample is the central difference of the controller pose's
    position (``kin.fk_pose``: the TCP in ``base``) along the joint velocity, so a TCP offset counts;
    each joint's speed is compared with ``kin.limits.velocity``. No samples: all 0."""
    tcp, best = 0.0, (0.0, 0, 0.0)
    limits = kin.limits.velocity
    for q, qd in zip(positions, velocities):
        if any(qd):
            ahead = kin.fk_pose([a + v * _SPEED_STEP for a, v in zip(q, qd)]).as_tuple()[:3]
            behind = kin.fk_pose([a - v * _SPEED_STEP for a, v in zip(q, qd)]).as_tuple()[:3]
            tcp = max(tcp, math.dist(ahead, behind) / (2.0 * _SPEED_STEP))
        for j, (v, limit) in enumerate(zip(qd, limits)):
            if limit > 0.0 and abs(v) / limit > best[0]:
                best = (abs(v) / limit, j, abs(v))
    return PeakSpeeds(tcp, best[1], best[2], best[0])


def goal_from_msg(msg) -> PlanGoal:
    """The action goal as a PlanGoal; VrDriverError / ValueError for a goal_type that is none of
    JOINTS, NAMED, POSE or a pose that is not finite."""
    common = dict(planner_id=msg.planner_id, planning_time=msg.allowed_planning_time,
                  velocity_scaling=msg.velocity_scaling)
    if msg.goal_type == PlanGoalMsg.JOINTS:
        return PlanGoal(joints=(tuple(msg.joint_names), tuple(msg.positions)), **common)
    if msg.goal_type == PlanGoalMsg.NAMED:
        if not msg.named_state:
            raise ValueError("goal_type NAMED needs named_state (e.g. home)")
        return PlanGoal(named=msg.named_state, **common)
    if msg.goal_type == PlanGoalMsg.POSE:
        p = msg.pose
        return PlanGoal(pose=ControllerPose.from_sequence((p.x, p.y, p.z, p.rx, p.ry, p.rz)), **common)
    raise ValueError("goal_type %d is unknown (1 JOINTS, 2 NAMED, 3 POSE)" % msg.goal_type)


class PlanServer:
    """The ``plan`` action (see the module text). :meth:`start` advertises it, or says why not."""

    def __init__(self, core, params, trajectory_action: str = "joint_trajectory_action",
                 name: str = "plan") -> None:
        self.core = core
        self.params = params
        self.name = name
        self.trajectory_action = trajectory_action
        self.planning: Optional[PlanningProcess] = None
        self.unavailable = ""                 # why the action is not served ("" when it is)
        self.server = None
        self.client = None
        self.marker_pub = None
        # goals run side by side, none preempts another (the worker plans one at a time)
        self.goals = GoalRunner(name, self._run, lambda text: PlanResult(
            error_code=core_planning.INVALID_MOTION_PLAN, error_string=text), thread_name="plan")

    def start(self) -> bool:
        """Start the planning process and advertise the action; False (and one warning saying why) when
        planning is not possible here. Waits for the worker to be ready (about a second: its imports),
        so that the first plan does not."""
        try:
            planning = PlanningProcess(self.core)
            planning.start()
            self.planning = planning
        except MissingDependency as exc:
            self.unavailable = str(exc)
            rospy.logwarn("interface: the plan action is not served: %s", exc)
            return False
        except VrDriverError as exc:    # a model the planner cannot plan for (limits), a worker that cannot start
            self.unavailable = str(exc)
            rospy.logwarn("interface: the plan action is not served: %s", exc)
            return False
        self.marker_pub = rospy.Publisher("~plan_markers", MarkerArray, queue_size=2, latch=True)
        self.client = actionlib.ActionClient(self.trajectory_action, FollowJointTrajectoryAction)
        self.server = actionlib.ActionServer(self.name, PlanAction, goal_cb=self.goals.on_goal,
                                             cancel_cb=self.goals.on_cancel, auto_start=False)
        self.server.start()
        if not self.planning.collision_checked:
            rospy.logwarn("interface: the plan action plans WITHOUT collision checks (collision_check: false): "
                          "only the joint limits and the workspace box")
        rospy.loginfo("interface: plan action ready (default planner %s, %g s budget, velocity scaling %g)",
                      self.params.planner_id, self.params.planning_time, self.params.velocity_scaling)
        return True

    def shutdown(self) -> None:
        """Stop the planning process (a plan in progress ends PLANNING_FAILED, saying so). The worker
        also ends by itself when the node's process does (its socket closes)."""
        if self.planning is not None:
            self.planning.close()

    # ------------------------------------------------------------------ one goal
    def _run(self, goal: Goal) -> None:
        """One accepted goal (its thread; :class:`GoalRunner` ends it if this raises)."""
        self._execute(goal, goal.get_goal(), goal.cancel)

    def _execute(self, handle, msg, cancel: threading.Event) -> None:
        """Plan ``msg``, show it and, unless ``preview_only``, run it; ``handle`` (a :class:`Goal`) ends
        once with the result, ``cancel`` stops the planning or the run."""
        handle.publish_feedback(PlanFeedback(phase=PlanFeedback.PHASE_PLANNING, progress=0.0))
        try:
            goal = goal_from_msg(msg)
        except (VrDriverError, ValueError) as exc:
            self._end(handle, PlanResult(error_code=core_planning.INVALID_GOAL, error_string="refused: %s" % exc))
            return
        outcome = self.planning.plan(goal, cancel=cancel)
        result = self._result(outcome, goal.velocity_scaling or self.params.velocity_scaling,
                              default=not goal.velocity_scaling)
        if outcome.code == core_planning.PREEMPTED:         # cancelled while planning: nothing planned
            rospy.loginfo("plan to %s: %s", goal.describe(), outcome.text)
            handle.set_canceled(result, result.error_string)
            return
        if not outcome.ok:
            rospy.logwarn("plan to %s: %s", goal.describe(), outcome.text)
            self._end(handle, result)
            return
        text = result.error_string                      # the plan and the speed it runs at, in words
        rospy.loginfo("plan to %s: %s", goal.describe(), text)
        handle.publish_feedback(PlanFeedback(phase=PlanFeedback.PHASE_PREVIEWING, progress=1.0))
        self.show(outcome)
        if cancel.is_set():
            result.error_code = core_planning.PREEMPTED
            result.error_string = "cancelled before it ran: %s" % text
            handle.set_canceled(result, result.error_string)
            return
        if msg.preview_only:
            result.error_string = "preview only (nothing sent): " + text
            handle.set_succeeded(result, result.error_string)
            return
        self._follow(handle, result, outcome, cancel)

    def _result(self, outcome: PlanOutcome, velocity_scaling: float = 0.0, default: bool = False) -> PlanResult:
        """The action's result of ``outcome``; with a trajectory also the speed it runs at
        (``velocity_scaling``: what it was timed with, ``default``: the parameter's; the peaks when the
        planning's kinematics are there) and what the protocol delivers (``run_*``,
        :meth:`DriverCore.announce`: on v1 the program's speed, with why the scaling does not apply),
        appended to error_string in words."""
        result = PlanResult(error_code=outcome.code, error_string=outcome.text, planning_time=outcome.planning_time,
                            planner_id=outcome.planner_id)
        if outcome.trajectory is not None:
            result.trajectory = self.trajectory_msg(outcome)
            result.duration = outcome.trajectory.duration
            result.velocity_scaling = velocity_scaling
            kin = getattr(self.planning, "kin", None)
            if kin is not None and len(outcome.trajectory.positions) > 1:
                peaks = peak_speeds(kin, outcome.trajectory.positions, outcome.trajectory.velocities)
                result.peak_tcp_speed = peaks.tcp
                result.peak_joint = self.core.joint_names[peaks.joint]
                result.peak_joint_speed = math.degrees(peaks.joint_speed)
                result.peak_joint_fraction = peaks.joint_fraction
                said = "velocity scaling" in outcome.text         # the planning's words name it already
                result.error_string += ("; %sat its fastest the TCP moves %.0f mm/s, %s %.1f deg/s (%.0f %% of its "
                                        "limit)" % ("" if said else "velocity scaling %g: " % velocity_scaling,
                                                    result.peak_tcp_speed, result.peak_joint,
                                                    result.peak_joint_speed, 100.0 * result.peak_joint_fraction))
            if len(outcome.trajectory.positions) > 1:
                self._announce(result, outcome, velocity_scaling, default)
        if outcome.target is not None:
            result.target = CartesianPose(*outcome.target.as_tuple())
        return result

    def _announce(self, result: PlanResult, outcome: PlanOutcome, velocity_scaling: float, default: bool) -> None:
        """The run's figures as the protocol delivers them (``run_*``), said in error_string: of what
        the driver sends for the plan as the planning's stream check made it (``outcome.stream`` /
        ``previews``; made again here only when the outcome does not carry them)."""
        plan = outcome.trajectory
        try:
            announced = self.core.announce([float(t) for t in plan.times], [tuple(q) for q in plan.positions],
                                           outcome.previews or None, outcome.stream or None)
        except VrDriverError as exc:
            result.run_words = "its run not worked out: %s" % exc
        else:
            result.run_duration, result.run_peak_tcp_speed = announced.duration, announced.top_speed
            result.run_times = list(announced.times)
            warning = scaling_words(announced, velocity_scaling, default, result.peak_tcp_speed or math.inf)
            result.run_words = "%s%s" % (warning + "; " if warning else "", announced.words)
        result.error_string += "; " + result.run_words

    def trajectory_msg(self, outcome: PlanOutcome) -> JointTrajectory:
        """The plan as trajectory_msgs/JointTrajectory under the driver's joint names (the planner's
        chain order is J1..J6, the order of controller_joint_names); stamp 0: start on arrival."""
        msg = outcome.trajectory.to_msg(JointTrajectory, JointTrajectoryPoint, rospy.Duration.from_sec)
        msg.joint_names = list(self.core.joint_names)
        return msg

    def _end(self, handle, result: PlanResult) -> None:
        handle.set_aborted(result, result.error_string)

    def _follow(self, handle, result: PlanResult, outcome: PlanOutcome, cancel: threading.Event) -> None:
        """Run the plan through joint_trajectory_action; the goal ends with its result."""
        text = result.error_string
        if not self.client.wait_for_server(rospy.Duration(5.0)):
            result.error_code = core_planning.CONTROL_FAILED
            result.error_string = "%s is not served: nothing was sent (%s)" % (self.trajectory_action, text)
            self._end(handle, result)
            return
        done = threading.Event()

        def transition(gh) -> None:
            if gh.get_comm_state() == actionlib.CommState.DONE:
                done.set()
        gh = self.client.send_goal(FollowJointTrajectoryGoal(trajectory=result.trajectory), transition_cb=transition)
        started = time.monotonic()
        # the duration the protocol delivers (v1: the program's speed), as said before it ran
        duration = max(result.run_duration or outcome.trajectory.duration, 1e-3)
        feedback = PlanFeedback(phase=PlanFeedback.PHASE_EXECUTING)
        cancelled = False
        while not done.wait(0.1):
            if cancel.is_set() and not cancelled:
                cancelled = True
                gh.cancel()                      # the trajectory server stops the arm, ends at rest
            if rospy.is_shutdown():
                break
            feedback.progress = min(1.0, (time.monotonic() - started) / duration)
            handle.publish_feedback(feedback)
        state, fjt = gh.get_goal_status(), gh.get_result()
        result.execution_error_code = fjt.error_code if fjt is not None else 0
        words = fjt.error_string if fjt is not None and fjt.error_string else "goal state %d" % state
        if state == GoalStatus.SUCCEEDED:
            result.error_code = core_planning.SUCCESS
            result.error_string = "%s; executed: %s" % (text, words)
            handle.set_succeeded(result, result.error_string)
            return
        if state in (GoalStatus.PREEMPTED, GoalStatus.RECALLED) or cancelled:
            result.error_code = core_planning.PREEMPTED
            result.error_string = "%s; stopped: %s" % (text, words)
            handle.set_canceled(result, result.error_string)
            return
        result.error_code = core_planning.CONTROL_FAILED
        result.error_string = "%s; %s by %s: %s" % (
            text, "refused" if state == GoalStatus.REJECTED else "failed", self.trajectory_action, words)
        rospy.logwarn("plan: %s", result.error_string)
        self._end(handle, result)

    # ------------------------------------------------------------------ RViz
    def show(self, outcome: PlanOutcome) -> None:
        """The plan on ~plan_markers (latched; each plan replaces the last): the TCP path (line strip,
        frame ``base_frame``), the arm as stick figures at SWEEP_POSES samples fading from start to
        end and the end's TCP (frame: the chain root, base_link)."""
        if not self.params.publish_markers or self.marker_pub is None:
            return
        try:
            self.marker_pub.publish(self.markers(outcome))
        except Exception as exc:  # a display aid only
            rospy.logwarn("could not publish the plan markers: %s", exc)

    def markers(self, outcome: PlanOutcome) -> MarkerArray:
        kin = self.planning.kin
        stamp = rospy.Time.now()
        plan = outcome.trajectory
        clear = Marker(action=Marker.DELETEALL)
        clear.header.frame_id = self.params.base_frame
        tcp = Marker()
        tcp.header.stamp, tcp.header.frame_id = stamp, self.params.base_frame
        tcp.ns, tcp.id, tcp.type, tcp.action = "plan_tcp_path", 0, Marker.LINE_STRIP, Marker.ADD
        tcp.pose.orientation.w = 1.0
        tcp.scale.x = 0.005
        tcp.color = ColorRGBA(1.0, 0.4, 0.0, 1.0)
        for q in plan.positions:
            x, y, z = kin.fk_pose(q).position_m
            tcp.points.append(Point(x, y, z))
        out = [clear, tcp]
        n = len(plan.positions)
        picks = sorted(set(round(k * (n - 1) / (SWEEP_POSES - 1)) for k in range(SWEEP_POSES))) if n > 1 else [0]
        for i, k in enumerate(picks):
            ghost = Marker()
            ghost.header.stamp, ghost.header.frame_id = stamp, kin.base
            ghost.ns, ghost.id, ghost.type, ghost.action = "plan_sweep", i, Marker.LINE_STRIP, Marker.ADD
            ghost.pose.orientation.w = 1.0
            ghost.scale.x = 0.03
            f = i / max(1, len(picks) - 1)
            ghost.color = ColorRGBA(0.3 + 0.7 * f, 0.6, 1.0 - 0.7 * f, 0.35 if 0 < i < len(picks) - 1 else 0.7)
            ghost.points = [Point(*p) for p in arm_points(kin, plan.positions[k])]
            out.append(ghost)
        end = Marker()
        end.header.stamp, end.header.frame_id = stamp, self.params.base_frame
        end.ns, end.id, end.type, end.action = "plan_goal", 0, Marker.SPHERE, Marker.ADD
        end.pose.position = tcp.points[-1]
        end.pose.orientation.w = 1.0
        end.scale.x = end.scale.y = end.scale.z = 0.04
        end.color = ColorRGBA(1.0, 0.4, 0.0, 0.9)
        out.append(end)
        return MarkerArray(markers=out)
