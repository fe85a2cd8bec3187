"""RecordClock (driver/link/record_clock.py): a record's time from the controller's loop counter. A
simulated program loops at a steady period; each record waits a random part of a loop in the card
before the master reads it. The clock must stamp each record with the time it was taken, to a small
part of the loop period, where the observation alone is off by up to a whole period."""
from __future__ import annotations

import random

import pytest

from vr_driver.driver.link.record_clock import RecordClock

PERIOD = 0.010          # the program loop
BUS = 0.053             # the bus cycle (not a multiple of the loop)


def observations(n, start_loop=0, seed=1, period=PERIOD, jitter=0.0):
    """(heartbeat, true time the record was taken, observed time) of ``n`` bus cycles."""
    rng = random.Random(seed)
    out = []
    t = 5.0
    for _ in range(n):
        t += BUS
        loops = int(t / period)                       # the last loop before the telegram
        taken = loops * period + rng.uniform(-jitter, jitter)
        out.append(((start_loop + loops) % 65536, taken, t))
    return out


def test_without_a_heartbeat_the_stamp_is_the_observation():
    clock = RecordClock()
    assert clock.stamp(12.5, None) == 12.5 and clock.period is None


def test_a_steady_loop_is_dated_to_a_small_part_of_its_period():
    clock = RecordClock()
    errors_raw, errors = [], []
    for k, (hb, taken, observed) in enumerate(observations(400)):
        stamp = clock.stamp(observed, hb)
        assert stamp <= observed
        if k >= 100:
            errors.append(abs(stamp - taken))
            errors_raw.append(observed - taken)
    assert clock.period == pytest.approx(PERIOD, rel=1e-3)
    assert max(errors) < 0.1 * PERIOD, max(errors)
    assert max(errors_raw) > 0.5 * PERIOD          # what the observation alone would be off by


def test_the_same_record_keeps_its_stamp():
    clock = RecordClock()
    obs = observations(100)
    for hb, _taken, observed in obs:
        clock.stamp(observed, hb)
    hb, _taken, observed = obs[-1]
    first = clock.stamp(observed, hb)
    assert clock.stamp(observed + 0.05, hb) == first      # read again a cycle later: not new


def test_the_counter_wraps_at_65536():
    clock = RecordClock()
    errors = []
    for k, (hb, taken, observed) in enumerate(observations(400, start_loop=65536 - 1000)):
        stamp = clock.stamp(observed, hb)
        if k >= 100:
            errors.append(abs(stamp - taken))
    assert max(errors) < 0.1 * PERIOD


def test_a_restarted_program_starts_the_estimate_afresh():
    clock = RecordClock()
    for hb, _taken, observed in observations(200):
        clock.stamp(observed, hb)
    assert clock.period is not None
    resets = clock.resets
    later = observations(5, start_loop=0, seed=2)          # a counter back near 0: a restart
    hb, _taken, observed = later[-1]
    stamp = clock.stamp(observed + 30.0, (hb + 40000) % 65536)
    assert clock.resets == resets + 1 and clock.period is None and stamp == observed + 30.0


def test_stamps_never_go_back_in_time():
    clock = RecordClock()
    stamps = [clock.stamp(observed, hb) for hb, _t, observed in observations(300, jitter=0.002, seed=3)]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
