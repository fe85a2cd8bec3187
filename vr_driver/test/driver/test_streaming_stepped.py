"""Protocol v2 streaming stepped with a fake clock, in one thread: DriverCore with the
StreamSequencer, our DP master, the in-memory link, the virtual controller's v2 slave, program and
streaming arm (_world.World(protocol="v2")). A planned trajectory runs as planned: on time, on
path, without stops, each target exactly once -- and stops, cuts and replacements keep the rules.
"""
from __future__ import annotations

import math

import pytest

from vr_driver.driver import JobPhase, LinkState, MoveRequest, SubmitMode
from vr_driver.driver.bus_loop import END_POLL_PERIOD
from vr_driver.driver.motion.stream_points import _motion, corner_levels, corner_rounding, stream_points, stream_speeds
from vr_driver.driver.motion.stream_thinning import thin_timed
from vr_driver.driver.motion.streaming import END_LEAD, END_WATCH, seq_offset
from vr_driver.driver.motion.trajectories import TrajectoryGoal, validate
from vr_driver.poses import ControllerPose, MoveType
from vr_driver.protocol.v2 import SEQ_MAX, StreamState, blend_window
from vr_driver.controller.arm import Outcome

from _world import World

FAR = ControllerPose(1000, -600, 800, 0, 45, 0)
DEG = math.pi / 180.0


@pytest.fixture
def world(kin):
    w = World(kin, protocol="v2")
    w.ready()
    return w


def smooth_path(q0, n=30, duration=3.0, amp=(0.5, 0.25, -0.3, 0.6, 0.4, 0.8)):
    """A curved planner-like path of ``n`` points after ``q0``: each joint on its own curve, timed
    with a smooth start and stop (zero speed at both ends)."""
    times, points = [], []
    for k in range(1, n + 1):
        u = k / n
        s = u * u * (3.0 - 2.0 * u)                       # smoothstep: a planner's ramp up and down
        points.append(tuple(q + a * (math.sin(0.5 * math.pi * s) + 0.3 * math.sin(3 * math.pi * s))
                            / 1.0 for q, a in zip(q0, amp)))
        times.append(duration * u)
    return times, points


def trajectory(world, times, points, **kw):
    names = world.core.joint_names
    lim = world.kin.limits
    goal = TrajectoryGoal(tuple(names), tuple(points), tuple(times), **kw)
    return validate(goal, names, world.status().joints, lim.lower, lim.upper, world.now)


def taken_seqs(world):
    return [e.seq for e in world.log.entries()]


def record(world, job, timeout=30.0):
    """Run until ``job`` is done, sampling the arm every tick: [(t, joints, state)]."""
    samples = []

    def done():
        samples.append((world.now, tuple(world.arm.joints), world.arm.state))
        return job.done
    world.run_until(done, timeout, "job %d done" % job.id)
    return samples


# ------------------------------------------------------------------------------ pure functions
def test_split_long_puts_planned_points_back_where_a_joint_would_turn_too_far():
    from vr_driver.driver.motion.stream_thinning import split_long
    line = [(0.0, 0.1 * k) for k in range(11)]                 # joint 2 turns 1.0 in steps of 0.1
    assert split_long(line, [0, 10], 2.0) == [0, 10]           # within the step: unchanged
    out = split_long(line, [0, 10], 0.35)
    assert out == [0, 3, 6, 9, 10]                             # the farthest point within 0.35 each time
    assert split_long(line, [0, 5, 10], 0.25) == [0, 2, 4, 5, 7, 9, 10]
    wide = [(0.0,), (1.0,), (2.0,)]                            # planned steps wider than max_step stay
    assert split_long(wide, [0, 2], 0.5) == [0, 1, 2]


def test_split_long_puts_planned_points_back_where_the_controller_would_not_reach_the_next():
    """``reaches`` (a Cartesian controller: would it solve the next pose onto the planned joints
    after a target here?) splits a step within ``max_step`` too; a planned step it does not reach
    is sent as planned (the stream check then refuses it in words)."""
    from vr_driver.driver.motion.stream_thinning import split_long
    line = [(0.0, 0.1 * k) for k in range(11)]
    calls = []

    def reaches(a, b):
        calls.append((a, b))
        return abs(a[1] - b[1]) <= 0.45
    assert split_long(line, [0, 10], 2.0, reaches) == [0, 4, 8, 10]
    assert calls                                                # it was asked
    assert split_long(line, [0, 10], 2.0, lambda a, b: True) == [0, 10]
    # not even the next planned point: every planned point goes back (the densest stream; the
    # stream check decides on it)
    assert split_long(line, [0, 10], 2.0, lambda a, b: False) == list(range(11))


