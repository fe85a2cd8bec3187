"""vr_driver.driver.joints.supervision: what joint_trajectory_action decides while a planner trajectory
runs and when it ends -- stepped with a fake clock in one thread, no ROS, no sleeps. The last tests
run the supervisor on the stepped driver core and virtual controller (_world.World), v1 and v2."""
from __future__ import annotations

import math
from dataclasses import replace

import pytest

from vr_driver.driver.core import TrajectoryRun
from vr_driver.driver.motion.jobs import JobPhase, MoveJob, StreamPoint
from vr_driver.driver.joints.supervision import (ABORTED, CANCELED, CANCELLED, PREEMPTED, SHUTDOWN, SUCCEEDED,
                                          TrajectorySupervisor)
from vr_driver.driver.motion.trajectories import (GOAL_TOLERANCE_VIOLATED, PATH_TOLERANCE_VIOLATED, SUCCESSFUL,
                                           TrajectoryGoal, validate)
from vr_driver.poses import ControllerPose
from vr_driver.protocol import registry

DEG = math.pi / 180.0
NAMES = tuple("joint_%d" % i for i in range(1, 7))
LOWER = (-2.705, -1.745, -3.0, -3.316, -4.712, -6.28)
UPPER = (2.705, 2.618, 1.3, 4.712, 4.712, 6.28)
HOME = (0.0, 0.6, -0.3, 0.0, 0.4, 0.0)
MID = (0.5, 0.6, -0.3, 0.0, 0.4, 0.0)
END = (1.0, 0.6, -0.3, 0.0, 0.4, 0.0)
V1 = registry.get("v1")
V2 = registry.get("v2")
T0 = 500.0                     # the fake clock's time at the start of the run


def plan(wire, goal_time_tolerance=0.0, **tolerances):
    """HOME -> MID (1 s) -> END (2 s) along joint_1, validated with the protocol's defaults."""
    goal = TrajectoryGoal(NAMES, (MID, END), (1.0, 2.0), goal_time_tolerance=goal_time_tolerance,
                          **tolerances)
    return validate(goal, NAMES, HOME, LOWER, UPPER, T0,
                    default_path_tolerance=wire.default_path_tolerance,
                    default_goal_tolerance=wire.default_goal_tolerance)


class FakeJob:
    """A v1 job of the run: done / result as MoveJob has them."""

    def __init__(self):
        self.job = MoveJob(None, points=(StreamPoint(END, 1000, 0, 2.0, 2),))   # any MoveJob will do

    def __getattr__(self, name):
        return getattr(self.job, name)


def stream_run(traj, gaps=0):
    """A v2 run: one streamed job of the two planned points."""
    job = MoveJob(None, points=(StreamPoint(MID, 500, 3, 1.0, 1), StreamPoint(END, 500, 0, 2.0, 2)),
                  start=HOME)
    job.gaps = gaps
    return TrajectoryRun(traj, [0, 1, 2], [job], T0)


def v1_run(traj):
    """A v1 run: a PTP job to each kept point."""
    return TrajectoryRun(traj, [0, 1, 2], [FakeJob().job, FakeJob().job], T0)


def succeed(run):
    for job in run.jobs:
        job.finish(True, JobPhase.SUCCEEDED, "", None)


def on_plan(traj, t):
    return tuple(traj.sample(t))


def follow(sup, traj, until=2.0, dt=0.1, lag=0.0):
    """Step along the plan (``lag`` seconds behind it) every ``dt`` up to ``until``; the samples."""
    out = []
    k = 0
    while k * dt <= until + 1e-9:
        t = k * dt
        out.append(sup.step(T0 + t, True, on_plan(traj, max(0.0, t - lag))))
        k += 1
    return out


