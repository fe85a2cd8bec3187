"""What ``feedback_states`` (the ROS-Industrial status topic, a FollowJointTrajectoryFeedback) says
of one controller record: desired, actual and error. ROS-free, no clock of its own: the node calls
:meth:`DesiredJoints.sample` with each :class:`~vr_driver.driver.core.DriverStatus` it publishes
``joint_states`` from, and hands it every planner trajectory it starts (:meth:`DesiredJoints.follow`).

``desired`` is the target being executed at the record's time:

- a planner trajectory running (``joint_trajectory_action``, the ``joint_path_command`` topic and
  service): the plan at the record's time since the run's start -- the same point the action's own
  feedback reports (:class:`~vr_driver.driver.joints.supervision.TrajectorySupervisor`);
- any other job in flight (a ``move_to_pose`` goal, a v1 joint path point, a streamed target):
  where that job ends (its joint target, when it has one);
- at rest (no job, or a stopped job settling): the actual joints.

``error`` is ``actual - desired``, joint by joint. Without valid joints (the link down, a stale
record) there is no sample: nothing is published.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Optional, Tuple

__all__ = ["FeedbackSample", "DesiredJoints"]


@dataclass(frozen=True)
class FeedbackSample:
    desired: Tuple[float, ...]
    actual: Tuple[float, ...]
    error: Tuple[float, ...]
    source: str                 # "trajectory", "job" or "rest": where desired came from


class DesiredJoints:
    """The newest planner trajectory run, and the desired joints of a status sample."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._run: Any = None

    def follow(self, run: Any) -> None:
        """``run`` (a :class:`~vr_driver.driver.core.TrajectoryRun`: ``traj``, ``started``, ``jobs``,
        ``done``) is now the trajectory being executed; it replaces any earlier one."""
        with self._lock:
            self._run = run

    def _running(self) -> Any:
        with self._lock:
            run = self._run
        if run is None or run.done or not run.jobs or run.failure() is not None:
            return None
        return run

    def sample(self, status: Any) -> Optional[FeedbackSample]:
        """desired / actual / error of ``status`` (None without valid joints). The record's time
        is ``record_time``, else ``feedback_time``, else the snapshot's ``time``."""
        if not status.joints_valid or status.joints is None:
            return None
        actual = tuple(float(v) for v in status.joints)
        job = status.job
        settling = bool(getattr(status, "settling", False))
        run = self._running()
        desired: Optional[Tuple[float, ...]] = None
        source = "rest"
        if run is not None and not settling and (job is None or job in run.jobs):
            stamp = next((t for t in (getattr(status, "record_time", None),
                                      getattr(status, "feedback_time", None)) if t is not None), status.time)
            desired = tuple(float(v) for v in run.traj.sample(stamp - run.started))
            source = "trajectory"
        elif job is not None and not settling and not job.done:
            try:
                target = job.joint_target
            except (AssertionError, AttributeError):
                target = None
            if target is not None and len(target) == len(actual):
                desired = tuple(float(v) for v in target)
                source = "job"
        if desired is None or len(desired) != len(actual):
            desired, source = actual, "rest"
        error = tuple(a - d for a, d in zip(actual, desired))
        return FeedbackSample(desired, actual, error, source)