def test_split_long_skips_planned_points_the_controller_would_not_reach_to_one_it_would():
    """Across the elbow's stretch: the planned points just past it are solved onto the other branch
    from the last one before it, farther ones are not. With ``times`` the stream skips to the first
    reached one -- dropping a thinned-in point too -- when the straight move over the skipped ones
    stays within ``skip_tolerance`` of each at its planned time; else they stay (the stream check
    says why)."""
    from vr_driver.driver.motion.stream_thinning import split_long
    line = [(0.0, 0.1 * k) for k in range(11)]
    times = [0.1 * k for k in range(11)]
    stretch = 0.45                        # between points 4 and 5

    def reaches(a, b):                    # past the stretch only from 0.25 beyond it
        return not (a[1] < stretch < b[1] and b[1] - stretch < 0.25)
    # 4 -> 5 and 4 -> 6 are not reached, 4 -> 7 is: points 5 and 6 (5 thinned in) are skipped
    assert split_long(line, [0, 5, 10], 2.0, reaches, times, skip_tolerance=0.01) == [0, 4, 7, 10]
    # without the times, or with the skipped points off the straight move: as before, planned steps kept
    assert split_long(line, [0, 5, 10], 2.0, reaches) == [0, 4, 5, 10]
    bent = [(0.0, 0.1 * k) if k != 6 else (0.05, 0.6) for k in range(11)]
    assert split_long(bent, [0, 5, 10], 2.0, reaches, times, skip_tolerance=0.01) == [0, 4, 5, 10]
    assert split_long(bent, [0, 5, 10], 2.0, reaches, times, skip_tolerance=0.1) == [0, 4, 7, 10]
    # a pause of the plan among the points it would skip: kept (the arm holds there)
    held = line[:6] + [line[5]] + line[6:]
    held_times = times[:6] + [0.55] + [t + 0.05 for t in times[6:]]
    assert split_long(held, [0, 5, 6, 11], 2.0, reaches, held_times, skip_tolerance=0.1) == [0, 4, 5, 6, 11]
    # timed unevenly (the arm speeding up out of the stretch): the timing counts, not only the path
    slow = [0.0, 0.1, 0.2, 0.3, 0.4, 0.6, 0.65, 0.7, 0.8, 0.9, 1.0]
    assert split_long(line, [0, 5, 10], 2.0, reaches, slow, skip_tolerance=0.01) == [0, 4, 5, 10]


def test_thin_timed_keeps_ends_and_timing():
    times = [0.0, 1.0, 2.0, 3.0, 4.0]
    line = [(0.1 * k,) * 6 for k in range(5)]                  # constant speed: nothing in between
    assert thin_timed(times, line, 1e-6) == [0, 4]
    accel = [(0.1 * k * k,) * 6 for k in range(5)]             # speeding up: the timing needs points
    assert thin_timed(times, accel, 1e-6) == [0, 1, 2, 3, 4]
    assert thin_timed(times, accel, 0.5) == [0, 4]


def test_thin_timed_keeps_both_ends_of_a_pause_however_short():
    """A pause of the plan (a point where the one before is, later) is a hold: both its samples are
    kept even where the straight move around it would pass within the tolerance (at a large one:
    an 0.01 s pause in a slow move moves the chord by 0.0005 rad)."""
    times = [0.0, 0.5, 1.0, 1.01, 1.5, 2.0]
    path = [(0.0,) * 6, (0.025,) * 6, (0.05,) * 6, (0.05,) * 6, (0.075,) * 6, (0.1,) * 6]
    assert thin_timed(times, path, 0.01) == [0, 2, 3, 5]
    assert thin_timed(times[:3] + times[4:], path[:3] + path[4:], 0.01) == [0, 4]      # no pause: a line


def test_stream_speeds_round_up_and_do_not_drift():
    vmax = (1.0,) * 6
    start = (0.0,) * 6
    # 100 segments of 0.0123 rad in 0.1 s: 12.3 % each; rounding up alone would arrive early
    points = [(0.0123 * k,) * 6 for k in range(1, 101)]
    times = [0.1 * k for k in range(1, 101)]
    speeds = stream_speeds(start, points, times, vmax)
    assert all(1 <= s <= 1000 for s in speeds) and set(speeds) <= {123, 124}
    arrival = sum(0.0123 / (s / 1000.0) for s in speeds)
    assert abs(arrival - 10.0) < 0.01                   # on time at the end, not 0.8 % early
    assert stream_speeds(start, [(1.0,) * 6], [1.0], vmax) == [1000]


def test_stream_points_smooth_all_but_the_last():
    times = [0.0, 1.0, 2.0, 3.0]
    pts = [(0.0,) * 6, (0.3,) * 6, (0.5,) * 6, (0.6,) * 6]
    stream = stream_points(times, pts, (1.0,) * 6, 4, 1e-6, 0.0, corner_tolerance=1.0)
    assert [p.index for p in stream] == [1, 2, 3]
    assert [p.smooth for p in stream] == [4, 4, 0]
    assert [p.speed for p in stream] == [300, 200, 100]
    # the speed changes at both points (0.3 -> 0.2 -> 0.1 rad/s): a tight corner tolerance blends
    # them at the lowest level, never at 0 (the arm would stop there)
    tight = stream_points(times, pts, (1.0,) * 6, 4, 1e-6, 0.0, corner_tolerance=1e-9)
    assert [p.smooth for p in tight] == [1, 1, 0]
    assert [p.smooth for p in stream_points(times, pts, (1.0,) * 6, 0, 1e-6, 0.0)] == [0, 0, 0]


