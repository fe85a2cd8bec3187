"""The driver set from the commissioning (driver/checks/commissioned.py, params.ControllerFacts), stepped with
the fake clock in one thread (_world.World): the virtual G2 set one way (one of its assumptions about
the real G2, doc/controller_program.md §10.9) and the driver told the same by its ``controller``
parameters -- or not told, to show what the setting costs.

- MOVEP's speed unit (``speed_scale``): told, a v3 trajectory runs its planned time; not told, slower;
- no interpreter look-ahead: every point a stop (``stream_smooth`` 0), the time it costs said at
  connect and kept to;
- a program that refuses a target sent ahead: one target per acknowledgement, every stream runs;
- look-ahead 2: shorter stream segments, fed in time;
- a program loop that blocks during a MOVE: a streaming protocol refused at start, v1 runs;
- the words at connect, and the plan action's limits from the commissioning's joint_limits.yaml."""
from __future__ import annotations

import functools
import logging
import math

import pytest

import _world
from _world import World
from test_streaming_stepped import record, smooth_path, trajectory
from vr_driver.controller.arm import Outcome
from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.controller.stream_arm import SimStreamArm
from vr_driver.driver.checks.commissioned import controller_notes, min_segment_cycles, planning_kinematics
from vr_driver.driver.motion.stream_points import MIN_SEGMENT_CYCLES
from vr_driver.driver.motion.streaming import wire_speed
from vr_driver.driver import MoveRequest
from vr_driver.params import DriverParams, ParamError
from vr_driver.poses import MoveType
from vr_driver.protocol.v2 import StreamState


def g2_world(kin, monkeypatch, told=None, arm=None, program=None, lookahead=1, **kw):
    """A v3 world whose virtual G2 has ``arm`` (SimStreamArm keywords: speed_scale, ...) and
    ``program`` (ControllerProgramV3 keywords: send_ahead, ...) and look-ahead ``lookahead``; the
    driver told ``told`` (its ``controller`` parameters; None: told nothing)."""
    if arm:
        monkeypatch.setattr(_world, "SimStreamArm", functools.partial(SimStreamArm, **arm))
    if program:
        monkeypatch.setattr(_world, "ControllerProgramV3", functools.partial(ControllerProgramV3, **program))
    params = dict(kw.pop("params", {}))
    if told is not None:
        params["controller"] = told
    w = World(kin, params, protocol="v3", interpreter_lookahead=lookahead, **kw)
    monkeypatch.undo()
    w.ready()
    return w


def run_path(world, n=30, duration=4.0):
    q0 = tuple(world.arm.joints)
    times, points = smooth_path(q0, n=n, duration=duration)
    traj = trajectory(world, times, points)
    t0 = world.now
    run = world.core.submit_trajectory(traj)
    job = run.jobs[0]
    samples = record(world, job)
    return traj, job, samples, world.now - t0


def peak_fraction(world, traj):
    """The plan's fastest segment as a fraction of the model's joint speed limits."""
    vmax = world.kin.limits.velocity
    return max(abs(b - a) / ((t1 - t0) * v) for p0, p1, t0, t1 in zip(traj.positions, traj.positions[1:],
                                                                        traj.times, traj.times[1:])
               for a, b, v in zip(p0, p1, vmax))


# ------------------------------------------------------------------------------------ the parameters

