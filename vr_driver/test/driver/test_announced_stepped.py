"""What the driver says before a move (vr_driver.driver.motion.announced) is what the move does (issue 46,
part 4): the time and the TCP's top speed DriverCore.announce gives for a planned path agree within
10 % with the run on the stepped world -- v3 on the plan's timing, v1 at the robot program's own speed
(the virtual G2's program_speed, both sides of the assumption: the documented 10 m/min and twice
that), its stops included; a velocity scaling v1 cannot honour is said in words. Fake clock, one
thread."""
from __future__ import annotations

import math
import re

import pytest

from vr_driver.controller.options import SimOptions
from vr_driver.controller.simulator import SimError
from vr_driver.driver.motion.announced import STREAM_LATENCY_CYCLES, scaling_words
from vr_driver.kinematics.preview import at_tcp_speed, peak_tcp_speed
from vr_driver.protocol.v1 import PROGRAM_PATH_SPEED, PROGRAM_SPEED
from vr_driver.params import ControllerFacts

from _world import World
from test_wire_supervision_stepped import validated

AGREE = 0.10


def plan_from(q0, reach):
    """A 2 s planned path of 11 points from ``q0``: joint_1..3 by ``reach`` rad (and less)."""
    q1 = (q0[0] + reach, q0[1] + reach / 2.0, q0[2] - reach / 3.0) + tuple(q0[3:])
    n = 10
    times = [2.0 * k / n for k in range(n + 1)]
    return times, [tuple(a + (b - a) * k / n for a, b in zip(q0, q1)) for k in range(n + 1)]


def paced_plan(kin, plan):
    """v3 on the paced 19.2 kbit/s line, the arm at rest at START: (the world, the ``plan`` from there
    (q0 -> (times, points)) with its start, what the driver says before it runs)."""
    from _paced import PacedWorld
    from test_wire_supervision_stepped import START
    world = PacedWorld(kin, protocol="v3", initial_pose=kin.fk_pose(START))
    world.ready()
    world.run_for(1.0)
    q0 = tuple(world.status().joints)
    times, points = plan(q0)
    times, points = [0.0] + times, [q0] + points
    return world, times, points, world.core.announce(times, points)


def run(world, times, points):
    """Submit the plan as joint_trajectory_action does and step to its end: (time from the first target
    on the wire to the end, the arm's top TCP speed [mm/s] sampled every program loop)."""
    traj = validated(world, times[1:], points[1:])
    run = world.core.submit_trajectory(traj, started=world.now)
    last = [world.now, world.kin.fk_pose(world.arm.joints)]
    top = [0.0]

    def sample():
        now, pose = world.now, world.kin.fk_pose(world.arm.joints)
        if now - last[0] >= 0.02:
            dp, _ = pose.distance_to(last[1])
            top[0] = max(top[0], dp / (now - last[0]))
            last[:] = [now, pose]
        return run.done
    world.run_until(sample, 60.0, "the run")
    assert run.success, [j.result for j in run.jobs]
    ended = max(job.ended_at for job in run.jobs)
    return ended - run.first_sent, top[0]


@pytest.mark.parametrize("speeds", [(PROGRAM_SPEED, PROGRAM_PATH_SPEED), (2 * PROGRAM_SPEED, 2 * PROGRAM_PATH_SPEED)])
def test_v1_runs_at_the_program_speed_it_announces(kin, speeds):
    world = World(kin, {"controller": {"program_speed": speeds[0], "program_path_speed": speeds[1]}}, protocol="v1",
                  program_speeds=speeds)
    world.ready()
    world.run_for(0.3)
    times, points = plan_from(world.status().joints, 0.4)
    said = world.core.announce(times, points)
    assert said.program
    assert said.top_speed == pytest.approx(speeds[0] * 1000.0 / 60.0, rel=1e-6)       # the program's MOVEP speed
    assert "MOVEP %g m/min" % speeds[0] in said.words and "not a plan's timing" in said.words
    took, top = run(world, times, points)
    assert took == pytest.approx(said.duration, rel=AGREE), (took, said.words)
    assert top == pytest.approx(said.top_speed, rel=AGREE)
    if speeds[0] == PROGRAM_SPEED:    # the plan's own timing (2 s) is not what v1 runs: at 10 m/min it takes longer
        assert took > (1.0 + AGREE) * times[-1]