def test_a_sharp_corner_gets_its_neighbouring_planned_points_back():
    """J1 runs 1 rad/s for 1 s, then J2 does (points every 20 ms): thinned to the corner and the end,
    even smooth level 1 would round the corner by 0.36 deg (1 s segments). The planned points 0.1 s
    (min_dt) before and after it come back: the corner's segments, and its blend window, shrink,
    and its rounding stays within the tolerance at level 2."""
    vmax = (1.0,) * 6
    times = [0.02 * k for k in range(101)]
    positions = [(min(t, 1.0), max(t - 1.0, 0.0), 0.0, 0.0, 0.0, 0.0) for t in times]
    tol = 0.1 * DEG
    stream = stream_points(times, positions, vmax, 3, 1e-6, 0.1, corner_tolerance=tol)
    assert [round(p.time, 6) for p in stream] == [0.9, 1.0, 1.1, 2.0]
    assert [p.smooth for p in stream] == [3, 2, 3, 0]
    start = positions[0]
    speeds = [p.speed for p in stream]
    joints = [p.joints for p in stream]
    moves, velocities = _motion(start, joints, speeds, vmax)
    assert corner_rounding(2, moves, velocities, 1) <= tol < corner_rounding(3, moves, velocities, 1)
    # without the points back the corner would be rounded by ~0.36 deg at level 1
    assert corner_rounding(1, [1.0, 1.0], [(1.0, 0, 0, 0, 0, 0), (0, 1.0, 0, 0, 0, 0)], 0) > 3 * tol


def test_a_pause_of_the_plan_is_a_hold_not_a_target():
    """A kept point where the previous one is (the plan pauses): the arm stops exactly at the point
    before (smooth 0), the next target is released when the pause ends and timed from then; a pause
    at the start delays the first target, one at the end just ends the stream."""
    vmax = (1.0,) * 6
    p0, p1, p2 = (0.0,) * 6, (0.3,) * 6, (0.5,) * 6
    stream = stream_points([0.0, 1.0, 2.0, 3.0], [p0, p1, p1, p2], vmax, 3, 1e-6, 0.0)
    assert [(p.joints, p.smooth, p.release, p.index) for p in stream] == [(p1, 0, 0.0, 1), (p2, 0, 2.0, 3)]
    assert [p.speed for p in stream] == [300, 200]          # 0.2 rad in the 1 s after the pause
    start = stream_points([0.0, 1.0, 2.0], [p0, p0, p1], vmax, 3, 1e-6, 0.0)
    assert [(p.joints, p.release, p.speed) for p in start] == [(p1, 1.0, 300)]
    end = stream_points([0.0, 1.0, 2.0], [p0, p1, p1], vmax, 3, 1e-6, 0.0)
    assert [(p.joints, p.smooth, p.release) for p in end] == [(p1, 0, 0.0)]


def test_corner_levels_keep_the_rounding_within_the_tolerance():
    """The level at a point is the largest (up to the configured one) whose blend rounds the corner
    there by at most the tolerance (|v1 - v2| * window / 8, every joint)."""
    vmax = (1.0,) * 6
    start = (0.0,) * 6
    # straight on at one speed: nothing to round, the full level
    line = [(0.2 * k,) * 6 for k in range(1, 4)]
    assert corner_levels(start, line, [200, 200, 200], vmax, 5, 1e-9) == [5, 5, 0]
    # J1 runs 0.4 rad/s for 1 s, then J2 does: a corner with a jump of 0.4 rad/s in both joints
    corner = [(0.4, 0.0, 0.0, 0.0, 0.0, 0.0), (0.4, 0.4, 0.0, 0.0, 0.0, 0.0)]
    for tol_deg in (0.05, 0.1, 0.3, 0.5, 1.0, 5.0):
        tol = tol_deg * DEG
        [level, last] = corner_levels(start, corner, [400, 400], vmax, 10, tol)
        assert last == 0 and 1 <= level <= 10
        rounding = [0.4 * blend_window(k, 1.0, 1.0) / 8.0 for k in range(11)]
        assert level == 1 or rounding[level] <= tol, (tol_deg, level)
        assert level == 10 or rounding[level + 1] > tol, (tol_deg, level)


def test_seq_offset_wraps():
    assert seq_offset(5, 5) == 0 and seq_offset(7, 5) == 2
    assert seq_offset(1, SEQ_MAX) == 1 and seq_offset(SEQ_MAX - 1, SEQ_MAX) == SEQ_MAX - 1


# ------------------------------------------------------------------------------ a trajectory
def test_a_planned_trajectory_runs_as_planned(world):
    """30 points over 4 s: on time (<= 1.10 of the plan), never standing still between start and
    end, on the planned path at the same time, each target taken and passed exactly once, the end
    exactly where planned."""
    q0 = tuple(world.arm.joints)
    times, points = smooth_path(q0, duration=4.0)
    traj = trajectory(world, times, points)
    t_submit = world.now
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    samples = record(world, job)
    assert job.result.success, job.result.reason
    assert run.success and run.points_done() == len(traj.positions) - 1
    elapsed = world.now - t_submit
    assert elapsed <= 1.10 * traj.duration, elapsed
    # motion from the first sample that left the start to the last that arrived
    moving = [i for i, (_t, q, _s) in enumerate(samples) if max(abs(a - b) for a, b in zip(q, q0)) > 1e-6]
    t0 = samples[moving[0]][0]
    still = 0.0
    for (ta, qa, _sa), (tb, qb, _sb) in zip(samples[moving[0]:], samples[moving[0] + 1:]):
        if qa == qb and tb <= samples[-1][0] and max(abs(a - b) for a, b in zip(qb, traj.positions[-1])) > 1e-6:
            still += tb - ta
    assert still <= 0.05 * traj.duration, "stood still %.3f s mid-path" % still
    assert all(s is not StreamState.WAITING for _t, _q, s in samples), "a gap in the stream"
    assert job.gaps == 0
    worst = max(max(abs(a - b) for a, b in zip(q, traj.sample(t - t0))) for t, q, _s in samples[moving[0]:])
    # (0.53 deg: the plan's own speed steps at its points, rounded by the blends and the ramps)
    assert worst <= 0.75 * DEG, "%.2f deg from the plan at the same time" % (worst / DEG)
    final = world.arm.joints
    assert max(abs(a - b) for a, b in zip(final, traj.positions[-1])) <= 0.001 * DEG
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs)) == len(job.points)
    assert seqs == job.seqs
    outcomes = [e.outcome for e in world.log.entries()]
    assert outcomes[-1] is Outcome.EXECUTED and set(outcomes[:-1]) <= {Outcome.BLENDED}
    s = world.status()
    assert s.counters.targets_sent == s.counters.targets_done == len(job.points)