def test_controller_facts_are_range_checked_and_name_the_key():
    assert DriverParams.from_dict({}).controller == DriverParams.from_dict({"controller": {}}).controller
    for bad, name in (({"speed_scale": 0}, "controller/speed_scale"),
                      ({"speed_scale": "fast"}, "controller/speed_scale"),
                      ({"interpreter_lookahead": -1}, "controller/interpreter_lookahead"),
                      ({"interpreter_lookahead": 1.5}, "controller/interpreter_lookahead"),
                      ({"send_ahead": "maybe"}, "controller/send_ahead"),
                      ({"configuration": "any"}, "controller/configuration"),
                      ({"ramp_shape": "cubic"}, "controller/ramp_shape"),
                      ({"ramp_time": -0.1}, "controller/ramp_time"),
                      ({"loop_period": 0.0}, "controller/loop_period"),
                      ({"ring_size": 0}, "controller/ring_size"),
                      ({"check_word": "yes"}, "controller/check_word"),
                      ({"accelerations": {"joint_7": 3.0}}, "controller/accelerations/joint_7"),
                      ({"accelerations": {"joint_1": 0.0}}, "controller/joint_1"),
                      ({"accelerations": [1, 2]}, "controller/accelerations"),
                      ({"speed_unit": 0.6}, "controller/speed_unit")):
        with pytest.raises(ParamError) as err:
            DriverParams.from_dict({"controller": bad})
        assert err.value.name == name, (bad, err.value)
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"controller": [1]})
    assert err.value.name == "controller"
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"commissioning": "today"})
    assert err.value.name == "commissioning"
    facts = DriverParams.from_dict({"controller": {"accelerations": {"joint_2": 10}, "ramp_time": 0.5}}).controller
    assert facts.acceleration("joint_2") == 10.0 and facts.acceleration("joint_1") is None
    assert facts.ramp_time == 0.5


def test_planning_limits_file_is_checked_at_start(tmp_path):
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"planning_limits": str(tmp_path / "nope.yaml")})
    assert err.value.name == "planning_limits" and "no such file" in str(err.value)
    path = tmp_path / "joint_limits.yaml"
    entry = "{has_velocity_limits: true, max_velocity: 1.0, has_acceleration_limits: true, max_acceleration: %s}"
    lines = ["joint_limits:"] + ["  joint_%d: %s" % (i, entry % "5.0") for i in range(1, 6)]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"planning_limits": str(path)})
    assert "joint_limits/joint_6: missing" in str(err.value)
    path.write_text("\n".join(lines + ["  joint_6: %s" % (entry % "-1")]) + "\n")
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict({"planning_limits": str(path)})
    assert "joint_limits/joint_6/max_acceleration" in str(err.value)
    path.write_text("\n".join(lines + ["  joint_6: %s" % (entry % "7.5")]) + "\n")
    assert DriverParams.from_dict({"planning_limits": str(path)}).planning_limits == str(path)


def test_a_loop_that_blocks_during_a_move_refuses_streaming_at_start_and_v1_runs(kin, monkeypatch):
    for protocol in ("v2", "v3"):
        with pytest.raises(ParamError) as err:
            DriverParams.from_dict({"protocol": protocol, "controller": {"loop_blocks_during_move": True}})
        text = str(err.value)
        assert err.value.name == "controller/loop_blocks_during_move"
        assert "cannot stream" in text and "use protocol v1" in text
    # v1 takes one target at a time: a loop that stops while the MOVE runs is what it waits for
    monkeypatch.setattr(_world, "ControllerProgram", functools.partial(ControllerProgram, loop_blocks_during_move=True))
    w = World(kin, {"controller": {"loop_blocks_during_move": True}}, protocol="v1")
    monkeypatch.undo()
    assert w.program.loop_blocks_during_move
    w.ready()
    assert w.core.controller_notes == ()
    for target in ((1000, -200, 150, 0, 90, 0), (900, 100, 400, 0, 90, 0)):
        assert w.finish(w.core.submit(MoveRequest(MoveType.PTP, target))).success
    assert [e.outcome for e in w.log.entries()] == [Outcome.EXECUTED] * 2


def test_wire_speed_divides_by_the_speed_unit_rounded_up_and_capped():
    assert wire_speed(600, 1.0) == 600
    assert wire_speed(600, 0.6) == 1000
    assert wire_speed(601, 0.6) == 1000                     # the arm cannot: full speed, slower than planned
    assert wire_speed(300, 0.6) == 500
    assert wire_speed(301, 0.6) == 502                      # rounded up: never slower than planned
    assert wire_speed(1, 2.0) == 1 and wire_speed(1000, 2.0) == 500


