"""feedback_states' desired / actual / error (driver/joints/feedback_states.py), with stand-ins for the
status, the jobs and the trajectory run (no bus, no ROS)."""
from types import SimpleNamespace

import pytest

from vr_driver.driver.joints.feedback_states import DesiredJoints


class Traj:
    """Joint 1 from 0 to 1 rad over 2 s, the others 0 (linear, like ValidTrajectory.sample)."""

    def sample(self, t):
        f = min(1.0, max(0.0, t / 2.0))
        return (f, 0.0, 0.0, 0.0, 0.0, 0.0)


class Job:
    def __init__(self, target, done=False):
        self.joint_target = target
        self.done = done


class Run:
    def __init__(self, jobs, started=10.0):
        self.traj, self.started, self.jobs = Traj(), started, jobs
        self.failed = None

    @property
    def done(self):
        return all(job.done for job in self.jobs)

    def failure(self):
        return self.failed


def status(joints=(0.1, 0.0, 0.0, 0.0, 0.0, 0.0), job=None, valid=True, settling=False, record_time=11.0):
    return SimpleNamespace(joints=joints, joints_valid=valid, job=job, settling=settling,
                           record_time=record_time, feedback_time=record_time + 0.01, time=record_time + 0.02)


def test_no_valid_joints_no_sample():
    d = DesiredJoints()
    assert d.sample(status(valid=False)) is None
    assert d.sample(status(joints=None)) is None


def test_at_rest_desired_is_actual_and_error_zero():
    s = DesiredJoints().sample(status())
    assert s.source == "rest"
    assert s.desired == s.actual == (0.1, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert s.error == (0.0,) * 6


def test_a_running_trajectory_gives_the_plan_at_the_record_time():
    d = DesiredJoints()
    job = Job((1.0, 0, 0, 0, 0, 0))
    d.follow(Run([job], started=10.0))
    s = d.sample(status(job=job, record_time=11.0))          # 1 s into a 2 s plan: joint 1 at 0.5
    assert s.source == "trajectory"
    assert s.desired[0] == pytest.approx(0.5)
    assert s.error[0] == pytest.approx(0.1 - 0.5)
    assert s.actual[0] == 0.1


def test_a_finished_or_failed_run_is_no_longer_desired():
    d = DesiredJoints()
    job = Job((1.0, 0, 0, 0, 0, 0), done=True)
    d.follow(Run([job]))
    assert d.sample(status()).source == "rest"
    job2 = Job((1.0, 0, 0, 0, 0, 0))
    run = Run([job2])
    run.failed = job2
    d.follow(run)
    assert d.sample(status(job=job2)).source == "job"        # the job itself still in flight


def test_another_job_in_flight_gives_its_target():
    d = DesiredJoints()
    d.follow(Run([Job((1.0, 0, 0, 0, 0, 0))]))                # a trajectory's job, not the one in flight
    other = Job((0.3, 0.2, 0.1, 0.0, 0.0, 0.0))
    s = d.sample(status(job=other))
    assert s.source == "job"
    assert s.desired == (0.3, 0.2, 0.1, 0.0, 0.0, 0.0)
    assert s.error[1] == pytest.approx(-0.2)


def test_a_stopped_job_settling_is_at_rest():
    job = Job((0.3, 0.2, 0.1, 0.0, 0.0, 0.0))
    s = DesiredJoints().sample(status(job=job, settling=True))
    assert s.source == "rest" and s.error == (0.0,) * 6