def test_a_corner_is_rounded_within_the_path_tolerance(world):
    """J1 then J2 at 0.1 rad/s: the corner's smooth level is lowered from stream_smooth (3 would
    round it by ~0.11 deg) so that the arm passes the corner within stream_path_tolerance
    (0.1 deg), blending through it (never stopping there)."""
    q0 = tuple(world.arm.joints)
    corner = (q0[0] + 0.1,) + q0[1:]
    end = (corner[0], corner[1] + 0.1) + corner[2:]
    traj = trajectory(world, [0.0, 1.0, 2.0], [q0, corner, end])
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    levels = [p.smooth for p in job.points]
    samples = record(world, job)
    assert job.result.success, job.result.reason
    closest = min(max(abs(a - b) for a, b in zip(q, corner)) for _t, q, _s in samples)
    assert 0.0 < closest <= world.params.stream_path_tolerance * DEG, closest / DEG
    assert [e.outcome for e in world.log.entries()] == [Outcome.BLENDED, Outcome.EXECUTED]
    assert levels == [2, 0]


@pytest.mark.parametrize("duration", [1.0, 1.13, 1.27, 1.41, 1.55])
def test_the_result_follows_the_arrival_without_waiting_a_bus_period(world, duration):
    """At 20 Hz the feedback comes every 50 ms; around a stream's planned end the bus polls every
    END_POLL_PERIOD, so the job ends within that (plus one program loop) of the arm's arrival --
    and the fast polling stops END_WATCH after the planned end at the latest."""
    q0 = tuple(world.arm.joints)
    times, points = smooth_path(q0, n=10, duration=duration, amp=(0.2, 0.1, -0.1, 0.2, 0.1, 0.3))
    traj = trajectory(world, times, points)
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    first_bus = len(world.bus_times)
    world.finish(job)
    assert job.result.success, job.result.reason
    arrival = world.log.entries()[-1]
    assert arrival.outcome is Outcome.EXECUTED
    assert world.now - arrival.end_time <= END_POLL_PERIOD + world.loop_period + 1e-9, \
        world.now - arrival.end_time
    # fast cycles only near the end: at most the watch window's worth beyond the 20 Hz ones
    cycles = len(world.bus_times) - first_bus
    span = world.bus_times[-1] - world.bus_times[first_bus]
    assert cycles <= span * world.params.cycle_rate + (END_LEAD + END_WATCH) / END_POLL_PERIOD + 2 * len(job.points)
    world.run_for(1.0)
    idle = [t for t in world.bus_times if t > world.now - 0.9]
    assert len(idle) <= 0.9 * world.params.cycle_rate + 1          # back to the cycle rate


def test_a_late_target_is_a_gap_the_arm_waits_at_the_point_and_it_is_counted(kin):
    """The driver's process stalls for 0.5 s mid-stream (below a 1 s watchdog): the controller runs
    through what it took, stops exactly at the last point it has and waits (WAITING) -- it never
    guesses; the stream goes on when the bus does, ends exactly, and the job counts the gap."""
    world = World(kin, {"watchdog_ms": 1000, "link_timeout": 1.5}, protocol="v2")
    world.ready()
    q0 = tuple(world.arm.joints)
    # a zig-zag in J1 and J2, 0.1 s per segment: no point can be thinned away
    points = [(q0[0] + 0.05 * (k % 2), q0[1] + 0.01 * k) + q0[2:] for k in range(1, 21)]
    times = [0.0] + [0.1 * k for k in range(1, 21)]
    run = world.core.submit_trajectory(trajectory(world, times, [q0] + points))
    job = run.jobs[0]
    assert len(job.points) == 20
    world.run_until(lambda: job.points_done >= 5, 10.0, "5 points passed")
    states = []
    world.frozen = True                     # as World.freeze, watching the arm meanwhile
    end = world.now + 0.5
    while world.now < end:
        world.tick()
        states.append(world.arm.state)
    world.frozen = False
    world.next_bus = world.now
    record(world, job)
    assert job.result.success, job.result.reason
    assert StreamState.WAITING in states
    assert job.gaps == 1
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs)) == len(job.points)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, points[-1])) <= 0.001 * DEG


def paused_job(world, times):
    """A plan from where the arm is to P1 (joint_1 + 0.2 rad), P1 again (a pause), P2 (joint_2 + 0.2
    rad) at ``times``, submitted: (t0, its job, P1, P2)."""
    q0 = tuple(world.arm.joints)
    p1 = (q0[0] + 0.2,) + q0[1:]
    p2 = (p1[0], p1[1] + 0.2) + p1[2:]
    traj = trajectory(world, times, [q0, p1, p1, p2])
    t0 = world.now
    return t0, world.core.submit_trajectory(traj).jobs[0], p1, p2


