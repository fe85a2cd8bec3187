"""`joint_trajectory_action`: the FollowJointTrajectory action server of the node `interface`
(the ROS-Industrial name; what MoveIt's simple controller manager drives). ROS adapter only: the
checks are in :mod:`vr_driver.driver.trajectories`, the execution in
:meth:`vr_driver.driver.DriverCore.submit_trajectory`.

- A goal is validated before anything is sent; a refusal is ``set_rejected`` with the control_msgs
  error code (INVALID_JOINTS, INVALID_GOAL, OLD_HEADER_TIMESTAMP) and the reason.
- A new goal preempts the running one (its remaining points are replaced; the one in flight
  completes), as MoveIt expects of a trajectory controller.
- Feedback at the joint_states rate: desired (the plan at the elapsed time), actual, error.
- The path is watched against the path tolerance (v1 cannot keep the schedule, so the distance to
  the planned *path* is checked, not to the point of the schedule); outside it: the arm is stopped
  and the goal aborted with PATH_TOLERANCE_VIOLATED. At the end the joints must be within the goal
  tolerance (GOAL_TOLERANCE_VIOLATED otherwise), and within ``goal_time_tolerance`` of the planned
  end when one is given.
- The result's error_string always says how the run's time compares with the plan (v1 stops at
  each kept point and moves at the controller program's own speed; v2 streams the points with
  their timing and blends through them).
- Cancel stops the arm; the goal ends when it is at rest.
"""
from __future__ import annotations

import threading
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import actionlib
import rospy
from trajectory_msgs.msg import JointTrajectoryPoint

from vr_driver.msg import FollowJointTrajectoryAction, FollowJointTrajectoryFeedback, FollowJointTrajectoryResult

from ..driver import DriverCore, DriverError
from ..driver.trajectories import (GOAL_TOLERANCE_VIOLATED, INVALID_GOAL, PATH_TOLERANCE_VIOLATED, SUCCESSFUL,
                                  TrajectoryError, TrajectoryGoal, path_deviation, segment_speeds, validate)