# ------------------------------------------------------------------------------ success and notes
def test_a_run_on_plan_succeeds_with_its_note():
    traj = plan(V2)
    run = stream_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    samples = follow(sup, traj)
    assert sup.running                                   # the job has not ended
    assert all(s is not None and not s.violated for s in samples)
    mid = samples[5]                                     # t = 0.5 s: desired, actual, error
    assert mid.time == pytest.approx(0.5)
    assert mid.desired == pytest.approx((0.25,) + HOME[1:])
    assert mid.actual == pytest.approx(mid.desired) and max(map(abs, mid.error)) < 1e-9
    succeed(run)
    assert not sup.running and not sup.stops_arm
    out = sup.finish(T0 + 2.0, True, END)
    assert (out.state, out.error_code) == (SUCCEEDED, SUCCESSFUL)
    assert out.error_string.startswith("ran 1.00 x the planned 2.00 s (protocol v2: 2 of 2 points "
                                       "streamed, smooth levels up to 3)"), out.error_string
    assert out.samples == 21 and out.max_time_deviation < 1e-9


def test_the_note_says_how_closely_any_arm_could_follow_the_plan():
    """Given the arm's accelerations, the result says the plan's floor (driver.joints.following) where it is
    FLOOR_WORDS or more, in the controller's joint names: this plan starts and stops joint_1 at
    0.5 rad/s at once; at 1 rad/s^2 no arm follows it closer than 1.23 deg, at the model's 20.9 rad/s^2
    0.06 deg (not said)."""
    from vr_driver.driver.joints.following import REST_FACTOR
    traj = plan(V2)
    names = tuple("arm/j%d" % i for i in range(1, 7))
    words = {}
    for acc in (1.0, 20.9, None):
        run = stream_run(traj)
        sup = TrajectorySupervisor(traj, run, T0, V2, names, accelerations=None if acc is None else (acc,) * 6)
        follow(sup, traj)
        succeed(run)
        words[acc] = sup.finish(T0 + 2.0, True, END).error_string
        if acc is not None:
            assert sup.floor()[0] == pytest.approx(REST_FACTOR * 0.25 / acc)
    assert ("; no arm within the joint acceleration limits follows this plan closer than %.3f deg (arm/j1 at point 0 "
            "of 2 (starts at 29 deg/s))" % math.degrees(REST_FACTOR * 0.25)) in words[1.0], words[1.0]
    assert "no arm" not in words[20.9] and "no arm" not in words[None]
    assert words[20.9] == words[None]


def test_the_note_names_the_protocol_and_its_way_of_running():
    traj = plan(V1)
    run = v1_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V1, NAMES)
    succeed(run)
    out = sup.finish(T0 + 5.0, True, END)
    assert out.state == SUCCEEDED
    assert out.note == "ran 2.50 x the planned 2.00 s (protocol v1 stops at each of 2 points)"

    class Streams:                        # any streaming protocol: its own name, the streaming text
        name = "v7"
        streams = True
    sup = TrajectorySupervisor(traj, stream_run(traj, gaps=3), T0, Streams, NAMES)
    note = sup.note(2.0, cycle_rate=87.5)
    assert note.startswith("ran 1.00 x the planned 2.00 s (protocol v7: 2 of 2 points streamed, smooth "
                           "levels up to 3)")
    assert "stopped 3 time(s) on the way" in note and "(87.5 cycles/s)" in note
    slow = TrajectorySupervisor(traj, stream_run(traj), T0, Streams, NAMES).note(3.0)
    assert "1.50 x" in slow and "50 % longer than planned although no target came late" in slow
    assert "interpreter" in slow and "longer than planned" not in note
    # a stream that began with a hold (the bus bringing the first targets): said, and the run judged
    # against the plan after it -- 2.6 s of a 2.0 s plan after a 0.5 s hold is not a slow controller
    held = stream_run(traj)
    job = held.jobs[0]
    job.points = ((StreamPoint(HOME, 3, 0, 0.0, 0, fed=0.5, hold=True),)
                  + tuple(replace(p, fed=p.time + 0.5) for p in job.points))
    after = TrajectorySupervisor(traj, held, T0, Streams, NAMES).note(2.6)
    assert "3 of 2 points streamed, smooth levels up to 3, the first a 0.50 s hold at the start" in after, after
    assert "longer than planned" not in after
    late = TrajectorySupervisor(traj, held, T0, Streams, NAMES).note(3.3)
    assert "32 % longer than planned with its hold although no target came late" in late, late