def test_the_arm_holds_at_a_pause_of_the_plan_for_its_planned_time(world):
    """P1 at 1 s, P1 again at 2 s, P2 at 3 s: the arm stops exactly at P1 and stays there until the
    pause ends (the next target is not even offered before), then reaches P2 on time; each target
    is taken once."""
    t0, job, p1, _p2 = paused_job(world, [0.0, 1.0, 2.0, 3.0])
    assert len(job.points) == 2 and job.points[0].smooth == 0 and job.points[1].release == 2.0
    samples = record(world, job)
    assert job.result.success, job.result.reason
    at_p1 = [t - t0 for t, q, _s in samples if max(abs(a - b) for a, b in zip(q, p1)) <= 0.001 * DEG]
    assert at_p1[0] <= 1.2 and at_p1[-1] >= 2.0, (at_p1[0], at_p1[-1])
    entries = world.log.entries()
    assert [e.outcome for e in entries] == [Outcome.EXECUTED, Outcome.EXECUTED]
    assert entries[1].taken_time - t0 >= 2.0
    assert entries[1].end_time - t0 <= 3.0 + 0.2
    assert taken_seqs(world) == job.seqs


def test_after_a_pause_the_next_target_waits_for_the_arm_to_reach_the_held_point(kin):
    """An arm slower than planned (MOVEP's speed unit half the assumed one) reaches P1 long after the
    pause of the plan there ended: the target after the pause is offered only once P1 is done, so the
    controller takes it with the arm at rest at P1 (what a G2 that solves a target nearest its joints
    when it takes it needs, stream_prep); the arm then goes on to P2. Before, it went out when the
    pause's time was over, with the arm still on its way."""
    w = World(kin, protocol="v2")
    w.arm.speed_scale = 0.5
    w.ready()
    t0, job, _p1, p2 = paused_job(w, [0.0, 1.0, 1.1, 2.0])
    assert job.points[1].release == pytest.approx(1.1)
    record(w, job)
    assert job.result.success, job.result.reason
    first, second = w.log.entries()
    assert first.end_time - t0 > 1.5                          # the slow arm reached P1 late
    assert second.taken_time >= first.end_time                # ... and P2 was taken after that
    assert taken_seqs(w) == job.seqs
    assert max(abs(a - b) for a, b in zip(w.arm.joints, p2)) < 1e-4


def test_joints_and_pose_come_from_the_v2_feedback(world):
    s = world.status()
    assert s.joints_valid and max(abs(a - b) for a, b in zip(s.joints, world.arm.joints)) <= 0.0006 * DEG
    assert abs(s.pose.x - world.arm.pose.x) <= 0.006


def test_a_cartesian_move_is_streamed_and_ends_exactly(world):
    job = world.core.submit(MoveRequest(MoveType.PTP, FAR))
    result = world.finish(job)
    assert result.success, result.reason
    assert max(abs(a - b) for a, b in zip(world.arm.joints, job.preview.joint_target)) <= 0.001 * DEG
    assert abs(result.reached.x - FAR.x) < 0.05 and abs(result.reached.z - FAR.z) < 0.05
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs)) == len(job.points) >= 1


def test_a_lin_move_stays_straight(world):
    job = world.core.submit(MoveRequest(MoveType.LIN, FAR))
    start = world.arm.pose
    samples = []
    world.run_until(lambda: samples.append(world.arm.pose) or job.done, 30.0, "LIN done")
    assert job.result.success, job.result.reason
    a = [start.x, start.y, start.z]
    b = [FAR.x, FAR.y, FAR.z]
    d = [q - p for p, q in zip(a, b)]
    dd = sum(x * x for x in d)
    worst = 0.0
    for p in samples:
        v = [p.x - a[0], p.y - a[1], p.z - a[2]]
        f = max(0.0, min(1.0, sum(x * y for x, y in zip(v, d)) / dd))
        worst = max(worst, math.sqrt(sum((vi - f * di) ** 2 for vi, di in zip(v, d))))
    assert worst < 2.0, "%.2f mm off the line" % worst


# ------------------------------------------------------------------------------ stops and faults
def test_cancel_stops_the_stream_at_rest_and_sends_nothing_more(world):
    times, points = smooth_path(world.status().joints)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    job = run.jobs[0]
    world.run_until(lambda: job.points_done >= 5, 10.0, "5 points done")
    world.core.cancel(job, "test cancel")
    t_cancel = world.now
    world.finish(job)
    assert job.result.phase is JobPhase.CANCELLED and job.result.reason == "test cancel"
    assert not world.arm.moving and job.result.reached is not None
    assert abs(job.result.reached.x - world.arm.pose.x) < 0.01
    n = len(world.log.entries())
    world.run_for(2.0)
    assert len(world.log.entries()) == n, "nothing after the stop"
    late = [e for e in world.log.entries() if e.outcome is not Outcome.STOPPED and e.end_time > t_cancel + 0.5]
    assert not late
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs))


