"""Protocol v3 (Cartesian targets streamed with a look-ahead, the G2 as it is) stepped with a fake
clock, in one thread: DriverCore with the StreamSequencer, our DP master, the in-memory link, the
virtual controller's v3 slave and program (its own IK, a ring, an interpreter look-ahead) and the
streaming arm (_world.World(protocol="v3")). A planned trajectory runs as planned, each target
exactly once, one new target per bus cycle; the interpreter look-ahead 0 stops at every point and
the driver says so; a target the controller would solve in another configuration is refused
before anything is sent."""
from __future__ import annotations

import math

import pytest

from vr_driver.controller.arm import Outcome
from vr_driver.driver import DriverError
from vr_driver.driver.checks.stream_prep import CONFIGURATION_TOLERANCE
from vr_driver.driver.motion.jobs import StreamPoint
from vr_driver.protocol.registry import get
from vr_driver.protocol.v2 import StreamState

from _world import World
from test_streaming_stepped import record, smooth_path, trajectory

DEG = math.pi / 180.0
V3 = get("v3")


@pytest.fixture
def world(kin):
    w = World(kin, protocol="v3")
    w.ready()
    return w


def run_path(world, n=30, duration=4.0):
    q0 = tuple(world.arm.joints)
    times, points = smooth_path(q0, n=n, duration=duration)
    traj = trajectory(world, times, points)
    t_submit = world.now
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    samples = record(world, job)
    return traj, run, job, samples, world.now - t_submit


def test_a_planned_trajectory_runs_as_planned(world):
    traj, run, job, samples, elapsed = run_path(world)
    assert job.result.success, job.result.reason
    assert run.success and run.points_done() == len(traj.positions) - 1
    assert elapsed <= 1.10 * traj.duration + 0.3, elapsed
    assert job.gaps == 0 and all(s is not StreamState.WAITING for _t, _q, s in samples)
    # each target taken once, in order, as the MOVEP of its pose rounded to the wire
    entries = world.log.entries()
    assert [e.seq for e in entries] == job.seqs and len(set(job.seqs)) == len(job.points)
    assert all(e.move_type == "MOVEP" for e in entries)
    assert [tuple(e.target) for e in entries] == [
        tuple(round(v / u) for v, u in zip(p.pose.as_tuple(), (0.1,) * 3 + (0.01,) * 3)) for p in job.points]
    assert [e.outcome for e in entries][-1] is Outcome.EXECUTED
    # the end: the planned joints within what the wire's rounding costs (protocol.target_error)
    off = max(abs(a - b) for a, b in zip(world.arm.joints, traj.positions[-1]))
    assert off <= V3.target_error, off / DEG
    # joint_states (the IK of the reported pose) agree with the arm at rest
    s = world.status()
    assert max(abs(a - b) for a, b in zip(s.joints, world.arm.joints)) <= 0.05 * DEG
    assert s.counters.targets_sent == s.counters.targets_done == len(job.points)


def test_one_new_target_per_bus_cycle(world):
    """A one-slot record would bring a target every second cycle if the master waited for each
    acknowledgement (it comes a cycle late); with protocol.send_ahead 2 the ring fills one target
    per cycle."""
    assert V3.look_ahead_slots == 1 and V3.send_ahead == 2
    traj, run, job, _samples, _elapsed = run_path(world, n=40, duration=4.0)
    assert job.result.success, job.result.reason
    taken = [e.taken_time for e in world.log.entries()]
    period = world.bus_period
    # the first four fill the empty ring (ring_size 4): one per bus cycle, not one per two
    first = taken[:4]
    assert first[-1] - first[0] <= 3.5 * period, [round((t - first[0]) / period, 2) for t in first]


def test_interpreter_lookahead_0_stops_at_every_point_and_says_so(kin):
    """A G2 whose interpreter reads the next MOVE only after the current one ended: the arm stops at
    each point (the controller's log: every target executed, none blended). Every target still runs
    once, in order, and the goal succeeds; the stops cost time."""
    world = World(kin, protocol="v3", interpreter_lookahead=0)
    world.ready()
    traj, run, job, samples, elapsed = run_path(world, n=10, duration=3.0)
    assert job.result.success, job.result.reason
    entries = world.log.entries()
    assert [e.seq for e in entries] == job.seqs and len(set(job.seqs)) == len(job.points)
    assert all(e.outcome is Outcome.EXECUTED for e in entries)       # none blended: a stop at each
    assert elapsed > traj.duration                                   # the stops cost time
    lookahead_1 = World(kin, protocol="v3", interpreter_lookahead=1)
    lookahead_1.ready()
    _traj, _run, job1, _samples, elapsed1 = run_path(lookahead_1, n=10, duration=3.0)
    assert job1.result.success and elapsed1 < elapsed
    assert {e.outcome for e in lookahead_1.log.entries()[:-1]} == {Outcome.BLENDED}


def test_a_target_in_another_configuration_is_refused_before_anything_is_sent(world):
    """The wrist flipped (J4 + 180 deg, J5 negated, J6 + 180 deg) is the same pose: the controller,
    solving nearest the previous target, would run the unflipped joints, not the planned ones."""
    q = (0.2, 0.3, -0.2, 0.3, 0.5, 0.4)
    flipped = (0.2, 0.3, -0.2, 0.3 + math.pi, -0.5, 0.4 + math.pi)
    assert world.core.kin.fk_pose(q).distance_to(world.core.kin.fk_pose(flipped))[0] < 1e-6
    points = [StreamPoint(q, 100, 3, 1.0, 1), StreamPoint(flipped, 100, 0, 2.0, 2)]
    assert world.core.cartesian_points(q, points[:1])[0].pose is not None
    with pytest.raises(DriverError) as err:
        world.core.cartesian_points(q, points)
    text = str(err.value)
    assert "point 2 of 2" in text and "another configuration" in text
    assert "joint_4" in text or "joint_6" in text, text                   # 180 deg off the plan
    assert "nothing was sent" in text
    assert CONFIGURATION_TOLERANCE < math.pi / 2


