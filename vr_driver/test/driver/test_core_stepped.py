"""The driver core stepped with a fake clock, in one thread: DriverCore (link supervisor +
sequencer), our DP master, the in-memory link, the virtual controller's DP slave, program and arm
(_world.World). Each case of issue 14 is here as a deterministic test: the same run every time.
"""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from vr_driver.driver import DriverError, JobPhase, LinkState, MoveRequest, SubmitMode
from vr_driver.driver.joints.tracking import CommandedPath
from vr_driver.kinematics.preview import MovePreviewer
from vr_driver.errors import EnvelopeError, VrDriverError
from vr_driver.poses import ControllerPose, MoveType
from vr_driver.protocol.v1 import ControllerState, StatusBits

from _world import World

FAR = ControllerPose(1000, -600, 800, 0, 45, 0)


@pytest.fixture
def world(kin):
    return World(kin)


def lin(target):
    return MoveRequest(MoveType.LIN, target)


def first_rest(job):
    assert job.done, "the stopped job must have ended (at rest) before anything else is sent"
    return job.result.reached.as_tuple()


def moving_for(world, job, seconds):
    world.run_until(lambda: job.phase is JobPhase.MOVING, 5.0, "moving")
    world.run_for(seconds)
    assert world.arm.moving


# ------------------------------------------------------------------------------------- basics
def test_connects_and_executes_a_move_exactly_once(world):
    status = world.ready()
    assert status.link is LinkState.CONNECTED and status.pose == ControllerPose(1120, 0, 725, 0, 45, 0)
    job = world.core.submit(lin(FAR))
    result = world.finish(job)
    assert result.success and result.reached == FAR
    assert world.executed() == [("LIN", FAR.as_tuple(), "executed")]
    assert world.status().counters.targets_sent == 1


def test_the_world_is_deterministic(kin):
    """Two runs of the same world see the same statuses at the same times."""
    def run():
        w = World(kin)
        w.ready()
        job = w.core.submit(lin(FAR))
        moving_for(w, job, 0.5)
        w.core.cancel(job, "test")
        w.finish(job)
        return [(s.time, s.link, s.pose) for s in w.statuses], job.result.reached
    assert run() == run()


# ------------------------------------------------------------------ 1. the truth about stops
@pytest.mark.parametrize("how", ["cancel", "stop_motion", "preempt"])
def test_a_stopped_move_ends_at_rest_and_reports_the_rest_pose(world, how):
    world.ready()
    job = world.core.submit(lin(FAR), mode=SubmitMode.PREEMPT, ticket=world.core.claim_ticket())
    moving_for(world, job, 1.0)
    at_stop = world.status().pose
    if how == "cancel":
        world.core.cancel(job, "cancelled by the test")
    elif how == "stop_motion":
        world.core.stop_motion("stop_motion by the test")
    else:
        newer = world.core.submit(lin(ControllerPose(1000, 200, 800, 0, 45, 0)),
                                  mode=SubmitMode.PREEMPT, ticket=world.core.claim_ticket())
    world.run_until(lambda: job.phase is JobPhase.STOPPING or job.done, 1.0, "stopping")
    assert not job.done                                   # not at the moment the stop was sent
    result = world.finish(job, 5.0)
    assert result.phase is JobPhase.CANCELLED and not result.success
    fb = world.program.last_feedback
    # at rest: in-motion clear, and the reported pose is the controller's, exactly
    assert not fb.status & StatusBits.IN_MOTION and not world.arm.moving
    assert result.reached.as_tuple() == world.arm.reported_pose()
    entry = world.log.entries()[0]
    assert entry.outcome.value == "rejected" and entry.aborted
    assert result.reached.as_tuple() == entry.final_pose            # the execution log agrees
    # the arm braked: it went on beyond where it was when the stop was sent
    assert result.reached.distance_to(at_stop)[0] > 10.0
    if how == "preempt":
        assert world.finish(newer).success                # and the newer goal then runs from there
        assert newer.preview.trajectory.start != job.preview.trajectory.goal


def test_nothing_is_sent_while_the_stopped_arm_is_still_braking(world):
    world.ready()
    job = world.core.submit(lin(FAR))
    moving_for(world, job, 1.0)
    world.core.cancel(job, "test")
    queued = world.core.submit(lin(ControllerPose(1000, 0, 700, 0, 45, 0)))
    world.run_until(lambda: world.status().counters.targets_sent == 2, 10.0, "second target sent")
    assert not world.arm.moving and first_rest(job) == world.arm.reported_pose()
    assert world.finish(queued).success


