"""A step woken by a request makes a record between two bus reports (vr_driver.driver.bus_loop, on a
bus process): when a cycle was under way, that cycle's report says the record was not carried, and
the next step's record replaces it before any telegram did (vr_driver.bus.process). The stream then
offers again what the lost record offered (StreamSequencer.before_record) -- without that, the
START of a new stream, made the moment its goal arrived, was replaced by its next target sent
ahead, which the controller ignores without a START: the arm stood at point 1, or lost a target's
worth of look-ahead (bench/README.md). Stepped: v3 in the world of _world.py, the lost record
dropped by hand."""
from __future__ import annotations

from dataclasses import replace


from vr_driver.driver.sequencer import SequencerBase
from vr_driver.driver.streaming import StreamSequencer

from _world import World
from test_streaming_stepped import record, smooth_path, trajectory


def run(kin, monkeypatch, rule: bool):
    if not rule:
        monkeypatch.setattr(StreamSequencer, "before_record", SequencerBase.before_record)
    world = World(kin, protocol="v3")
    world.ready()
    core = world.core
    samples, lose_next, commands = [], [False], []
    step = core.link.step

    def link_step(now):
        sample = step(now)
        if lose_next[0]:
            sample, lose_next[0] = replace(sample, carried=False), False
        samples.append(sample)
        return sample
    monkeypatch.setattr(core.link, "step", link_step)
    make = core.sequencer.record

    def recorded(now):
        command = make(now)
        commands.append(command)
        return command
    monkeypatch.setattr(core.sequencer, "record", recorded)
    world.tick()
    while not samples:
        world.tick()

    times, points = smooth_path(tuple(world.arm.joints), n=20, duration=2.0)
    traj = trajectory(world, times, points)
    job_run = core.submit_trajectory(traj)
    core.run_planning()                    # the stream is prepared and posted: a request wakes the bus loop
    job = job_run.jobs[0]
    woken = core.sequencer.step(world.now, replace(samples[-1], cycled=False, fresh=None, time=world.now),
                                world.status().joints)
    # the woken step's record never reaches the wire: the next report's record replaces it
    lose_next[0] = True
    n = len(commands)
    world.tick()
    while len(commands) == n:
        world.tick()
    return world, job, woken, commands[n]


def test_the_lost_start_is_offered_again_and_the_stream_runs_each_target_once(kin, monkeypatch):
    world, job, woken, after = run(kin, monkeypatch, rule=True)
    assert woken.describe().startswith("START #%d " % job.seqs[0])
    assert after == woken                  # what was lost goes out now
    record(world, job)
    assert job.result.success, job.result.reason
    assert job.gaps == 0
    assert [e.seq for e in world.log.entries()] == job.seqs


def test_without_the_rule_the_next_record_goes_on_as_if_the_start_had_been_read(kin, monkeypatch):
    _world, job, woken, after = run(kin, monkeypatch, rule=False)
    assert woken.describe().startswith("START #%d " % job.seqs[0])
    assert after.describe().startswith("#%d " % job.seqs[1])     # sent ahead of a START nobody read