def test_stop_motion_then_a_new_trajectory_from_the_rest_pose(world):
    q0 = world.status().joints
    times, points = smooth_path(q0)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    world.run_until(lambda: run.jobs[0].points_done >= 8, 10.0, "8 points")
    world.core.stop_motion("test stop")
    world.finish(run.jobs[0])
    rest = world.status().joints
    back_times = [1.0, 2.0]
    back = [tuple(0.5 * (a + b) for a, b in zip(rest, q0)), tuple(q0)]
    run2 = world.core.submit_trajectory(trajectory(world, back_times, back))
    result = world.finish(run2.jobs[0])
    assert result.success, result.reason
    assert max(abs(a - b) for a, b in zip(world.arm.joints, q0)) <= 0.001 * DEG
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs))


def test_a_link_cut_fails_the_stream_and_nothing_is_resent(world):
    times, points = smooth_path(world.status().joints)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    job = run.jobs[0]
    world.run_until(lambda: job.points_done >= 5, 10.0, "5 points done")
    world.link.cut = True
    world.finish(job, 5.0)
    assert job.result.phase is JobPhase.FAILED and "link to the controller lost" in job.result.reason
    assert "not re-sent" in job.result.reason
    world.link.cut = False
    world.run_until(lambda: world.status().link is LinkState.CONNECTED, 10.0, "link back")
    world.run_for(2.0)
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs))
    assert not [e for e in world.log.entries() if e.outcome is Outcome.REJECTED]
    assert world.program.accepted_seq == max(seqs)       # nothing taken after the cut
    # the next stream starts (START after the loss) and runs
    q = world.status().joints
    run2 = world.core.submit_trajectory(trajectory(world, [1.0], [tuple(v + 0.05 for v in q)]))
    assert world.finish(run2.jobs[0]).success


def _reconnect_unarmed(world):
    """Cut the line until both ends call the link lost (the controller disarms), then restore it
    with a controller that does not arm on our empty record (a slow or faulty program)."""
    world.link.cut = True
    world.run_until(lambda: world.status().link is not LinkState.CONNECTED and not world.program.armed,
                    5.0, "link lost on both ends")
    world.program.is_idle_command = lambda command: False
    world.link.cut = False
    world.run_until(lambda: world.status().link is LinkState.CONNECTED, 10.0, "link back")
    world.run_for(0.2)
    assert world.program.last_feedback.armed is False


@pytest.mark.parametrize("arms", [True, False])
def test_a_stream_waits_for_the_controller_to_arm(world, arms):
    """After a reconnect the controller reports "not armed" until it saw our empty record: the
    driver holds the stream back (nothing taken, nothing refused) for up to accept_timeout. When it
    arms, the stream runs; when it never does, the stream goes out and its NOT_ARMED refusal ends the
    goal with the reason."""
    _reconnect_unarmed(world)
    q = world.status().joints
    run = world.core.submit_trajectory(trajectory(world, [1.0], [tuple(v + 0.05 for v in q)]))
    job = run.jobs[0]
    entries = len(world.log.entries())
    world.run_for(0.8 * world.params.accept_timeout)
    assert len(world.log.entries()) == entries and not job.done       # held back, not refused
    if arms:
        del world.program.is_idle_command                           # the class's own: arms now
        assert world.finish(job).success
    else:
        result = world.finish(job)
        assert not result.success and "NOT_ARMED" in result.reason
        assert [e.outcome for e in world.log.entries()[entries:]] == [Outcome.REJECTED]


def test_a_new_path_replaces_the_rest_of_the_running_one(world):
    q0 = world.status().joints
    times, points = smooth_path(q0)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    world.run_until(lambda: run.jobs[0].points_done >= 6, 10.0, "6 points")
    here = world.status().joints
    run2 = world.core.submit_trajectory(trajectory(world, [1.5, 3.0], [
        tuple(0.5 * (a + b) for a, b in zip(here, q0)), tuple(q0)]))
    first = world.finish(run.jobs[0])
    assert first.phase is JobPhase.CANCELLED and "replaced" in first.reason
    result = world.finish(run2.jobs[0])
    assert result.success, result.reason
    assert max(abs(a - b) for a, b in zip(world.arm.joints, q0)) <= 0.001 * DEG
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs))
    old = [e for e in world.log.entries() if e.seq in run.jobs[0].seqs]
    assert len(old) < len(run.jobs[0].points)      # the rest of the old stream was never sent


def test_an_estop_mid_stream_fails_at_rest(world):
    times, points = smooth_path(world.status().joints)
    run = world.core.submit_trajectory(trajectory(world, times, points))
    job = run.jobs[0]
    world.run_until(lambda: job.points_done >= 3, 10.0, "3 points")
    world.arm.set_estop(True)
    world.finish(job, 10.0)
    assert not job.result.success and job.result.phase is JobPhase.FAILED, job.result
    world.arm.set_estop(False)
    seqs = taken_seqs(world)
    assert len(set(seqs)) == len([s for s in seqs if s])


def test_a_queued_move_waits_for_the_stream_and_appends(world):
    job1 = world.core.submit(MoveRequest(MoveType.PTP, FAR))
    job2 = world.core.submit(MoveRequest(MoveType.PTP, ControllerPose(1120, 0, 725, 0, 45, 0)),
                             mode=SubmitMode.APPEND)
    assert world.finish(job1).success
    assert world.finish(job2).success
    seqs = taken_seqs(world)
    assert len(seqs) == len(set(seqs)) == len(job1.points) + len(job2.points)