# ------------------------------------------------- 3. goals take effect in arrival order
def test_the_newest_goal_wins_whatever_order_their_plans_finish_in(world):
    world.ready()
    tickets = [world.core.claim_ticket() for _ in range(20)]
    targets = [ControllerPose(1000, -500 + 50 * k, 800, 0, 45, 0) for k in range(20)]
    # the newest goal's plan finishes first, the oldest last (threads racing)
    jobs = [world.core.submit(lin(t), mode=SubmitMode.PREEMPT, ticket=tk)
            for t, tk in reversed(list(zip(targets, tickets)))]
    world.finish(jobs[0])
    world.run_for(1.0)
    assert jobs[0].result.success and jobs[0].result.reached == targets[-1]
    for job in jobs[1:]:
        assert job.result.phase is JobPhase.CANCELLED and "superseded" in job.result.reason
    assert world.executed() == [("LIN", targets[-1].as_tuple(), "executed")]


def test_goals_sent_back_to_back_end_at_the_last_one(world):
    world.ready()
    targets = [ControllerPose(1000, -500 + 50 * k, 800, 0, 45, 0) for k in range(20)]
    jobs = []
    for target in targets:
        jobs.append(world.core.submit(lin(target), mode=SubmitMode.PREEMPT,
                                      ticket=world.core.claim_ticket()))
        world.tick()
    assert world.finish(jobs[-1]).success
    assert world.status().pose == targets[-1] and world.arm.reported_pose() == targets[-1].as_tuple()
    assert all(j.result.phase is JobPhase.CANCELLED for j in jobs[:-1])
    assert world.log.entries()[-1].target == targets[-1].as_tuple()


# ------------------------------------------------------------ 4. joint paths replace each other
def test_a_new_joint_path_replaces_the_queued_targets_of_the_previous_one(world):
    status = world.ready()
    names = list(world.core.joint_names)
    q0 = list(status.joints)
    paths = []
    for k in range(200):                      # one-point paths at 100 Hz for 2 s
        q = list(q0)
        q[0] = q0[0] + 0.002 * (k + 1)
        paths.append(world.core.submit_joint_path(names, [q]))
        world.run_for(0.01)
    stopped_publishing = world.now
    last = paths[-1][0]
    world.finish(last, 20.0)
    assert last.result.success
    done_after = world.now - stopped_publishing
    executed = [e for e in world.log.entries() if e.outcome.value == "executed"]
    replaced = [p[0] for p in paths if p[0].result.phase is JobPhase.CANCELLED]
    assert "replaced" in replaced[0].result.reason
    # at most the one in flight when the publisher stopped, and the last one, after it stopped
    assert len(executed) < 60 and len(replaced) > 140
    assert done_after < 2.0, done_after
    assert tuple(world.log.entries()[-1].target) == last.preview.commands[0].values


def test_a_joint_path_lets_the_target_in_flight_complete(world):
    status = world.ready()
    names = list(world.core.joint_names)
    q0 = list(status.joints)
    first = world.core.submit_joint_path(names, [[q0[0] + 0.5] + q0[1:], [q0[0] + 0.6] + q0[1:]])
    world.run_until(lambda: first[0].phase is JobPhase.MOVING, 5.0)
    second = world.core.submit_joint_path(names, [[q0[0] - 0.2] + q0[1:]])
    world.finish(second[0])
    assert first[0].result.success                            # completed, not stopped
    assert first[1].result.phase is JobPhase.CANCELLED and "replaced" in first[1].result.reason
    assert second[0].result.success
    assert [e.outcome.value for e in world.log.entries()] == ["executed", "executed"]


# ------------------------------------------------------------ 5. the envelope along the path
def test_an_arc_below_the_floor_is_refused_naming_the_sample(world):
    world.ready()
    start = world.core.submit(MoveRequest(MoveType.PTP, (1000, -200, 150, 0, 90, 0)))
    assert world.finish(start).success
    sent = world.status().counters.targets_sent
    with pytest.raises(EnvelopeError) as err:
        world.core.submit(MoveRequest(MoveType.CIRC, (1000, 200, 150, 0, 90, 0),
                                      via=(1000, -141, 9, 0, 90, 0)))
    text = str(err.value)
    assert "CIRC path leaves the workspace at sample" in text and "Z = -" in text
    world.run_for(1.0)
    assert world.status().counters.targets_sent == sent and len(world.log.entries()) == 1


