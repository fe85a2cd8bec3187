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


from vr_driver.driver.motion.sequencer import SequencerBase
from vr_driver.driver.motion.streaming import StreamSequencer

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


def test_the_first_target_is_dated_by_the_cycle_that_carried_its_record(kin, monkeypatch):
    """A bus process numbers each new record; its report says which one the cycle carried. On a
    saturated line a record set after a report goes out with the cycle after the one under way: the
    report two steps later carries it -- while the record set last (one step later, offering the next
    target) is not carried yet. The first target's time (MoveJob.left_at, the result's "first target
    left") is that report's, by the serial of the record that first offered it; by "the record set
    last was carried" it came a cycle or more late."""
    world = World(kin, protocol="v3")
    world.ready()
    core = world.core
    serials, sent = [0], [b""]                       # the serial of the record set last; the record
    at_step = []                                     # the serial set last at each step's start
    set_outputs, step = core.link.set_outputs, core.link.step

    def numbered(record):
        if record != sent[0]:
            sent[0] = record
            serials[0] += 1
        set_outputs(record)

    def reported(now):
        sample = step(now)
        at_step.append(serials[0])
        carried = at_step[-2] if len(at_step) >= 2 else 0        # set at the end of the step before the last
        return replace(sample, outputs_serial=serials[0], carried_serial=carried, carried=carried >= serials[0])
    monkeypatch.setattr(core.link, "set_outputs", numbered)
    monkeypatch.setattr(core.link, "step", reported)
    times_of = []
    monkeypatch.setattr(core.sequencer, "_note_carried", lambda sample, f=core.sequencer._note_carried: (
        times_of.append(sample.time), f(sample))[1])
    for _ in range(5):
        world.tick()
    times, points = smooth_path(tuple(world.arm.joints), n=20, duration=2.0)
    run_ = core.submit_trajectory(trajectory(world, times, points))
    job = run_.jobs[0]
    world.run_until(lambda: job.left_at is not None, 2.0, "the first target")
    assert job.sent_serial is not None
    sent_step = times_of.index(job.sent_at)
    assert job.left_at == times_of[sent_step + 2]         # the report of the cycle after the one under way
    record(world, job)
    assert job.result.success, job.result.reason