def test_short_segments_raise_the_thinning_tolerance_up_to_its_limit():
    times = [0.02 * k for k in range(101)]
    pos = [(0.5 * math.sin(2.0 * t),) * 6 for t in times]
    vmax = (2.0,) * 6
    tight = stream_points(times, pos, vmax, 3, 1e-5, 0.0)
    assert tight == stream_points(times, pos, vmax, 3, 1e-5, 0.1, max_tolerance=1e-5)   # capped
    fed = stream_points(times, pos, vmax, 3, 1e-5, 0.1, max_tolerance=0.01)
    assert len(fed) < len(tight)
    kept = [0] + [p.index for p in fed]
    for a, b in zip(kept, kept[1:]):                     # every dropped point within the limit, in time
        for k in range(a + 1, b):
            f = (times[k] - times[a]) / (times[b] - times[a])
            assert abs(pos[a][0] + f * (pos[b][0] - pos[a][0]) - pos[k][0]) <= 0.01 + 1e-12


# ------------------------------------------------------------------------------ the controller's own I/O
def test_controller_outputs_go_out_and_the_gripper_input_follows(world):
    from vr_driver.controller.program_v2 import GRIPPER_DELAY
    world.core.sequencer.outputs = 0x0001                      # output 1: close the gripper
    world.run_until(lambda: world.program.io_outputs == 1, 1.0, "output 1 set")
    t_set = world.now
    world.run_until(lambda: world.status().feedback.inputs & 1, 2.0, "input 1 (closed)")
    assert world.now - t_set >= GRIPPER_DELAY - 1e-9
    assert world.status().feedback.outputs == 1
    world.program.set_input(3, True)
    world.run_until(lambda: world.status().feedback.inputs & 0b100, 1.0, "input 3")
    with pytest.raises(ValueError):
        world.program.set_input(1, True)


def test_controller_outputs_fall_to_safe_on_a_link_loss_and_stay_there(world):
    world.core.sequencer.outputs = 0x0005
    world.run_until(lambda: world.program.io_outputs == 5, 1.0, "outputs set")
    world.link.cut = True
    world.run_until(lambda: world.program.io_outputs == 0, 2.0, "controller outputs safe")
    world.run_until(lambda: world.status().link is not LinkState.CONNECTED, 2.0, "link lost")
    world.link.cut = False
    world.run_until(lambda: world.status().link is LinkState.CONNECTED, 10.0, "link back")
    world.run_for(1.0)
    assert world.core.sequencer.outputs == 0 and world.program.io_outputs == 0   # until set again


@pytest.mark.parametrize("protocol", ["v2", "v3"])
def test_a_joint_path_without_timing_is_refused_naming_the_protocol(kin, protocol):
    """A streaming protocol runs a joint path with its timing: an untimed one is refused in words
    that name the protocol actually in use (v3 takes this path too), and nothing is sent."""
    from vr_driver.driver import DriverError
    w = World(kin, protocol=protocol)
    w.ready()
    q = list(w.core.status().joints)
    q[0] += 0.1
    with pytest.raises(DriverError, match="protocol %s runs a joint path with its timing" % protocol):
        w.core.submit_joint_path(w.core.joint_names, [q])
    assert w.core.status().job is None


def _late(fed, feed, ring, releases=None):
    """The targets of a fed schedule (the hold first, if any) a point of which is reached sooner
    than one ``feed`` after the next target can be in the controller -- worked out apart from
    fed_schedule: one target a ``feed`` after the one before, none before the ring has room (the
    target ``ring`` before it passed), after a pause none before its end (``releases``: target ->
    its release, shifted)."""
    passed = ([fed.lead] if fed.lead else []) + list(fed.times)
    arrive = []
    for k in range(len(passed)):
        a = 0.0 if k == 0 else arrive[-1] + feed
        if ring and k >= ring:
            a = max(a, passed[k - ring])
        if releases and k in releases:
            a = releases[k]
        arrive.append(a)
    return [k for k in range(len(passed) - 1)
            if (not releases or k + 1 not in releases) and passed[k] < arrive[k + 1] + feed - 1e-12]


def test_fed_schedule_reaches_no_point_before_the_next_can_be_there():
    """The plan's first points come faster than the bus (one target every 50 ms): whatever the ring,
    no point is reached before the next can be there (worked out apart: _late), and no segment runs
    faster than planned; a plan dense all along (31 points 50 ms apart, a 62.5 ms feed, a ring of 4)
    too -- there the ring, not the lead, limits what comes ahead, and later points wait. The check
    can fail: the plan as it is, and the plan delayed by a lead too short, are late."""
    from vr_driver.driver.motion.stream_points import Fed, fed_schedule
    feed = 0.05
    times = [0.03, 0.06, 0.09, 0.5, 0.52, 1.0]
    dense = [0.05 * k for k in range(1, 32)]
    for plan, step, ring in [(times, feed, 0), (times, feed, 4), (times, feed, 3), (dense, 0.0625, 4),
                             (dense, 0.0625, 0)]:
        fed = fed_schedule(plan, [False] * len(plan), [0.0] * len(plan), step, ring)
        assert _late(fed, step, ring) == [], (plan, ring, fed)
        for (a, b), (c, d) in zip(zip(plan, plan[1:]), zip(fed.times, fed.times[1:])):
            assert d - c >= b - a - 1e-12
    assert _late(Fed(0.0, times), feed, 4) == [0, 1, 2]
    assert _late(Fed(0.1, [t + 0.1 for t in times]), feed, 4) != []
    # a ring of 4 cannot hold a dense plan's lead: points are held back further on as well
    fed = fed_schedule(dense, [False] * 31, [0.0] * 31, 0.0625, 4)
    assert fed.times[-1] - dense[-1] > fed.lead + 0.1
    # after a pause (the arm held at point 2 until 2.0 s) the ring is empty: the feed starts again
    after = fed_schedule([0.2, 0.4, 2.03, 2.06], [False, True, False, False], [0.0, 0.0, 2.0, 0.0], feed, 4)
    assert after.lead == 0.0 and after.times == pytest.approx([0.2, 0.4, 2.1, 2.13])   # (the last: shifted only)
    assert _late(after, feed, 4, {2: 2.0}) == []