def test_samples_without_valid_joints_are_skipped():
    traj = plan(V2)
    sup = TrajectorySupervisor(traj, stream_run(traj), T0, V2, NAMES)
    assert sup.step(T0 + 0.5, False, HOME) is None
    assert sup.step(T0 + 0.5, True, None) is None
    assert sup.samples == 0
    out = sup.finish(T0 + 2.0, False, None)
    assert (out.state, out.error_code) == (ABORTED, GOAL_TOLERANCE_VIOLATED)
    assert out.error_string.startswith("no joint state at the end; ran 1.00 x")


# ------------------------------------------------------------------------------ path tolerance
def test_leaving_the_path_tolerance_stops_the_run():
    traj = plan(V1)                                      # default path tolerance 4 deg
    run = v1_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V1, NAMES)
    near = (0.3, 0.6 + 3.5 * DEG) + HOME[2:]             # 3.5 deg beside the path: inside
    s = sup.step(T0 + 0.6, True, near)
    assert not s.violated and s.path_deviation == pytest.approx(3.5 / 4.0) and sup.running
    off = (0.7, 0.6 + 6.0 * DEG) + HOME[2:]              # 6 deg beside segment 2
    s = sup.step(T0 + 1.4, True, off)
    assert s.violated and s.segment == 2 and s.path_deviation == pytest.approx(1.5)
    assert not sup.running and sup.stops_arm
    assert sup.stop_reason == "the arm left the path tolerance near segment 2 (1.5 x the tolerance, joint_2)"
    sup.cancel()                                         # a cancel after that changes nothing
    out = sup.finish(T0 + 1.8, True, off)
    assert (out.state, out.error_code) == (ABORTED, PATH_TOLERANCE_VIOLATED)
    assert out.error_string.startswith(sup.stop_reason + "; ran 0.90 x the planned 2.00 s")
    assert out.max_path_deviation == pytest.approx(1.5)


def test_the_path_is_checked_not_the_schedule():
    """Far behind the schedule but on the path (v1 runs slower than planned): no violation."""
    traj = plan(V2)
    sup = TrajectorySupervisor(traj, stream_run(traj), T0, V2, NAMES)
    s = sup.step(T0 + 1.8, True, (0.2,) + HOME[1:])
    assert not s.violated and s.path_deviation == pytest.approx(0.0, abs=1e-9)
    assert s.time_deviation == pytest.approx(0.7)


# ------------------------------------------------------------------------------ goal and time
def test_outside_the_goal_tolerance_at_the_end_is_goal_tolerance_violated():
    traj = plan(V2)                                      # default goal tolerance 0.05 deg
    run = stream_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    succeed(run)
    short = (END[0],) + END[1:4] + (END[4] - 0.1 * DEG, END[5])
    out = sup.finish(T0 + 2.0, True, short)
    assert (out.state, out.error_code) == (ABORTED, GOAL_TOLERANCE_VIOLATED)
    assert out.error_string.startswith("joint_5 ended 0.0017 rad from the goal (tolerance 0.0009); ran 1.00 x")
    # within 0.04 deg: succeeded
    assert sup.finish(T0 + 2.0, True, END[:4] + (END[4] - 0.04 * DEG, END[5])).state == SUCCEEDED


def test_a_given_goal_tolerance_and_a_negative_one_are_kept():
    traj = plan(V2, goal_tolerance={"joint_5": 0.2 * DEG, "joint_6": -1.0})
    run = stream_run(traj)
    succeed(run)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    end = END[:4] + (END[4] - 0.1 * DEG, END[5] + 1.0)
    assert sup.finish(T0 + 2.0, True, end).state == SUCCEEDED