def test_the_arm_on_a_bound_of_the_box_can_move_on(world):
    """Bounds are inclusive: the arm reaches a target at X = 100 mm as FK(IK(pose)), a few 1e-13
    mm below it. The next move starts there; it was refused as "leaving the workspace at sample 0",
    and so was every move after it (the soak stalled with the arm parked on the bound)."""
    world.ready()
    on_bound = (100, -192, 1001, 113, 54, -35)
    assert world.finish(world.core.submit(MoveRequest(MoveType.PTP, on_bound))).success
    assert world.status().pose.x == 100
    for request in (MoveRequest(MoveType.LIN, (300, -192, 1001, 113, 54, -35)),
                    MoveRequest(MoveType.PTP, on_bound)):
        assert world.finish(world.core.submit(request)).success


def test_the_joints_follow_the_arms_configuration_through_fast_random_moves(kin):
    """v1 reports a pose in whole mm / deg; one pose has many joint solutions. At speed x100 the
    bus sees two or three poses of a move; near a reach or joint limit the rounded pose lies beyond
    the arm's own configuration. Solving each report nearest the previous solution lost the
    configuration (J1 off by 180 deg, J4..J6 by 360): the next move was validated from the wrong
    joints and the controller ran a path the driver never checked, up to 200 mm out of the box."""
    world = World(kin, speed_factor=100.0, params={"cycle_rate": 100.0})
    world.ready()
    rng = random.Random(3)                       # lost the configuration at the 5th move
    moved = 0
    while moved < 30:
        values = tuple(float(round(v)) for v in kin.fk_pose(kin.random_joints(rng)).as_tuple())
        try:
            job = world.core.submit(MoveRequest(MoveType.PTP, values))
        except VrDriverError:
            continue                             # outside the box, or its path leaves it
        assert world.finish(job).success
        world.run_for(0.1)
        moved += 1
        off = [abs(a - b) for a, b in zip(world.status().joints, world.arm.joints)]
        assert max(off) < math.radians(3.0), (moved, [round(math.degrees(v), 1) for v in off])


def test_the_commanded_path_places_the_arm_between_the_samples_it_stopped_between(kin):
    """Where on the last validated plan a reported pose lies (tracking.CommandedPath): between the
    two samples the arm stopped between, not at the nearest one; nowhere for a pose off the plan."""
    planner = MovePreviewer(kin)
    plan = planner.ptp_joints((0.2, 0.4, -0.3, 0.5, 0.8, -0.5), (0.9, 0.1, -0.6, -0.4, 1.2, 0.7))
    path = CommandedPath("plan", plan.positions, plan.tcp[:, :3, 3] * 1000.0, plan.tcp[:, :3, :3])
    q = np.asarray(plan.positions)

    def place(joints):
        pose = kin.fk_pose(joints)
        return path.locate(np.array(pose.as_tuple()[:3]), pose.rotation())
    k = len(q) // 2
    stopped = 0.7 * q[k] + 0.3 * q[k + 1]
    at = place(stopped)
    assert at == pytest.approx(k + 0.3, abs=0.02)
    assert np.abs(np.asarray(path.joints_at(at)) - stopped).max() < 0.05 * np.abs(q[k + 1] - q[k]).max()
    path.cursor = at
    assert path.joints_at(place(q[-1])) == pytest.approx(tuple(q[-1]), abs=1e-9)
    far = ControllerPose(1300.0, 800.0, 50.0, 0.0, 0.0, 0.0)
    assert path.locate(np.array(far.as_tuple()[:3]), far.rotation()) is None       # not on the plan