from ..errors import VrDriverError


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
        self.core = core
        self.names = list(core.joint_names)
        self.period = 1.0 / max(1.0, feedback_rate)
        self._lock = threading.Lock()
        self._cancel: Dict[str, threading.Event] = {}
        self._current: Optional[str] = None
        self.server = actionlib.ActionServer(name, FollowJointTrajectoryAction, goal_cb=self._on_goal,
                                             cancel_cb=self._on_cancel, auto_start=False)

    def start(self) -> None:
        self.server.start()

    # ------------------------------------------------------------------ callbacks
    def _on_goal(self, handle) -> None:
        """Goals arrive here in order: check, preempt the previous one, run in a thread."""
        goal_id = handle.get_goal_id().id
        try:
            traj = self._check(handle.get_goal())
        except TrajectoryError as exc:
            self._refuse(handle, exc.code, str(exc))
            return
        with self._lock:
            previous, self._current = self._current, goal_id
            self._cancel[goal_id] = threading.Event()
            if previous is not None and previous in self._cancel:
                self._cancel[previous].set()
        handle.set_accepted()
        threading.Thread(target=self._run, args=(handle, goal_id, traj),
                         name="trajectory-" + goal_id[-8:], daemon=True).start()

    def _on_cancel(self, handle) -> None:
        with self._lock:
            event = self._cancel.get(handle.get_goal_id().id)
        if event is not None:
            event.set()

    # ------------------------------------------------------------------ helpers
    def _check(self, goal):
        return self.check(goal_from_msg(goal))

    def check(self, goal: TrajectoryGoal):
        """Validate a goal against the arm's joints now (TrajectoryError with its code)."""
        status = self.core.status()
        if not status.motion_possible or status.joints is None:
            raise TrajectoryError(INVALID_GOAL, "motion is not possible: %s" % status.why_no_motion())
        lim = self.core.kin.limits
        traj = validate(goal, self.names, status.joints, lim.lower, lim.upper, rospy.get_time())
        segment_speeds(traj, lim.velocity, self.names)
        return traj

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

    def _refuse(self, handle, code: int, reason: str) -> None:
        rospy.logwarn("joint_trajectory_action refused (%d): %s", code, reason)
        handle.set_rejected(FollowJointTrajectoryResult(error_code=code, error_string=reason), reason)

    def _run(self, handle, goal_id: str, traj) -> None:
        try:
            self._execute(handle, goal_id, traj)
        except Exception as exc:  # never leave a goal hanging
            rospy.logerr("joint_trajectory_action: internal error: %s", exc)
            handle.set_aborted(FollowJointTrajectoryResult(error_code=INVALID_GOAL,
                                                           error_string="internal error: %s" % exc))
        finally:
            with self._lock:
                self._cancel.pop(goal_id, None)
                if self._current == goal_id:
                    self._current = None

    def _execute(self, handle, goal_id: str, traj) -> None:
        cancel = self._cancel[goal_id]
        if traj.delay > 0.0:
            cancel.wait(traj.delay)
        try:
            run = self.core.submit_trajectory(traj)
        except (VrDriverError, DriverError) as exc:
            result = FollowJointTrajectoryResult(error_code=INVALID_GOAL, error_string=str(exc))
            handle.set_aborted(result, str(exc))
            return
        started = rospy.get_time()
        self._draw("trajectory_plan", [self._tcp(q) for q in self._dense(traj)], (1.0, 0.9, 0.1))
        executed: List[Tuple[float, float, float]] = []
        last_draw = started
        fb = FollowJointTrajectoryFeedback(joint_names=self.names)
        why_stop = ""
        preempted = False
        code = SUCCESSFUL
        while not run.done:
            if rospy.is_shutdown():
                why_stop = "driver shutting down"
                break
            if cancel.is_set():
                with self._lock:
                    preempted = self._current != goal_id
                why_stop = "preempted by a newer trajectory" if preempted else "cancelled by the client"
                break
            status = self.core.status()
            if status.joints_valid and status.joints is not None:
                elapsed = rospy.get_time() - started
                desired = traj.sample(elapsed)
                actual = list(status.joints)
                fb.header.stamp = rospy.Time.now()
                fb.desired = JointTrajectoryPoint(positions=list(desired))
                fb.actual = JointTrajectoryPoint(positions=actual)
                fb.error = JointTrajectoryPoint(positions=[a - d for a, d in zip(actual, desired)])
                handle.publish_feedback(fb)
                if status.pose is not None:
                    executed.append(tuple(v / 1000.0 for v in status.pose.as_tuple()[:3]))
                    if rospy.get_time() - last_draw > 0.5:
                        last_draw = rospy.get_time()
                        self._draw("trajectory_executed", executed, (0.2, 1.0, 0.2))
                deviation, segment = path_deviation(traj, actual)
                if deviation > 1.0:
                    code = PATH_TOLERANCE_VIOLATED
                    why_stop = ("the arm left the path tolerance near segment %d (%.1f x the "
                                "tolerance)" % (segment, deviation))
                    break
            failed = run.failure()
            if failed is not None:
                break
            run.jobs[-1].wait(self.period)
        if why_stop:
            # preempted: the newer trajectory already replaced our queued points and starts from
            # the one in flight; cancelled / out of tolerance / shutdown: stop the arm (at rest)
            if not preempted:
                self.core.stop_motion(why_stop)
            for job in run.jobs:
                job.wait(self.core.params.stop_timeout + 5.0)
        self._draw("trajectory_executed", executed, (0.2, 1.0, 0.2))
        elapsed = rospy.get_time() - started
        slower = elapsed / traj.duration if traj.duration > 0 else 1.0
        if self.core.streaming:
            streamed = len(run.jobs[0].points) if run.jobs else 0
            note = "ran %.2f x the planned %.2f s (protocol v2: %d of %d points streamed, blended)" % (
                slower, traj.duration, streamed, len(traj.positions) - 1)
            gaps = run.jobs[0].gaps if run.jobs else 0
            if gaps:
                note += ("; the arm stopped %d time(s) on the way waiting for its next target: the bus "
                         "(%.1f cycles/s) did not bring it in time -- a faster line (baud) or a larger "
                         "stream_path_tolerance gives fewer, longer segments" % (gaps, self.core.link.cycle_rate))
        else:
            note = "ran %.2f x the planned %.2f s (protocol v1 stops at each of %d points)" % (
                slower, traj.duration, len(run.jobs))
        rospy.loginfo("joint_trajectory_action: %s", note)
        failed = run.failure()
        if why_stop and code != PATH_TOLERANCE_VIOLATED:
            handle.set_canceled(FollowJointTrajectoryResult(error_code=SUCCESSFUL,
                                                            error_string="%s; %s" % (why_stop, note)))
            return
        if code == PATH_TOLERANCE_VIOLATED or failed is not None:
            reason = why_stop or (failed.result.reason if failed is not None and failed.result else "failed")
            handle.set_aborted(FollowJointTrajectoryResult(
                error_code=code if code != SUCCESSFUL else PATH_TOLERANCE_VIOLATED,
                error_string="%s; %s" % (reason, note)))
            return
        status = self.core.status()
        final = traj.positions[-1]
        if status.joints is None or not status.joints_valid:
            handle.set_aborted(FollowJointTrajectoryResult(error_code=GOAL_TOLERANCE_VIOLATED,
                                                           error_string="no joint state at the end; " + note))
            return
        off = [abs(a - b) for a, b in zip(status.joints, final)]
        bad = [(self.names[i], off[i], t) for i, t in enumerate(traj.goal_tolerance) if off[i] > t]
        late = elapsed - traj.duration
        if bad:
            name, err, tol = bad[0]
            text = "%s ended %.4f rad from the goal (tolerance %.4f); %s" % (name, err, tol, note)
            handle.set_aborted(FollowJointTrajectoryResult(error_code=GOAL_TOLERANCE_VIOLATED, error_string=text))
        elif traj.goal_time_tolerance > 0.0 and late > traj.goal_time_tolerance:
            text = "reached %.2f s after the planned end (goal_time_tolerance %.2f s); %s" % (
                late, traj.goal_time_tolerance, note)
            handle.set_aborted(FollowJointTrajectoryResult(error_code=GOAL_TOLERANCE_VIOLATED, error_string=text))
        else:
            handle.set_succeeded(FollowJointTrajectoryResult(error_code=SUCCESSFUL, error_string=note))