def test_later_than_goal_time_tolerance_is_goal_tolerance_violated():
    traj = plan(V2, goal_time_tolerance=0.5)
    run = stream_run(traj)
    succeed(run)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    out = sup.finish(T0 + 3.0, True, END)
    assert (out.state, out.error_code) == (ABORTED, GOAL_TOLERANCE_VIOLATED)
    assert out.error_string.startswith("reached 1.00 s after the planned end (goal_time_tolerance 0.50 s); "
                                       "ran 1.50 x the planned 2.00 s")
    assert sup.finish(T0 + 2.4, True, END).state == SUCCEEDED
    # a run whose time was said before it ran (a hold at the start, the bus's cycles: 2.3 s from its
    # first target, sent 0.05 s after the start) is late against that end, not the plan's
    run.jobs[0].left_at = T0 + 0.05
    said = TrajectorySupervisor(traj, run, T0, V2, NAMES, said=2.3)
    assert said.finish(T0 + 2.8, True, END).state == SUCCEEDED           # 0.45 s after the planned end
    out = said.finish(T0 + 2.9, True, END)                                # 0.55 s after the said end
    assert (out.state, out.error_code) == (ABORTED, GOAL_TOLERANCE_VIOLATED)
    assert out.error_string.startswith("reached 0.55 s after the end said before it ran (2.30 s after its first "
                                       "target) (goal_time_tolerance 0.50 s); ")
    # without a goal_time_tolerance, late is fine
    untimed = plan(V2)
    assert TrajectorySupervisor(untimed, stream_run(untimed), T0, V2, NAMES).finish(
        T0 + 9.0, True, END).state == SUCCEEDED


# ------------------------------------------------------------------------------ failure, cancel
def test_a_failed_job_aborts_with_its_reason():
    traj = plan(V1)
    run = v1_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V1, NAMES)
    run.jobs[0].finish(True, JobPhase.SUCCEEDED, "", None)
    assert sup.running
    run.jobs[1].finish(False, JobPhase.FAILED, "the controller rejected the target (error 12)", None)
    assert not sup.running and not sup.stops_arm      # nothing to stop: the job ended
    out = sup.finish(T0 + 1.5, True, MID)
    assert (out.state, out.error_code) == (ABORTED, PATH_TOLERANCE_VIOLATED)
    assert out.error_string.startswith("the controller rejected the target (error 12); ran 0.75 x")


@pytest.mark.parametrize("stop, reason, stops_arm", [
    (lambda s: s.cancel(), CANCELLED, True),
    (lambda s: s.cancel(preempted=True), PREEMPTED, False),
    (lambda s: s.shutdown(), SHUTDOWN, True),
])
def test_cancel_preempt_and_shutdown_end_canceled_with_the_note(stop, reason, stops_arm):
    traj = plan(V2)
    run = stream_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    follow(sup, traj, until=0.8)
    assert sup.running
    stop(sup)
    assert not sup.running and sup.stop_reason == reason and sup.stops_arm is stops_arm
    assert sup.preempted is (reason == PREEMPTED)
    run.jobs[0].finish(False, JobPhase.CANCELLED, reason, None)
    out = sup.finish(T0 + 1.0, True, on_plan(traj, 0.8))
    assert (out.state, out.error_code) == (CANCELED, SUCCESSFUL)
    assert out.error_string.startswith("%s; ran 0.50 x the planned 2.00 s (protocol v2" % reason), out.error_string


# ------------------------------------------------------------------------------ defaults
def test_default_tolerances_follow_what_each_protocol_reaches():
    assert V1.default_goal_tolerance == pytest.approx(3.0 * DEG)         # 2 x its 1.5 deg target_error
    assert V1.default_path_tolerance == pytest.approx(4.0 * DEG)
    assert V2.default_goal_tolerance == pytest.approx(0.05 * DEG)
    assert V2.default_path_tolerance == pytest.approx(1.05 * DEG)
    for wire in (V1, V2):
        traj = plan(wire)
        assert traj.goal_tolerance == pytest.approx((wire.default_goal_tolerance,) * 6)
        assert traj.path_tolerance == pytest.approx((wire.default_path_tolerance,) * 6)
        assert wire.default_goal_tolerance >= 2.0 * wire.target_error