# ------------------------------------------------------------------ 8. no stale good news
def test_a_frozen_driver_never_reports_old_good_news(world):
    world.ready()
    job = world.core.submit(lin(FAR))
    moving_for(world, job, 0.5)
    assert world.status().motion_possible and world.status().feedback.status & StatusBits.IN_MOTION
    before = len(world.statuses)
    world.freeze(2.0)                            # the controller's watchdog stops the arm meanwhile
    stale = world.status()
    assert stale.link is LinkState.STALE and not stale.motion_possible and stale.pose is None
    assert not stale.joints_valid and stale.error_code != 0
    world.run_for(0.3)
    after = world.statuses[before:]
    assert after and all(not s.motion_possible and s.feedback is None for s in after[:3])
    assert job.done and not job.result.success and "lost" in job.result.reason


def test_a_reply_that_waited_out_a_freeze_is_not_fresh_news(world):
    """The driver stopped right after sending a request; the controller answered at once (moving,
    motion possible); the driver resumed 1.5 s later and read that answer. It is 1.5 s old: the
    status must not report it (seen in the SIGSTOP rostest as one "motion possible, in motion")."""
    world.ready()
    job = world.core.submit(lin(FAR))
    moving_for(world, job, 0.5)
    before = len(world.statuses)
    world.link.stall_next_read = 1.5
    world.tick()
    while len(world.statuses) == before:
        world.tick()
    first = world.statuses[before]
    assert not first.motion_possible and first.feedback is None, first
    assert first.counters.stalled_cycles == 1


def test_feedback_older_than_link_timeout_is_not_reported(world):
    world.ready()
    world.link.cut = True
    world.run_until(lambda: not world.status().connected, 2.0)
    statuses = [s for s in world.statuses if s.feedback_time is not None]
    assert all(s.time - s.feedback_time <= world.params.link_timeout + 1e-9 for s in statuses)


# ---------------------------------------------------------------- link loss and reconnect
def test_a_link_cut_fails_the_job_without_resending_and_recovers(world):
    world.ready()
    job = world.core.submit(lin(FAR))
    moving_for(world, job, 0.5)
    world.link.cut = True
    result = world.finish(job, 3.0)
    assert not result.success and "lost" in result.reason and "not re-sent" in result.reason
    world.link.cut = False
    world.ready(5.0)
    world.run_for(2.0)
    assert len(world.log.entries()) == 1                 # nothing re-sent by itself
    assert world.finish(world.core.submit(lin(ControllerPose(1000, 0, 800, 0, 45, 0)))).success


@pytest.mark.parametrize("cycle_rate", [20.0, 100.0])
def test_the_status_keeps_its_rate_while_the_link_is_down_and_reconnecting(kin, cycle_rate):
    """robot_status is published also while the link is down: a bus iteration must not wait on
    the card's back-off longer than a bus period (it waited max(0.2 s, two periods): the status
    stood still 4 periods at 20 Hz, 20 at 100 Hz, and the soak's status paused while its line was
    cut). Down and reconnecting, a snapshot at least every two periods (a telegram's reply window
    may end in the next one); in Data_Exchange the cycle under way ends first, as before."""
    world = World(kin, {"cycle_rate": cycle_rate})
    world.ready()
    period = 1.0 / cycle_rate
    before = len(world.statuses)
    world.link.cut = True
    world.run_until(lambda: not world.status().connected, 2.0, "link lost")
    world.run_for(1.5)                                   # the card backs off, the port stays open
    world.link.cut = False
    world.ready(5.0)
    statuses = world.statuses[before:]
    down = [(b.time - a.time, b.link.value) for a, b in zip(statuses, statuses[1:])
            if not a.connected and not b.connected]
    assert len(down) > 1.5 / (2.0 * period)
    assert max(gap for gap, _ in down) <= 2.0 * period + 1e-9, (max(down), period)


def test_refusals_while_the_link_is_down(world):
    world.link.cut = True
    world.run_for(1.0)
    with pytest.raises(DriverError, match="no link"):
        world.core.submit(lin(FAR))
    assert world.log.entries() == []


# ------------------------------------------------------------------ replanning off the bus
def test_a_job_queued_behind_a_stopped_one_is_planned_again_off_the_bus(world):
    world.ready()
    first = world.core.submit(lin(FAR))
    second = world.core.submit(lin(ControllerPose(1000, -300, 700, 0, 45, 0)))
    planned_from = second.preview.trajectory.start
    moving_for(world, first, 0.8)
    world.core.cancel(first, "test")
    world.run_until(lambda: second.phase is JobPhase.REPLANNING or second.done, 10.0)
    assert world.finish(second).success
    assert second.preview.trajectory.start != planned_from
    start_pose = world.kin.fk_pose(second.preview.trajectory.start)
    assert start_pose.distance_to(first.result.reached)[0] <= 1.5


