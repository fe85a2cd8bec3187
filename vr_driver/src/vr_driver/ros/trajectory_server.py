"""`joint_trajectory_action`: the FollowJointTrajectory action server of the node `interface`
(the ROS-Industrial name; what MoveIt's simple controller manager drives). ROS adapter only: it
translates messages. The checks are in :mod:`vr_driver.driver.motion.trajectories`, the execution in
:meth:`vr_driver.driver.DriverCore.submit_trajectory`, what is decided while it runs and how it
ends in :class:`vr_driver.driver.joints.supervision.TrajectorySupervisor`; here: goal message ->
TrajectoryGoal -> validate -> submit -> step the supervisor with the driver's status, publish its
feedback, pass on cancel / preempt / shutdown -> set the result it gives (and draw in RViz).

- A goal is validated before anything is sent; a refusal is ``set_rejected`` with the control_msgs
  error code (INVALID_JOINTS, INVALID_GOAL, OLD_HEADER_TIMESTAMP) and the reason.
- A new goal preempts the running one (its remaining points are replaced; the one in flight
  completes), as MoveIt expects of a trajectory controller.
- Feedback at the joint_states rate: desired (the plan at the elapsed time), actual, error.
- A joint the goal leaves at 0 gets the protocol's default tolerances
  (``default_path_tolerance`` / ``default_goal_tolerance``: what its wire can reach).
- The path is watched against the path tolerance (v1 cannot keep the schedule, so the distance to
  the planned *path* is checked, not to the point of the schedule); outside it: the arm is stopped
  and the goal aborted with PATH_TOLERANCE_VIOLATED. At the end the joints must be within the goal
  tolerance (GOAL_TOLERANCE_VIOLATED otherwise), and within ``goal_time_tolerance`` of the planned
  end when one is given.
- The result's error_string always says how the run's time compares with the plan (v1 stops at
  each kept point and moves at the controller program's own speed; v2 streams the points with
  their timing and blends through them), timed from the goal's arrival: how long the preparation
  took and when the first target left are said apart.
- Cancel stops the arm; the goal ends when it is at rest.
"""
from __future__ import annotations

from typing import Callable, List, Optional, Sequence, Tuple

import actionlib
import rospy
from trajectory_msgs.msg import JointTrajectoryPoint

from vr_driver.msg import FollowJointTrajectoryAction, FollowJointTrajectoryFeedback, FollowJointTrajectoryResult

from ..driver import DriverCore, DriverError
from ..driver.checks.commissioned import planning_kinematics
from ..driver.joints.resolution import WireResolution
from ..driver.joints.supervision import CANCELED, SUCCEEDED, TrajectorySupervisor
from ..driver.motion.trajectories import INVALID_GOAL, TrajectoryError, TrajectoryGoal, segment_speeds, validate
from ..errors import VrDriverError
from ..moveit.refusal import for_moveit
from .goal_runner import Goal, GoalRefused, GoalRunner


def trajectory_from_msg(traj, path_tolerance=(), goal_tolerance=(), goal_time_tolerance: float = 0.0
                        ) -> TrajectoryGoal:
    """A trajectory_msgs/JointTrajectory (and tolerances) as a TrajectoryGoal (no ROS types)."""
    stamp = traj.header.stamp.to_sec() if traj.header.stamp else 0.0
    return TrajectoryGoal(
        joint_names=tuple(traj.joint_names),
        positions=tuple(tuple(p.positions) for p in traj.points),
        times=tuple(p.time_from_start.to_sec() for p in traj.points),
        path_tolerance={t.name: t.position for t in path_tolerance},
        goal_tolerance={t.name: t.position for t in goal_tolerance},
        goal_time_tolerance=goal_time_tolerance,
        start_time=stamp or None)


def goal_from_msg(goal) -> TrajectoryGoal:
    """The ROS goal as a TrajectoryGoal (no ROS types)."""
    return trajectory_from_msg(goal.trajectory, goal.path_tolerance, goal.goal_tolerance,
                               goal.goal_time_tolerance.to_sec())