def test_fed_schedule_holds_at_the_start_and_then_keeps_the_plans_own_timing():
    """Where the first points come too soon the stream begins with a hold (``lead``), and every point
    after it keeps its planned time plus the lead: the run is the plan delayed by a constant (a
    trajectory bench's fitted start delay absorbs it) -- not the plan stretched where it came too
    soon. A plan the bus keeps up with, or no feed: unchanged, no hold. v2 (no hold): shifted as
    needed from the first point."""
    from vr_driver.driver.motion.stream_points import Fed, fed_schedule
    feed = 0.05
    times = [0.03, 0.06, 0.09, 0.5, 0.52, 1.0]
    fed = fed_schedule(times, [False] * 6, [0.0] * 6, feed, 4)
    # the hold is the first target: point j (0-based) is target j + 1, the next comes j + 2 feeds
    # after the start, and one feed for the jitter: point 2 needs the most, 5 feeds - 0.09 s
    assert fed.lead == pytest.approx(0.16)
    assert fed.times == pytest.approx([t + fed.lead for t in times])
    assert fed_schedule([0.2, 0.4, 0.6], [False] * 3, [0.0] * 3, feed, 4) == Fed(0.0, [0.2, 0.4, 0.6])
    assert fed_schedule(times, [False] * 6, [0.0] * 6, 0.0, 4) == Fed(0.0, times)
    shifted = fed_schedule(times, [False] * 6, [0.0] * 6, feed, 0, hold=False)
    assert shifted.lead == 0.0 and shifted.times == pytest.approx([0.1, 0.15, 0.2, 0.61, 0.63, 1.11])


def test_a_stream_that_needs_a_lead_begins_with_a_hold_just_off_its_start():
    """The stream of a plan whose first samples come faster than the bus: its first target is the
    hold -- HOLD_CREEP toward the first point in the joint that moves most, an exact stop, at the speed
    that takes the lead -- and the planned points follow at their planned times plus the lead."""
    from vr_driver.driver.motion.stream_points import HOLD_CREEP, stream_points, stream_speeds
    vmax = (3.0,) * 6
    start = (0.0,) * 6
    times = [0.0, 0.03, 0.06, 0.09, 0.3, 0.5, 0.7, 0.9]      # (a curve: every sample kept)
    positions = [(2.0 * t * t,) + (0.0,) * 5 for t in times]
    plain = stream_points(times, positions, vmax, 5, 1e-6, 0.01)
    fed = stream_points(times, positions, vmax, 5, 1e-6, 0.01, feed=0.05, ring=4)
    assert not any(p.hold for p in plain)
    hold, rest = fed[0], fed[1:]
    assert hold.hold and hold.smooth == 0 and hold.index == 0 and hold.time == 0.0
    lead = hold.fed
    assert lead >= 0.1 - 1e-12                                       # at least two feeds
    assert hold.joints[0] == pytest.approx(HOLD_CREEP, rel=0.5) and hold.joints[1:] == start[1:]
    # its speed makes the creep last the lead (a whole wire speed: exactly)
    assert stream_speeds(start, [hold.joints], [lead], vmax) == [hold.speed]
    assert hold.joints[0] / (vmax[0] * hold.speed / 1000.0) == pytest.approx(lead)
    assert [p.joints for p in rest] == [p.joints for p in plain]
    assert [p.fed for p in rest] == pytest.approx([p.time + lead for p in plain])
    assert [p.time for p in rest] == [p.time for p in plain]


def test_the_holds_speed_is_the_nearest_whole_step():
    """A hold of hundredths of a degree runs at 0.1-1 %: its speed is the nearest whole 0.1 % step
    (hold_speed), not the step above as a segment's (stream_speeds) -- a 1.02 would become 2 and the
    hold half as long; where the controller's solution moves more (another joint_4 / joint_6 split
    near joint_5 = 0), the speed is as much higher, so that the hold still lasts its lead."""
    from vr_driver.driver.motion.stream_points import hold_speed, stream_speeds
    vmax = (2.0,) * 6
    start = (0.0,) * 6
    lead = 0.15
    creep = (1.02 * 0.001 * 2.0 * lead,) + (0.0,) * 5           # 1.02 steps of 0.1 % in ``lead``
    assert hold_speed(start, creep, lead, vmax) == 1
    assert stream_speeds(start, [creep], [lead], vmax) == [2]
    split = (creep[0], 0.0, 0.0, 0.01, 0.0, -0.01)               # the sum kept, the split 0.01 rad off
    assert hold_speed(start, split, lead, vmax) == round(1000.0 * 0.01 / 2.0 / lead)
    assert hold_speed(start, start, lead, vmax) == 1 and hold_speed(start, creep, 0.0, vmax) == 1000