def test_a_controller_rejection_fails_the_rest_of_the_path(world):
    status = world.ready()
    names = list(world.core.joint_names)
    q0 = list(status.joints)
    jobs = world.core.submit_joint_path(names, [[q0[0] + 0.3] + q0[1:], [q0[0] + 0.5] + q0[1:]])
    world.run_until(lambda: jobs[0].phase is JobPhase.MOVING, 5.0)
    world.arm.set_error("test error", now=world.now)
    world.finish(jobs[1], 15.0)
    world.finish(jobs[0], 5.0)                      # ends at rest, with the rest pose
    assert jobs[0].result.reached.as_tuple() == world.arm.reported_pose()
    assert jobs[0].result.phase is JobPhase.FAILED and jobs[1].result.phase is JobPhase.FAILED
    assert "earlier target" in jobs[1].result.reason
    assert len(world.log.entries()) == 1
    assert world.program.state in (ControllerState.READY, ControllerState.REJECTED)


# ------------------------------------------------------------ planner trajectories (v1)
def test_a_planner_trajectory_runs_through_its_thinned_points_each_once(world):
    """v1: a 30-point trajectory becomes the fewest PTP stops that keep the path within the path
    tolerance; each is executed once; the arm stays near the planned path all along."""
    import math
    from vr_driver.driver.motion.trajectories import TrajectoryGoal, path_deviation, validate
    status = world.ready()
    q0 = status.joints
    points, times = [], []
    for k in range(1, 31):
        s = k / 30.0
        points.append((q0[0] + 0.6 * s, q0[1] + 0.25 * math.sin(math.pi * s), q0[2], q0[3],
                       q0[4] + 0.2 * s, q0[5]))
        times.append(0.1 * k)
    names = world.core.joint_names
    tol = {n: math.radians(3.0) for n in names}
    goal = TrajectoryGoal(tuple(names), tuple(points), tuple(times), path_tolerance=tol,
                          goal_tolerance=tol)
    lim = world.kin.limits
    traj = validate(goal, names, q0, lim.lower, lim.upper, world.now)
    run = world.core.submit_trajectory(traj)
    assert 2 <= len(run.jobs) < 15
    worst = [0.0]

    def track():
        s = world.status()
        if s.joints_valid:
            worst[0] = max(worst[0], path_deviation(traj, s.joints)[0])
        return run.done
    world.run_until(track, 60.0, "trajectory done")
    assert run.success and run.points_done() == 30
    logged = [tuple(e.target) for e in world.log.entries()]
    assert logged == [job.preview.commands[0].values for job in run.jobs]     # each once, in order
    assert worst[0] <= 1.0, worst[0]                     # within the path tolerance throughout
    final = world.status().joints
    assert max(abs(a - b) for a, b in zip(final, points[-1])) <= math.radians(3.0)


def test_requests_plan_one_at_a_time(world):
    """Requests plan in their callers' threads (one per goal); only one planner runs at a time, so
    many goals at once cannot starve the bus thread of the interpreter lock."""
    import threading
    import time as _time
    world.ready()
    planner = world.core.previewer
    plan = planner.plan
    running, peak, lock = [0], [0], threading.Lock()

    def counting(*args, **kwargs):
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        try:
            _time.sleep(0.02)         # a planner holding its turn while others arrive
            return plan(*args, **kwargs)
        finally:
            with lock:
                running[0] -= 1
    planner.plan = counting
    try:
        threads = [threading.Thread(target=world.core.preview, args=(lin(FAR),)) for _ in range(6)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30.0)
    finally:
        planner.plan = plan
    assert not any(t.is_alive() for t in threads)
    assert peak[0] == 1