def test_a_v1_goal_with_empty_tolerances_does_not_fail_on_the_wires_rounding():
    """v1 lands up to 1.5 deg from a planned joint point (whole mm / deg, solved again by the
    controller's IK): with the default tolerances that ends SUCCEEDED; 1 deg (the old default)
    would have failed it."""
    traj = plan(V1)
    run = v1_run(traj)
    succeed(run)
    sup = TrajectorySupervisor(traj, run, T0, V1, NAMES)
    landed = tuple(v + 1.5 * DEG * (-1) ** i for i, v in enumerate(END))
    assert sup.step(T0 + 2.0, True, landed).violated is False
    assert sup.finish(T0 + 4.0, True, landed).state == SUCCEEDED
    strict = plan(V1, goal_tolerance={n: 1.0 * DEG for n in NAMES})
    out = TrajectorySupervisor(strict, run, T0, V1, NAMES).finish(T0 + 4.0, True, landed)
    assert out.error_code == GOAL_TOLERANCE_VIOLATED


# ------------------------------------------------------------------------------ at-time deviation
def test_the_deviation_at_the_same_time_is_recorded_and_reported():
    traj = plan(V2)
    run = stream_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    samples = follow(sup, traj, until=2.0, lag=0.2)      # 0.2 s behind: 0.1 rad of joint_1
    assert all(not s.violated for s in samples)         # on the path all along
    assert max(s.time_deviation for s in samples[2:]) == pytest.approx(0.1)
    assert sup.max_time_deviation == pytest.approx(0.1)
    # the sample's own time stamp, not the time it is read, sets the plan it is compared with
    s = sup.step(T0 + 1.5, True, on_plan(traj, 1.0), stamp=T0 + 1.0)
    assert s.time == pytest.approx(1.0) and s.time_deviation == pytest.approx(0.0, abs=1e-12)
    s = sup.step(T0 + 1.9, True, (0.3,) + HOME[1:], stamp=T0 + 1.9, pose=ControllerPose(1, 2, 3, 0, 0, 0))
    assert s.time_deviation == pytest.approx(0.65) and sup.max_time_deviation == pytest.approx(0.65)
    assert sup.executed == [(1, 2, 3)]
    succeed(run)
    out = sup.finish(T0 + 2.2, True, END)
    assert out.state == SUCCEEDED and out.max_time_deviation == pytest.approx(0.65)
    assert "at most " in out.note and " deg from the plan at the same time after a start delay of " in out.note
    assert "%.3f deg without the delay)" % math.degrees(0.65) in out.note


def test_a_constant_start_delay_is_fitted_out_of_the_deviation_at_the_same_time():
    """The arm keeps the schedule, 0.2 s late (the stream reached the controller a few bus cycles
    after the goal): 0.1 rad off the plan at the same time, 0 after the fitted delay."""
    traj = plan(V2)
    run = stream_run(traj)
    sup = TrajectorySupervisor(traj, run, T0, V2, NAMES)
    follow(sup, traj, until=2.4, lag=0.2)
    delay, off, joint, _at = sup.fit_delay()
    assert delay == pytest.approx(0.2, abs=0.006) and off < 0.01 and joint is not None
    assert sup.max_time_deviation == pytest.approx(0.1)
    succeed(run)
    out = sup.finish(T0 + 2.4, True, END)
    assert out.start_delay == pytest.approx(0.2, abs=0.006) and out.max_delayed_deviation < 0.01
    assert "after a start delay of 0.20" in out.note