class TrajectoryServer:
    def __init__(self, core: DriverCore, feedback_rate: float, name: str = "joint_trajectory_action",
                 show: Optional[Callable[[str, Sequence[Tuple[float, float, float]], Tuple[float, float, float]],
                                         None]] = None):
        """``show(ns, points_m, rgb)``: draw a TCP line strip (the plan, the executed path)."""
        self.show = show
        self.on_run: Optional[Callable[[object], None]] = None     # told each run it starts
        self.core = core
        self.names = list(core.joint_names)
        self._resolution: Optional[Tuple[Optional[WireResolution]]] = None     # made at the first goal
        self._acc: Optional[Tuple[float, ...]] = None                      # read at the first goal
        self.period = 1.0 / max(1.0, feedback_rate)
        # each goal checked at arrival (a refusal preempts nothing); a new goal preempts the running one
        self.goals = GoalRunner(name, self._execute,
                                lambda text: FollowJointTrajectoryResult(error_code=INVALID_GOAL, error_string=text),
                                check=self._check, exclusive=True, thread_name="trajectory", clock=core.clock)
        self.server = actionlib.ActionServer(name, FollowJointTrajectoryAction, goal_cb=self.goals.on_goal,
                                             cancel_cb=self.goals.on_cancel, auto_start=False)

    def start(self) -> None:
        self.server.start()

    # ------------------------------------------------------------------ helpers
    def _check(self, goal):
        """The goal message validated at its arrival (the runner's check): the trajectory to run, or
        GoalRefused with the control_msgs error code and the reason."""
        try:
            return self.check(goal_from_msg(goal))
        except TrajectoryError as exc:
            rospy.logwarn("joint_trajectory_action refused (%d): %s", exc.code, exc)
            raise GoalRefused(FollowJointTrajectoryResult(error_code=exc.code, error_string=str(exc)),
                              str(exc)) from None

    def check(self, goal: TrajectoryGoal):
        """Validate a goal against the arm's joints now (TrajectoryError with its code): the bus
        side's :meth:`~vr_driver.driver.DriverCore.motion_snapshot`, read without touching it."""
        snap = self.core.motion_snapshot()
        if not snap.motion_possible or snap.joints is None:
            raise TrajectoryError(INVALID_GOAL, "motion is not possible: %s" % snap.why_not)
        lim = self.core.kin.limits
        wire = self.core.wire
        if self._resolution is None:
            # the Cartesian protocols' per-configuration tolerances (driver/joints/resolution.py): what the
            # wire's pose resolution allows at each planned point, joint_4 / joint_6 by their sum
            # near joint_5 = 0; None with joint targets (v2: the protocol's fixed defaults)
            self._resolution = (WireResolution.of(self.core.kin, wire),)
        traj = validate(goal, self.names, snap.joints, lim.lower, lim.upper, rospy.get_time(),
                        default_path_tolerance=wire.default_path_tolerance,
                        default_goal_tolerance=wire.default_goal_tolerance, resolution=self._resolution[0])
        segment_speeds(traj, lim.velocity, self.names)
        return traj

    def _accelerations(self) -> Tuple[float, ...]:
        """The arm's joint acceleration limits: the commissioned ones (``planning_limits``) where
        measured, else the model's -- for the result's words on how closely any arm could follow."""
        if self._acc is None:
            try:
                self._acc = tuple(planning_kinematics(self.core.params, self.core.kin).limits.acceleration)
            except VrDriverError as exc:        # (checked at start; a file changed since: the model's)
                rospy.logwarn("planning_limits: %s; the model's accelerations are used", exc)
                self._acc = tuple(self.core.kin.limits.acceleration)
        return self._acc

    def _dense(self, traj) -> List[Tuple[float, ...]]:
        """The plan sampled every 0.05 rad of the largest joint motion (a smooth line in RViz)."""
        out = [traj.positions[0]]
        for a, b in zip(traj.positions, traj.positions[1:]):
            n = max(1, int(max(abs(x - y) for x, y in zip(a, b)) / 0.05))
            out.extend(tuple(x + (y - x) * k / n for x, y in zip(a, b)) for k in range(1, n + 1))
        return out

    def _tcp(self, q: Sequence[float]) -> Tuple[float, float, float]:
        x, y, z = self.core.kin.fk_pose(q).as_tuple()[:3]
        return x / 1000.0, y / 1000.0, z / 1000.0

    def _draw(self, ns: str, points: Sequence[Tuple[float, float, float]], rgb: Tuple[float, float, float]) -> None:
        if self.show is not None and len(points) > 1:
            try:
                self.show(ns, points, rgb)
            except Exception as exc:  # a display aid only
                rospy.logwarn("could not draw %s: %s", ns, exc)

    def _execute(self, goal: Goal) -> None:
        """One accepted goal (its thread; :class:`GoalRunner` ends it if this raises): ``goal.work`` is
        the trajectory :meth:`_check` validated."""
        traj, cancel = goal.work, goal.cancel
        if traj.delay > 0.0:
            cancel.wait(traj.delay)
        try:
            # the plan's time 0: the goal's arrival (or the start its header stamp asks for), so the
            # run's figures include the preparation (said apart in the result)
            run = self.core.submit_trajectory(traj, started=goal.arrived + traj.delay)
        except (VrDriverError, DriverError) as exc:
            # one line for MoveIt's user: why, and what to change (vr_driver.moveit.refusal)
            text = for_moveit(exc, self.core.params.collision_padding)
            rospy.logwarn("joint_trajectory_action: %s", text)
            goal.set_aborted(FollowJointTrajectoryResult(error_code=INVALID_GOAL, error_string=text), text)
            return
        if self.on_run is not None:
            self.on_run(run)                 # feedback_states: desired = this plan from now on
        said = 0.0
        try:
            announced = self.core.announce_run(run)
            words, said = announced.words, announced.duration
        except (VrDriverError, DriverError) as exc:     # (cannot happen: the run's own checks passed)
            words = "not worked out (%s)" % exc
        rospy.loginfo("joint_trajectory_action: %s", words)
        sup = TrajectorySupervisor(traj, run, run.started, self.core.wire, self.names,
                                   accelerations=self._accelerations(), said=said)
        self._draw("trajectory_plan", [self._tcp(q) for q in self._dense(traj)], (1.0, 0.9, 0.1))
        last_draw = rospy.get_time()
        fb = FollowJointTrajectoryFeedback(joint_names=self.names)
        last_record = None
        while sup.running:
            if rospy.is_shutdown():
                sup.shutdown()
                break
            if cancel.is_set():
                sup.cancel(goal.preempted)
                break
            status = self.core.status()
            new = status.record_time is not None and status.record_time != last_record
            sample = sup.step_status(self.core.clock(), status) if new else None
            if sample is not None:
                # once per new controller record, stamped with the time the controller took it
                last_record = status.record_time
                fb.header.stamp = rospy.Time.now() - rospy.Duration.from_sec(
                    max(0.0, self.core.clock() - status.record_time))
                fb.desired = JointTrajectoryPoint(positions=list(sample.desired))
                fb.actual = JointTrajectoryPoint(positions=list(sample.actual))
                fb.error = JointTrajectoryPoint(positions=list(sample.error))
                goal.publish_feedback(fb)
                if rospy.get_time() - last_draw > 0.5:
                    last_draw = rospy.get_time()
                    self._draw("trajectory_executed", self._executed(sup), (0.2, 1.0, 0.2))
                if sample.violated:
                    break
            if run.jobs:
                run.jobs[-1].wait(self.period)
        if sup.stop_reason:
            # preempted: the newer trajectory already replaced our queued points and starts from
            # the one in flight; cancelled / out of tolerance / shutdown: stop the arm (at rest)
            if sup.stops_arm:
                self.core.stop_motion(sup.stop_reason)
            for job in run.jobs:
                job.wait(self.core.params.stop_timeout + 5.0)
        self._draw("trajectory_executed", self._executed(sup), (0.2, 1.0, 0.2))
        # the status of the bus iteration that ended the run or a later one (the one that ended it may
        # not be out yet; waiting for the next one delayed every result by a bus cycle)
        ended = [job.ended_at for job in run.jobs if job.ended_at is not None]
        since = max(ended) if run.jobs and len(ended) == len(run.jobs) else self.core.clock()
        status = self.core.status_after(since)
        outcome = sup.finish_status(self.core.clock(), status)
        rospy.loginfo("joint_trajectory_action: %s", outcome.note)
        result = FollowJointTrajectoryResult(error_code=outcome.error_code, error_string="%s; said before it ran: %s"
                                             % (outcome.error_string, words))
        if outcome.state == SUCCEEDED:
            goal.set_succeeded(result)
        elif outcome.state == CANCELED:
            goal.set_canceled(result)
        else:
            goal.set_aborted(result)

    @staticmethod
    def _executed(sup: TrajectorySupervisor) -> List[Tuple[float, float, float]]:
        """The executed TCP path the supervisor recorded, in metres (RViz)."""
        return [(x / 1000.0, y / 1000.0, z / 1000.0) for x, y, z in sup.executed]