def test_the_record_is_stamped_with_the_time_the_controller_took_it(world):
    """record_time (what joint_states carry): the reply's arrival less its time on the wire (an SD2
    frame of 9 characters + the 14-byte record, 11 bits each at 19.2 kbit/s); a cycle without a new
    record keeps the stamp (nothing is re-published under a new one)."""
    status = world.ready()
    wire = (9 + 14) * 11 / 19200.0
    assert world.core.link.reply_time == pytest.approx(wire)
    assert status.record_time == pytest.approx(status.feedback_time - wire)
    stamps = set()
    for _ in range(10):
        world.run_for(world.bus_period)
        s = world.status()
        assert s.record_time == pytest.approx(s.feedback_time - wire)
        stamps.add(s.record_time)
    assert len(stamps) >= 8          # a new record nearly every bus cycle, each with its own stamp
    world.freeze(0.2)                # no bus cycle: the status keeps its record and stamp
    assert world.status().record_time == max(stamps)


def _longer_upper_arm(dz):
    """The model with the upper arm (joint_2 -> joint_3) ``dz`` metres longer: a robot the driver's
    model does not match."""
    import xml.etree.ElementTree as ET
    from panasonic_vr006l_support.description import render_urdf
    from vr_driver.kinematics.solver import Kinematics
    root = ET.fromstring(render_urdf())
    origin = next(j for j in root.findall("joint") if j.get("name") == "joint_3").find("origin")
    x, y, z = (float(v) for v in origin.get("xyz").split())
    origin.set("xyz", "%r %r %r" % (x, y, z + dz))
    return Kinematics.from_urdf_string(ET.tostring(root, encoding="unicode"))


def test_the_model_is_checked_against_the_controller_at_every_connection(kin, caplog):
    """v2 reports joints and pose: at each connection the driver compares the pose with its own FK
    of the joints. The same model: within the wire's resolution, no warning. A controller whose
    upper arm is 10 mm longer: a warning naming the size, in the status (-> /diagnostics)."""
    same = World(kin, protocol="v2")
    same.ready()
    check = same.status().model_check
    assert check is not None and check.ok and check.position_mm < 0.05 and check.angle_deg < 0.01
    other = World(kin, protocol="v2", controller_kin=_longer_upper_arm(0.010))
    with caplog.at_level("WARNING", logger="vr_driver.driver"):
        other.ready()
    check = other.status().model_check
    assert check is not None and not check.ok and 5.0 < check.position_mm < 10.5, check
    assert "are not the robot's" in check.describe()
    assert any("model check" in r.getMessage() and "%.3f mm" % check.position_mm in r.getMessage()
               for r in caplog.records)
    first = check.session
    other.link.cut = True                                  # a new connection is checked again
    other.run_until(lambda: not other.status().connected, 2.0, "link lost")
    other.link.cut = False
    other.ready(10.0)
    assert other.status().model_check.session > first


def test_a_protocol_without_joints_has_no_model_check(world):
    world.ready()
    assert world.status().model_check is None


def test_the_driver_parameter_model_makes_the_true_robot_the_drivers_model():
    """``model`` = the controller's own robot (as calibrate fit --write would give it): the driver's
    FK of the reported joints meets the reported pose (the model check passes); with the package's
    model it does not."""
    import os
    from vr_driver.kinematics.solver import Kinematics
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data",
                        "true_model_example.yaml")
    true_kin = Kinematics.from_true_model(path)
    calibrated = World(None, {"model": path}, protocol="v2", controller_kin=true_kin)
    assert calibrated.core.kin is not true_kin
    calibrated.ready()
    check = calibrated.status().model_check
    assert check is not None and check.ok and check.position_mm < 0.05, check
    default = World(None, protocol="v2", controller_kin=true_kin)
    default.ready()
    check = default.status().model_check
    assert check is not None and not check.ok, check


def test_status_after_waits_for_a_snapshot_of_a_later_iteration(world):
    """A thread woken by a job's end (set inside the sequencer's step, before that step's snapshot)
    asks for the status of a later iteration: status_after returns only once the bus loop has taken
    one (here the test's one thread steps the loop while another waits)."""
    import threading
    t = world.now + 1e-6                     # after the last snapshot
    got = []
    waiter = threading.Thread(target=lambda: got.append(world.core.bus_loop.status_after(t, 10.0)))
    waiter.start()
    waiter.join(0.2)
    assert waiter.is_alive() and got == []   # no later snapshot yet: still waiting
    world.run_for(2.0 / world.params.cycle_rate)
    waiter.join(5.0)
    assert got == [True]
    assert world.core.status().time >= t
    assert world.core.bus_loop.status_after(world.now + 1.0, 0.05) is False    # none: it gives up