def test_min_segment_cycles_follow_the_lookahead_and_the_send_ahead_rule():
    def cycles(**facts):
        return min_segment_cycles(DriverParams.from_dict({"protocol": "v3", "controller": facts}))
    assert cycles() == MIN_SEGMENT_CYCLES                    # the assumed G2: as before
    assert cycles(interpreter_lookahead=0) == MIN_SEGMENT_CYCLES
    assert cycles(interpreter_lookahead=2) == MIN_SEGMENT_CYCLES / 2
    assert cycles(send_ahead="refused") == 2 * MIN_SEGMENT_CYCLES
    assert min_segment_cycles(DriverParams.from_dict({"protocol": "v2"})) == MIN_SEGMENT_CYCLES


# ------------------------------------------------------------------------------------ MOVEP's speed unit

def test_speed_unit_told_runs_the_planned_time_not_told_runs_slower(kin, monkeypatch):
    told = g2_world(kin, monkeypatch, told={"speed_scale": 0.6}, arm={"speed_scale": 0.6})
    traj, job, _samples, elapsed = run_path(told)
    assert peak_fraction(told, traj) < 0.6            # planned within what the arm can at this unit
    assert job.result.success, job.result.reason
    assert job.gaps == 0
    assert elapsed <= 1.10 * traj.duration + 0.3, (elapsed, traj.duration)
    # what went on the wire: each planned speed / 0.6, rounded up
    assert [e.speed for e in told.log.entries()] == [wire_speed(p.speed, 0.6) for p in job.points]
    assert max(e.speed for e in told.log.entries()) > max(p.speed for p in job.points)

    untold = g2_world(kin, monkeypatch, arm={"speed_scale": 0.6})
    traj2, job2, _samples2, elapsed2 = run_path(untold)
    assert job2.result.success, job2.result.reason
    print("speed unit x0.6, a %.2f s v3 trajectory: driver told %.2f s, not told %.2f s"
          % (traj.duration, elapsed, elapsed2))
    assert elapsed2 > 1.10 * traj2.duration + 0.3
    assert elapsed2 > 1.3 * elapsed


def test_speed_unit_below_1_says_at_connect_what_it_does(kin, monkeypatch, caplog):
    caplog.set_level(logging.WARNING, logger="vr_driver.driver")
    w = g2_world(kin, monkeypatch, told={"speed_scale": 0.6}, arm={"speed_scale": 0.6})
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("controller: ")]
    assert len(said) == 1 and said == ["controller: " + n for n in w.core.controller_notes]
    assert "x0.6" in said[0] and "divided by 0.6" in said[0] and "60 %" in said[0]
    assert "give the planner the scaled velocity limits (planning_limits" in said[0]


# ------------------------------------------------------------------------------------ no look-ahead

def test_no_lookahead_every_point_a_stop_and_the_time_it_costs_said_and_kept(kin, monkeypatch, caplog):
    caplog.set_level(logging.WARNING, logger="vr_driver.driver")
    w = g2_world(kin, monkeypatch, told={"interpreter_lookahead": 0}, lookahead=0,
                 params={"stream_smooth": 3})
    assert w.params.stream_smooth == 0                       # the G2 stops anyway: timed as stops
    ramp = kin.limits.ramp_time
    (note,) = w.core.controller_notes
    assert "exact stop" in note and "stream_smooth 0" in note and "%.2g s" % ramp in note
    assert any(r.getMessage() == "controller: " + note for r in caplog.records)
    n = 10
    traj, job, _samples, elapsed = run_path(w, n=n, duration=3.0)
    assert job.result.success, job.result.reason
    assert all(p.smooth == 0 for p in job.points)
    entries = w.log.entries()
    assert [e.seq for e in entries] == job.seqs
    assert all(e.outcome is Outcome.EXECUTED for e in entries)          # none blended
    # what it costs: up to a ramp per point, as said (and a bus cycle each for the next target)
    print("look-ahead 0: %d points, planned %.2f s, ran %.2f s (said: up to %.2f s more)"
          % (len(job.points), traj.duration, elapsed, len(job.points) * ramp))
    assert traj.duration < elapsed <= traj.duration + len(job.points) * (ramp + w.bus_period) + 0.3


# ------------------------------------------------------------------------------------ send-ahead refused