def test_v3_runs_the_plans_timing_it_announces(kin):
    world = World(kin, protocol="v3")
    world.ready()
    world.run_for(0.3)
    times, points = plan_from(world.status().joints, 0.4)
    said = world.core.announce(times, points)
    latency = STREAM_LATENCY_CYCLES * world.core.bus_cycle()     # to the arm and back: a few cycles
    assert not said.program and said.duration == pytest.approx(times[-1] + latency, abs=1e-9)
    assert said.words.startswith("protocol v3 runs the plan's timing: %.2f s (the plan's 2.00 s and the bus's 3 "
                                 "cycles to the arm and back), the TCP at most" % said.duration)
    took, top = run(world, times, points)
    assert took == pytest.approx(said.duration, rel=AGREE)
    assert top == pytest.approx(said.top_speed, rel=AGREE)
    assert scaling_words(said, 0.1, True, said.top_speed) == ""            # v3 honours it


def test_a_velocity_scaling_v1_cannot_honour_is_said_in_words(kin):
    world = World(kin, protocol="v1")
    world.ready()
    world.run_for(0.3)
    times, points = plan_from(world.status().joints, 0.4)
    said = world.core.announce(times, points)
    words = scaling_words(said, 0.1, True, 264.0)
    assert words == ("velocity scaling 0.1 (the driver's default) does not apply on this protocol: the robot "
                     "program's speed does (the TCP at most 167 mm/s, slower than the plan's 264 mm/s)")
    assert "faster than the plan's 80 mm/s" in scaling_words(said, 0.05, False, 80.0)


def test_a_move_at_the_program_speed_never_exceeds_it_and_never_runs_faster_than_the_arm(kin, planner):
    home = tuple(kin.named_states["home"])
    far = planner.ptp_joints(home, (home[0] + 0.8,) + tuple(home[1:]))
    slowed = at_tcp_speed(far, 100.0)
    assert peak_tcp_speed(slowed) == pytest.approx(100.0, rel=1e-9)
    assert slowed.duration > far.duration and slowed.positions is far.positions
    assert at_tcp_speed(far, 1e6) is far and at_tcp_speed(far, None) is far


def test_the_program_speeds_are_options_of_the_virtual_g2_and_facts_of_the_driver():
    options = SimOptions()
    assert (options.program_speed, options.program_path_speed) == (PROGRAM_SPEED, PROGRAM_PATH_SPEED) == (10.0, 5.0)
    assert SimOptions.from_mapping({"program_speed": 30, "program_path_speed": 2.5}).program_speed == 30.0
    for bad in (0, -1, math.nan, "fast", 2000):
        with pytest.raises(SimError, match="program_speed must be a finite number in"):
            SimOptions(program_speed=bad)
    facts = ControllerFacts()
    assert (facts.program_speed, facts.program_path_speed) == (PROGRAM_SPEED, PROGRAM_PATH_SPEED)
    assert ControllerFacts.from_dict({"program_speed": 20}, ()).program_speed == 20.0


def test_v3_says_the_time_the_bus_adds_to_a_plan_whose_first_samples_come_faster_than_it(kin):
    """A plan whose first samples are 30 ms apart on the 19.2 kbit/s line (a 53 ms cycle): the bus
    brings its first targets later than the plan passes them, so the stream begins with a hold
    (stream_points.fed_schedule) and then runs the plan's own timing; what is said before the run
    is the plan, the hold and the bus's 3 cycles, and the run keeps it within 10 %."""
    from test_stream_timing_stepped import hard_start
    world, times, points, said = paced_plan(kin, hard_start)
    parts = re.search(r"the plan's ([0-9.]+) s, a ([0-9.]+) s hold at the start while the bus brings its first "
                      r"targets and the bus's 3 cycles to the arm and back", said.words)
    assert parts is not None, said.words
    hold = float(parts.group(2))
    assert hold > 0.02
    assert said.duration == pytest.approx(times[-1] + hold + STREAM_LATENCY_CYCLES * world.core.bus_cycle(), abs=0.01)
    took, _top = run(world, times, points)
    assert took == pytest.approx(said.duration, rel=AGREE), (took, said.words)