def test_a_flipping_trajectory_runs_through_the_wrist_singularity_to_the_flipped_wrist(world):
    """A straight joint move to the flipped wrist (joint_4 and joint_6 + 180 deg, joint_5 negated):
    its last point is the start's pose again, so thinned to its end the controller would stay where
    it is. The stream keeps the planned points the controller needs to reach each next one as
    planned (stream_thinning.split_long with the controller's solution), crosses joint_5 = 0 and ends on
    the flipped wrist."""
    q0 = tuple(world.arm.joints)
    flip = (q0[0], q0[1], q0[2], q0[3] + math.pi, -q0[4], q0[5] + math.pi)
    lim = world.kin.limits
    if not all(lo <= v <= hi for v, lo, hi in zip(flip, lim.lower, lim.upper)):
        pytest.skip("the flipped wrist is outside the joint limits at this start")
    n = 20
    points = [tuple(a + (b - a) * k / n for a, b in zip(q0, flip)) for k in range(1, n + 1)]
    times = [4.0 * k / n for k in range(1, n + 1)]
    traj = trajectory(world, times, points)
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    assert len(job.points) >= 3 and job.points[-1].index == n
    # thinned to its end alone (no planned point kept between), the stream would be refused
    with pytest.raises(DriverError) as err:
        world.core.cartesian_points(q0, job.points[-1:])
    assert "another configuration" in str(err.value)
    record(world, job)
    assert job.result.success, job.result.reason
    assert max(abs(a - b) for a, b in zip(world.arm.joints, flip)) <= V3.target_error


def test_a_wrist_turn_past_half_a_turn_is_streamed_in_steps_the_controller_solves_as_planned(world):
    """A straight joint move turning joint_6 by 270 deg thins to one segment; its end pose is the
    start's turned by -90 deg, which the controller (nearest the previous target) would run. The
    stream puts planned points back so no joint moves more than CARTESIAN_MAX_STEP between two
    targets: accepted, run, and the arm ends 270 deg on."""
    from vr_driver.driver.checks.stream_prep import CARTESIAN_MAX_STEP
    q0 = tuple(world.arm.joints)
    turn = 1.5 * math.pi
    end = q0[:5] + (q0[5] + turn,)
    lim = world.kin.limits
    if not lim.lower[5] <= end[5] <= lim.upper[5]:
        end = q0[:5] + (q0[5] - turn,)
    n = 40
    times = [6.0 * k / n for k in range(1, n + 1)]
    points = [tuple(a + (b - a) * k / n for a, b in zip(q0, end)) for k in range(1, n + 1)]   # one straight line
    run = world.core.submit_trajectory(trajectory(world, times, points))
    job = run.jobs[0]
    steps = [max(abs(a - b) for a, b in zip(p.joints, q)) for p, q in
             zip(job.points, [q0] + [p.joints for p in job.points[:-1]])]
    assert len(job.points) >= 4 and max(steps) <= CARTESIAN_MAX_STEP + 1e-9, [round(s / DEG, 1) for s in steps]
    record(world, job)
    assert job.result.success, job.result.reason
    assert abs(world.arm.joints[5] - end[5]) <= V3.target_error, (world.arm.joints[5] / DEG, end[5] / DEG)


def test_the_commanded_path_is_searched_with_the_reported_pose_in_mm_and_deg(world, monkeypatch):
    """Where the reported pose lies on the commanded path (tracking.CommandedPath: the stream's
    points as the controller solves them), the joints come from the path there (it matters where
    rounding pushes a pose past a reach or joint limit, or near the wrist singularity). The plan's
    lookup was once made with the record's raw integers (0.1 mm / 0.01 deg on v3), which never lay
    near the plan: every lookup missed."""
    from vr_driver.driver.joints.tracking import CommandedPath
    calls = []
    original = CommandedPath.locate

    def locate(self, position, rotation):
        found = original(self, position, rotation)
        calls.append((tuple(position), found))
        return found
    monkeypatch.setattr(CommandedPath, "locate", locate)
    _traj, run, job, _samples, _elapsed = run_path(world)
    assert job.result.success, job.result.reason
    assert calls
    reported = world.status().pose.as_tuple()
    assert max(abs(a - b) for a, b in zip(calls[-1][0], reported[:3])) < 1.0      # mm, not 0.1 mm
    hits = sum(1 for _v, found in calls if found is not None)
    assert hits >= 0.9 * len(calls), (hits, len(calls))


def test_a_move_to_where_the_arm_already_is_runs_as_one_target(world):
    """(It once sent a point without a pose: the bus thread raised and dropped the link.)"""
    from vr_driver.driver import MoveRequest
    from vr_driver.poses import MoveType
    here = world.status().pose
    job = world.core.submit(MoveRequest(MoveType.PTP, here))
    result = world.finish(job)
    assert result.success, result.reason
    assert world.status().counters.targets_sent == 1 and world.core.link.counters.losses == 0
    assert [e.move_type for e in world.log.entries()] == ["MOVEP"]