def test_send_ahead_refused_one_target_per_acknowledgement(kin, monkeypatch, caplog):
    caplog.set_level(logging.WARNING, logger="vr_driver.driver")
    w = g2_world(kin, monkeypatch, told={"send_ahead": "refused"}, program={"send_ahead": "refused"})
    assert w.core.wire.send_ahead == 1 and w.core.sequencer.wire.send_ahead == 1
    from vr_driver.protocol.v3 import V3
    assert V3.send_ahead == 2                                # the protocol's own rule unchanged
    assert w.core.streams.min_segment() == pytest.approx(2 * MIN_SEGMENT_CYCLES / 20.0)
    assert any("one target per acknowledgement" in r.getMessage() for r in caplog.records)
    traj, job, _samples, elapsed = run_path(w, n=30, duration=4.0)
    assert job.result.success, job.result.reason
    assert [e.seq for e in w.log.entries()] == job.seqs       # each once, in order
    assert w.status().counters.targets_rejected == 0
    assert elapsed <= 1.10 * traj.duration + 0.3, elapsed

    # not told: the second target goes out ahead and the program refuses it
    untold = g2_world(kin, monkeypatch, program={"send_ahead": "refused"})
    _traj, job2, _s, _e = run_path(untold, n=30, duration=4.0)
    assert not job2.result.success and "OUT_OF_ORDER" in job2.result.reason


# ------------------------------------------------------------------------------------ look-ahead 2

def test_lookahead_2_feeds_shorter_segments_in_time(kin, monkeypatch):
    one = g2_world(kin, monkeypatch, lookahead=2)
    two = g2_world(kin, monkeypatch, told={"interpreter_lookahead": 2}, lookahead=2)
    assert two.core.streams.min_segment() == pytest.approx(one.core.streams.min_segment() / 2)
    results = []
    for w in (one, two):
        # joint_1 and joint_4 swing once a second about a slow drift: points 0.06 s apart keep it
        # within the path tolerance -- shorter than two bus cycles (look-ahead 1), not than one
        q0 = tuple(w.arm.joints)
        times = [0.03 * k for k in range(1, 101)]
        points = [tuple(q + (0.05 * math.sin(2 * math.pi * t) * math.sin(math.pi * t / 3.0) if i in (0, 3)
                             else 0.1 * t / 3.0) for i, q in enumerate(q0)) for t in times]
        traj = trajectory(w, times, points)
        t0 = w.now
        job = w.core.submit_trajectory(traj).jobs[0]
        samples = record(w, job)
        elapsed = w.now - t0
        assert job.result.success, job.result.reason
        assert job.gaps == 0 and all(s is not StreamState.WAITING for _t, _q, s in samples[:-1])
        assert elapsed <= 1.10 * traj.duration + 0.3
        results.append(len(job.points))
    assert results[1] > results[0], results                 # more of the plan kept


# ------------------------------------------------------------------------------------ the plan action's limits

def test_planning_limits_are_the_plan_actions(kin, tmp_path):
    from vr_driver.kinematics import deps
    missing = deps.missing_dependencies(("ompl", "toppra"))
    if missing:
        pytest.skip("; ".join(r for _, r in missing))
    from vr_driver.commission.report import joint_limits, write_joint_limits
    from vr_driver.driver.planning.planning import PlanActionCore, PlanGoal
    lim = kin.limits
    slow = {axis: v / 0.5 for axis, v in enumerate(lim.velocity, 1)}     # a 0.5 s ramp on every joint
    limits = joint_limits(lim.names, lim.velocity, lim.acceleration, {"accelerations": slow})
    path = tmp_path / "joint_limits.yaml"
    write_joint_limits(str(path), limits, str(tmp_path / "commissioning.yaml"), sorted(slow))
    goal = PlanGoal(joints=(tuple(lim.names), (0.3, 0.5, -0.2, 0.0, 0.5, 0.0)))
    durations = []
    for params in ({}, {"planning_limits": str(path)}):
        w = World(kin, dict(params, collision_check=False, velocity_scaling=1.0, planning_time=20.0), protocol="v3")
        w.ready()
        pk = planning_kinematics(w.params, kin)
        assert (pk is kin) == (not params)
        planning = PlanActionCore(w.core, kinematics=pk)
        out = planning.plan(goal, seed=1)
        assert out.ok, out.text
        acc = [max(abs(a[i]) for a in out.trajectory.accelerations) for i in range(6)]
        assert all(a <= pk.limits.acceleration[i] * 1.0001 for i, a in enumerate(acc)), acc
        durations.append(out.trajectory.duration)
    assert kin.limits.acceleration == lim.acceleration       # the shared model untouched
    print("plan at the model's accelerations %.2f s, at a 0.5 s ramp %.2f s" % tuple(durations))
    assert durations[1] > 1.8 * durations[0]          # a short move: time ~ 1 / sqrt(acceleration)