def test_a_run_is_timed_from_the_goals_arrival_with_its_preparation_said_apart():
    """Issue 46: the figures count from the goal's arrival (the run's ``started``); how long it took
    to prepare and when its first target left are said first. Arrived at T0, queued 0.04 s later, the
    first target on the wire 0.06 s after the arrival, the arm on the plan's schedule from then on: the
    time ratio includes the 0.06 s, the fitted start delay is 0.06 s."""
    traj = plan(V2)
    job = MoveJob(None, points=(StreamPoint(MID, 500, 3, 1.0, 1), StreamPoint(END, 500, 0, 2.0, 2)), start=HOME)
    job.left_at = T0 + 0.06
    run = TrajectoryRun(traj, [0, 1, 2], [job], T0, prepared=T0 + 0.04)
    sup = TrajectorySupervisor(traj, run, run.started, V2, NAMES)
    follow(sup, traj, until=2.1, lag=0.06)
    succeed(run)
    out = sup.finish(T0 + 2.1, True, END)
    assert out.note.startswith("prepared in 0.040 s; first target left 0.060 s after the goal arrived; "
                               "ran 1.05 x the planned 2.00 s (protocol v2"), out.note
    assert out.start_delay == pytest.approx(0.06, abs=0.003) and "after a start delay of 0.06" in out.note
    # a goal whose header stamp starts it later: counted from that start
    late = replace(traj, delay=0.5)
    sup = TrajectorySupervisor(late, run, run.started, V2, NAMES)
    assert sup.start_words() == "prepared in 0.040 s; first target left 0.060 s after its start time (the goal's " \
                                "header stamp); "


def test_the_first_target_leaves_with_the_bus_cycle_after_the_goal_is_queued(kin):
    """On the stepped core (no preparation time on the fake clock): the record with the first target
    is made in the bus step after the goal was queued and carried by the next cycle -- within two bus
    cycles of the arrival."""
    from _world import World
    world = World(kin, protocol="v2")
    world.ready()
    world.run_for(0.3)
    q0 = world.status().joints
    goal = TrajectoryGoal(NAMES, ((q0[0] + 0.2,) + tuple(q0[1:]),), (1.0,))
    lim = world.kin.limits
    traj = validate(goal, NAMES, q0, lim.lower, lim.upper, world.now,
                    default_path_tolerance=V2.default_path_tolerance, default_goal_tolerance=V2.default_goal_tolerance)
    arrived = world.now
    run = world.core.submit_trajectory(traj, started=arrived)
    assert run.started == arrived and run.prepared == arrived and run.first_sent is None
    world.run_until(lambda: run.first_sent is not None, 1.0, "the first target")
    job = run.jobs[0]
    assert arrived <= job.sent_at <= job.left_at <= arrived + 2.0 / world.params.cycle_rate
    world.run_until(lambda: run.done, 5.0, "the run")
    assert job.ended_at is not None and job.ended_at >= job.left_at


# ------------------------------------------------------------------------------ on the stepped core
def _supervise(world, traj, dt=0.05):
    run = world.core.submit_trajectory(traj)
    sup = TrajectorySupervisor(traj, run, run.started, world.core.wire, world.core.joint_names)
    next_step = [world.now]

    def stepped():
        if world.now >= next_step[0]:
            next_step[0] += dt
            sup.step_status(world.now, world.status())
        return not sup.running
    world.run_until(stepped, 60.0, "the run")
    return sup, sup.finish_status(world.now, world.status())


@pytest.mark.parametrize("protocol", ["v1", "v2"])
def test_a_run_on_the_stepped_core_succeeds_with_the_defaults(kin, protocol):
    from _world import World
    world = World(kin, protocol=protocol)
    world.ready()
    q0 = world.status().joints
    points = [tuple(q + f * d for q, d in zip(q0, (0.4, 0.15, -0.1, 0.2, 0.2, 0.3))) for f in (0.5, 1.0)]
    lim = world.kin.limits
    p = world.core.wire
    traj = validate(TrajectoryGoal(NAMES, tuple(points), (1.5, 3.0)), NAMES, q0, lim.lower, lim.upper,
                    world.now, default_path_tolerance=p.default_path_tolerance,
                    default_goal_tolerance=p.default_goal_tolerance)
    sup, out = _supervise(world, traj)
    assert (out.state, out.error_code) == (SUCCEEDED, SUCCESSFUL), out.error_string
    assert out.samples > 5 and 0.0 < out.max_path_deviation <= 1.0
    assert ("protocol %s" % p.name) in out.note and "from the plan at the same time" in out.note
    if p.streams:                                        # v2 keeps the schedule
        assert out.max_time_deviation < 2.0 * DEG, out.note
        assert out.elapsed < 1.2 * traj.duration