def test_a_segment_the_bus_stretches_is_said_at_its_slower_speed(kin):
    """Where the stream shifts later points (the bus brings them slower than the plan passes them),
    the plan's samples between two points run as the two are shifted (fed_times), and the TCP's top
    speed said is the plan's as it runs so: a run said at 1055 mm/s went at most 846 where its
    fastest segment was stretched. A constant shift (the hold's lead alone) changes no speed."""
    from types import SimpleNamespace as P

    from vr_driver.driver.motion.announced import fed_times, plan_peak_speed
    times = [0.1 * k for k in range(11)]
    q0 = (0.0, 0.3, -0.6, 0.0, 0.5, 0.0)
    positions = [tuple(v + (0.05 * k if j == 0 else 0.0) for j, v in enumerate(q0)) for k in range(11)]
    constant = [P(time=t, fed=t + 0.2, hold=False) for t in (0.0, 0.5, 1.0)]
    assert fed_times(times, constant) == pytest.approx([t + 0.2 for t in times])
    assert plan_peak_speed(kin, fed_times(times, constant), positions) == pytest.approx(
        plan_peak_speed(kin, times, positions))
    stretched = [P(time=0.0, fed=0.2, hold=False), P(time=0.5, fed=0.7, hold=False), P(time=1.0, fed=1.45, hold=False),
                 P(time=0.0, fed=0.2, hold=True)]                    # (the hold is not a point of the plan)
    shifted = fed_times(times, stretched)
    assert shifted[5] == pytest.approx(0.7) and shifted[10] == pytest.approx(1.45)
    assert shifted[7] == pytest.approx(0.7 + 0.2 * 1.5)                # the segment 0.5-1.0 s runs 1.5 x its time
    assert plan_peak_speed(kin, shifted, positions) < plan_peak_speed(kin, times, positions)
    assert fed_times(times, []) == times


def test_a_run_whose_later_points_the_bus_brings_later_keeps_the_times_said(kin):
    """A plan dense all along on the 19.2 kbit/s line (test_stream_timing_stepped.dense: more targets
    than the bus brings in its time): the stream holds at the start and reaches later points later
    (stream_points.fed_schedule). What is said before it runs gives each point's time as the stream
    runs it (Announced.times), and the run follows those times -- not the plan's own, which no single
    start delay fits -- and keeps the time and the TCP's top speed said within 10 %."""
    from driver_check import plan_as_sampled, top_tcp_speed
    from test_stream_timing_stepped import dense
    world, times, points, said = paced_plan(kin, dense)
    assert "more where it brings later ones slower than the plan passes them" in said.words, said.words
    assert len(said.times) == len(times) and said.times[-1] > times[-1] + said.times[0] + 0.05
    assert all(b >= a for a, b in zip(said.times, said.times[1:]))
    samples = []

    def arm():
        q, t = world.arm.stepped_joints()
        if not samples or t > samples[-1][0]:
            samples.append((t, tuple(q)))
        return False
    traj = validated(world, times[1:], points[1:])
    trajectory_run = world.core.submit_trajectory(traj, started=world.now)
    world.run_until(lambda: arm() or trajectory_run.done, 30.0, "the run")
    assert trajectory_run.success and trajectory_run.jobs[0].gaps == 0
    took = max(job.ended_at for job in trajectory_run.jobs) - trajectory_run.first_sent
    assert took == pytest.approx(said.duration, rel=AGREE), (took, said.words)
    moving = [s for s in samples if s[0] >= trajectory_run.first_sent]
    _, off_said, at_said = plan_as_sampled(said.times, points, moving)
    _, off_plan, _ = plan_as_sampled(times, points, moving)
    assert off_said < math.radians(0.5) < off_plan, (math.degrees(off_said), math.degrees(off_plan))
    top = top_tcp_speed(world.kin, moving, 0.02)
    assert top == pytest.approx(said.top_speed, rel=AGREE), (top, said.top_speed)
    assert top_tcp_speed(world.kin, at_said, 0.02) <= 1.05 * said.top_speed