def test_notes_are_empty_for_the_assumed_g2_and_name_each_difference(kin):
    assert controller_notes(DriverParams.from_dict({"protocol": "v3"}), kin) == ()
    notes = controller_notes(DriverParams.from_dict({"protocol": "v3", "controller": {
        "check_word": False, "unreachable": "alarm_halt", "configuration": "current_joints",
        "send_ahead": "taken", "interpreter_lookahead": 2},
        "commissioning": {"date": "2025-01-02T10:00:00+01:00", "controller": {"ident": "0x06C6"}}}), kin)
    text = "\n".join(notes)
    assert "commissioned on 2025-01-02T10:00:00+01:00" in notes[0] and "0x06C6" in notes[0]
    for words in ("reads 2 MOVEs ahead", "RUNS a target sent ahead", "check word", "halts the G2's program",
                  "nearest its joints", "up to 5 points before it", "at most 18 deg apart"):
        assert words in text, words
    # the driver applies the rule: no longer "checks points assuming the previous target's solution"
    assert "previous target" not in text
    # v1 streams nothing: only what concerns every protocol
    v1 = controller_notes(DriverParams.from_dict({"controller": {"speed_scale": 0.6, "interpreter_lookahead": 0,
                                                                 "unreachable": "alarm_halt"}}), kin)
    assert len(v1) == 1 and "alarm" in v1[0]
    # the configuration rule: v1 tracks its joints by it, v2 sends joints (no rule to apply)
    rule = {"configuration": "current_joints"}
    v1 = controller_notes(DriverParams.from_dict({"controller": rule}), kin)
    assert len(v1) == 1 and "joint_states apply that rule" in v1[0] and "stream" not in v1[0], v1
    assert controller_notes(DriverParams.from_dict({"protocol": "v2", "controller": rule}), kin) == ()
    assert math.isfinite(kin.limits.ramp_time)


def test_the_hold_at_a_streams_start_lasts_its_lead_at_the_speed_unit_told(kin, monkeypatch):
    """The hold that begins a stream whose first points come faster than the bus (stream_points.
    hold_speed: a creep at 0.1-1 % of the joint speed) is sent as any target, its speed divided by
    MOVEP's speed unit: told 0.6, the G2 runs it as long as the lead (the wire's rounding: within
    20 %; 0.4 % sent as 0.7 % runs 0.42 %), stops there exactly and goes on with the targets in its
    ring -- no wait for a target -- and the run takes the time it takes at a unit of 1 (within 5 %)."""
    from test_stream_timing_stepped import hard_start
    took = {}
    for scale in (1.0, 0.6):
        w = g2_world(kin, monkeypatch, told={"speed_scale": scale}, arm={"speed_scale": scale})
        w.run_for(1.0)
        q0 = tuple(w.status().joints)
        times, points = hard_start(q0, speed=0.5)
        run = w.core.submit_trajectory(trajectory(w, times, points), started=w.now)
        job = run.jobs[0]
        hold = job.points[0]
        assert hold.hold and hold.smooth == 0 and hold.fed > 0.0
        w.run_until(lambda: run.done, 30.0, "the run")
        assert run.success and job.gaps == 0
        entries = w.log.entries()[-len(job.points):]
        first, second = entries[0], entries[1]
        assert first.speed == wire_speed(hold.speed, scale) and first.outcome.value == "executed"
        assert first.duration == pytest.approx(hold.fed, rel=0.2), (scale, first.duration, hold.fed)
        assert second.start_time - first.end_time < 1e-6
        took[scale] = max(j.ended_at for j in run.jobs) - run.first_sent
    assert took[0.6] == pytest.approx(took[1.0], rel=0.05), took
