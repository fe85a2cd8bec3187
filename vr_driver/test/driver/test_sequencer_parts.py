"""The sequencer's parts on their own, stepped by hand: Settling (driver/motion/settling.py: a stopped job
ends at rest with the pose reported, or fails after stop_timeout) and Inbox (driver/motion/inbox.py: the
requests in the order posted, the tickets that keep goals in arrival order, the wake-up and the
MotionSnapshot a request reads). The sequencers with
both are tested through the driver core in test_core_stepped.py, test_streaming_stepped.py and the
other stepped tests."""
from __future__ import annotations

import select
from types import SimpleNamespace

from vr_driver.driver.motion.inbox import AddJobs, CancelJobs, Inbox, MotionSnapshot, Wake
from vr_driver.driver.motion.jobs import JobPhase, SubmitMode
from vr_driver.driver.motion.settling import Settling
from vr_driver.params import DriverParams
from vr_driver.poses import ControllerPose
from vr_driver.protocol.common import StatusBits

PARAMS = DriverParams(stop_settle_time=0.25, stop_timeout=10.0)
POWERED = StatusBits.DRIVES_POWERED | StatusBits.PROGRAM_RUNNING


class Job:
    """The part of a MoveJob that Settling touches."""

    def __init__(self, job_id=1):
        self.id = job_id
        self.phase = JobPhase.MOVING
        self.result = None

    def set_phase(self, phase):
        self.phase = phase

    def finish(self, success, phase, reason, reached):
        self.result = (success, phase, reason, reached)


def record(x, moving=False):
    return SimpleNamespace(values=(int(x * 10), 0, 0, 0, 0, 0), pose=ControllerPose(x, 0.0, 0.0, 0.0, 0.0, 0.0),
                           status=POWERED | (StatusBits.IN_MOTION if moving else 0))


def always(_fb):
    return True


def test_a_stopped_job_ends_once_the_pose_held_still_for_stop_settle_time():
    settling, job = Settling(PARAMS), Job()
    settling.begin(job, JobPhase.CANCELLED, "cancelled", 0.0)
    assert job.phase is JobPhase.STOPPING and settling.pending.job is job
    for now, x, moving in [(0.0, 5.0, True), (0.1, 5.5, False), (0.2, 5.6, False), (0.3, 5.6, False)]:
        settling.track(now, record(x, moving))
        settling.check(now, record(x, moving), always)
        assert job.result is None and settling.pending is not None     # moved less than 0.25 s ago
    settling.track(0.45, record(5.6))
    settling.check(0.45, record(5.6), always)
    assert job.result == (False, JobPhase.CANCELLED, "cancelled", ControllerPose(5.6, 0, 0, 0, 0, 0))
    assert settling.pending is None


def test_the_protocols_own_condition_and_the_in_motion_bit_keep_it_waiting():
    settling, job = Settling(PARAMS), Job()
    settling.begin(job, JobPhase.FAILED, "rejected", 0.0)
    settling.track(0.0, record(1.0))
    settling.check(1.0, record(1.0), lambda fb: False)                 # e.g. v2's stream not idle
    assert job.result is None
    moving = record(1.0, moving=True)                                   # same pose, still moving
    settling.track(2.0, moving)
    settling.check(3.0, moving, always)
    assert job.result is None
    settling.check(3.0, record(1.0), always)                            # bit clear, still since 2.0
    assert job.result[1] is JobPhase.FAILED and job.result[2] == "rejected"


def test_a_stop_that_never_comes_to_rest_fails_after_stop_timeout_with_the_last_pose():
    settling, job = Settling(PARAMS), Job()
    settling.begin(job, JobPhase.CANCELLED, "cancelled", 0.0)
    now = 0.0
    while now <= 10.0:
        settling.track(now, record(now, moving=True))
        settling.check(now, record(now, moving=True), always)
        assert job.result is None
        now += 0.5
    settling.check(now, record(7.0, moving=True), always)
    success, phase, reason, reached = job.result
    assert (success, phase) == (False, JobPhase.FAILED) and reached == ControllerPose(7.0, 0, 0, 0, 0, 0)
    assert reason.startswith("cancelled; the arm did not come to rest within 10 s (stop_timeout)")


def test_after_a_link_loss_the_first_record_starts_the_rest_anew():
    settling, job = Settling(PARAMS), Job()
    settling.track(0.0, record(2.0))
    settling.forget()
    settling.track(5.0, record(2.0))                 # the same values: still a new start
    settling.begin(job, JobPhase.CANCELLED, "stopped", 5.0)
    settling.check(5.2, record(2.0), always)
    assert job.result is None
    settling.check(5.25, record(2.0), always)
    assert job.result is not None


def test_requests_are_taken_once_in_the_order_posted():
    inbox = Inbox()
    first, second = AddJobs((), SubmitMode.APPEND), CancelJobs(None, "stop")
    inbox.post(first)
    inbox.post(second)
    assert inbox.take() == [first, second]
    assert inbox.take() == []


def test_a_request_is_posted_to_the_inbox_and_wakes_the_bus_by_its_wake():
    """What a request's thread touches of the bus side is the inbox: posts (in order), the Wake
    (an event, and a pipe a bus process's master waits on) -- set once, taken once."""
    inbox = Inbox()
    inbox.add([], SubmitMode.PREEMPT)
    inbox.stop_all("stop")
    assert inbox.take() == [AddJobs((), SubmitMode.PREEMPT), CancelJobs(None, "stop")]
    wake = Wake()
    wake.set()                                        # before the pipe is made: its byte comes with it
    fd = wake.fileno()
    assert wake.wait(0.0) and select.select([fd], [], [], 0.0)[0] == [fd]
    wake.clear()
    assert not wake.is_set() and select.select([fd], [], [], 0.0)[0] == []
    wake.set()
    assert select.select([fd], [], [], 0.0)[0] == [fd]


def test_the_motion_snapshot_reads_as_a_lost_link_when_it_or_its_record_is_old():
    """The inbox's MotionSnapshot is read as the driver's status is: fresh as published, and one
    older than link_timeout (or whose controller record is) says why, with no motion and no valid
    joints."""
    inbox = Inbox()
    assert not inbox.snapshot(0.0).motion_possible            # nothing published yet
    inbox.publish(MotionSnapshot(10.0, True, "", (0.0,) * 6, True, "ok", 50.0, feedback_time=9.9, limit=0.5))
    fresh = inbox.snapshot(10.3)
    assert fresh.motion_possible and fresh.joints_valid and fresh.cycle_rate == 50.0
    old = inbox.snapshot(10.45)                               # the record 0.55 s old
    assert not old.motion_possible and not old.joints_valid and old.joints == (0.0,) * 6
    assert old.why_not == "no link to the controller (stale: the controller's last record is 0.55 s old)"
    assert "the driver's status is 0.60 s old" in inbox.snapshot(10.6).why_not


def test_a_preempting_ticket_older_than_one_claimed_or_taken_in_is_superseded():
    inbox = Inbox()
    a, b = inbox.claim_ticket(), inbox.claim_ticket()
    assert (a, b) == (1, 2)
    assert inbox.superseded(a) and not inbox.superseded(b)
    assert not inbox.superseded(None)                # a job without a ticket never is
    inbox.preempts(b)
    c = inbox.claim_ticket()
    inbox.preempts(c)
    assert inbox.superseded(b) and not inbox.superseded(c)
