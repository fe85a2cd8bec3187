"""The commissioning's numbers and files without a bus (vr_driver.commission.analysis, .report, .cli):
synthetic records of known loops and moves, the verdicts they must give. Pure computation; the tool
against the virtual G2 over a pty is test_commission.py."""
from __future__ import annotations

import io
import math
import os
import threading
import time
import random

import pytest

from vr_driver.commission import analysis
from vr_driver.commission.bus import port_users
from vr_driver.commission.cli import main
from vr_driver.commission.report import driver_values, joint_limits
from vr_driver.commission.steps import STOP_SPEED, LoopStep, _verdict
from vr_driver.controller.options import LoopTiming


def brackets_of(times, cycle):
    """The brackets a master cycling every ``cycle`` s sees for loops at ``times``."""
    out = []
    for k, t in enumerate(times[1:], start=1):
        latest = math.ceil(t / cycle) * cycle
        out.append((k, latest - cycle, latest))
    return out


@pytest.mark.parametrize("jitter", [0.0, 0.002])
def test_loop_period(jitter):
    rng = random.Random(3)
    t, times = 0.0013, []
    for _ in range(400):
        times.append(t)
        t += 0.01 + rng.uniform(-jitter, jitter)
    lt = analysis.loop_timing(brackets_of(times, 0.00413))      # a bus cycle not a fraction of the loop's
    assert abs(lt.period - 0.01) < 2e-4
    assert lt.max_gap < 0.02


def heartbeat_records(loop, jitter, seed, cycle=0.05, seconds=20.0, noise=0.002, wire=0.019):
    """(request time, heartbeat) of a master asking every ``cycle`` (+ up to ``noise`` late, its own
    scheduling) a card whose program loops as the virtual G2's does (controller.options.LoopTiming:
    ``loop`` +- ``jitter``, seeded): the card answers with the count of the loops that ran before the
    request's last character arrived (``wire`` after the request: 19.2 kbit/s)."""
    timing = LoopTiming(loop, jitter, seed)
    noise_rng = random.Random(seed + 1000)
    t, loops = timing.next_period() * 0.5, []
    while t < seconds + 1.0:
        loops.append(t)
        t += timing.next_period()
    out, k, request = [], 0, 0.0137
    while request < seconds:
        read = request + wire + noise_rng.uniform(0.0, noise)
        while k + 1 < len(loops) and loops[k + 1] <= read:
            k += 1
        out.append((request, k))
        request += cycle + noise_rng.uniform(0.0, noise)
    return out


@pytest.mark.parametrize("loop", [0.010, 0.013, 0.016, 0.020])
@pytest.mark.parametrize("jitter", [0.0, 0.002, 0.004, 0.006])
def test_loop_spread_through_a_bus_cycle_longer_than_the_loop(loop, jitter):
    """19.2 kbit/s at 20 cycles/s (50 ms) against 10-20 ms loops, steady or +-2-6 ms, five seeds of the
    loop's periods each, 20 s at rest (the loop step's default watch), longer where the verdict needs
    it as the loop step watches longer (a steady 20 ms loop: about 25 s): every verdict right -- a
    jittery loop is never "steady" -- and the spread within -35 % / +60 % of the true one (a uniform
    +-J spreads J / sqrt 3)."""
    true = jitter / math.sqrt(3.0)
    for seed in range(5):
        got = analysis.loop_spread(heartbeat_records(loop, jitter, seed), 0.05)
        more = analysis.watch_more(got, LoopStep.LONGEST_WATCH * 20.0)        # as the loop step does
        if more:
            got = analysis.loop_spread(heartbeat_records(loop, jitter, seed, seconds=20.0 + more), 0.05)
        assert got.verdict == ("steady" if jitter == 0.0 else "irregular"), (seed, got)
        assert "the bus cycle, 50 ms, is longer than the loop" in got.why
        if jitter:
            assert 0.65 * true <= got.spread <= 1.6 * true, (seed, got.spread, true)
            assert got.low <= got.spread <= got.high


def test_loop_spread_says_not_resolved_and_why_when_the_watch_is_short():
    """10 s of a 20 ms loop through 50 ms cycles: too few loops to tell 0.5 ms from none -- "not
    resolved", the watch it would need named (the loop step watches that long, up to 4 times its
    own time); a jittery loop is still never "steady"; too few records say so."""
    steady = analysis.loop_spread(heartbeat_records(0.020, 0.0, 1, seconds=10.0), 0.05)
    assert steady.verdict == "not resolved" and steady.needed is not None and 10.0 < steady.needed < 80.0
    assert "too few loops to tell a spread of 0.5 ms from none" in steady.why
    assert "it needs about %.0f s" % steady.needed in steady.why
    for seed in range(5):
        for jitter in (0.002, 0.004, 0.006):
            short = analysis.loop_spread(heartbeat_records(0.020, jitter, seed, seconds=10.0), 0.05)
            assert short.verdict != "steady", (seed, jitter, short)
    few = analysis.loop_spread(heartbeat_records(0.016, 0.0, 1, seconds=2.0), 0.05)
    assert few.verdict == "not resolved" and few.spread is None and "too few records" in few.why
    assert few.needed is not None and few.needed > 2.0
    # a bus faster than the loop: the same reading, without the words about the bus cycle
    fast = analysis.loop_spread(heartbeat_records(0.010, 0.004, 2, cycle=0.004, seconds=5.0, wire=0.001), 0.004)
    assert fast.verdict == "irregular" and "longer than the loop" not in fast.why


def test_a_stalled_heartbeat_shows_as_a_gap_and_splits_the_dating():
    times = [0.01 * k for k in range(50)] + [0.8 + 0.01 * k for k in range(50)]   # 0.3 s without a loop
    br = brackets_of(times, 0.004)
    assert analysis.loop_timing(br).max_gap > 0.29
    dates = analysis.date_loops(br, stall=0.05)
    assert all(e <= dates[k] <= l for k, e, l in br)
    assert abs(dates[60] - times[60]) < 0.004


def profile(shape, r, v=2.0, dist=1.0, dt=0.01, t0=0.105, quantum=1.7e-4):
    """Samples of a move from rest to rest (ramps of ``r`` with ``shape``) every ``dt``, rounded as the
    wire's resolution rounds a joint (~0.01 deg)."""
    ramp = analysis.ramp_s_curve if shape == "s_curve" else analysis.ramp_linear
    t_move = dist / v + r                            # from rest to rest: T0 + r
    out = []
    for i in range(int((t0 + t_move + 0.2) / dt)):
        t = i * dt
        tau = t - t0
        q = v * ramp(tau, r) - v * ramp(tau - dist / v, r)
        out.append((t, round(q / quantum) * quantum))
    return out


@pytest.mark.parametrize("shape, r", [("linear", 0.1), ("s_curve", 0.1), ("linear", 0.25), ("s_curve", 0.25)])
def test_move_fit_finds_speed_ramp_and_shape(shape, r):
    fit = analysis.fit_move(profile(shape, r))
    assert fit is not None
    assert abs(fit.speed - 2.0) < 0.01
    for ramp in (fit.ramp_in, fit.ramp_out):
        assert abs(ramp.duration_as(shape) - r) < 0.05 * r
        assert ramp.shape == shape
        assert (ramp.s_curve_evidence > 0) == (shape == "s_curve")


def test_a_move_without_cruise_is_not_fitted():
    a, half = 20.0, 0.15                             # up at 20 rad/s^2 for 0.15 s, then down at once
    tri = []
    for i in range(60):
        t = 0.01 * i - 0.1
        u = min(max(t, 0.0), 2 * half)
        q = a * u * u / 2 if u <= half else a * half * half - a * (2 * half - u) ** 2 / 2 + a * half * half
        tri.append((t, q))
    assert analysis.fit_move(tri) is None


def test_one_late_record_is_not_a_stop():
    """A blend through three points at a steady 36 deg/s, records every 10 ms, with the record
    after each point dated 20 ms late (a loaded machine): sample to sample the speed dips to 33 %
    there and looked like a stop at every point (a fresh-clone run judged such a stream "stops at 4
    of 4"); the steady speeds keep it near 36. A real stop -- several records slow -- still dips."""
    v, points = 36.0, [3.6, 7.2, 10.8]
    blend = [(0.01 * i + (0.02 if i in (11, 21, 31) else 0.0), v * 0.01 * i) for i in range(45)]
    raw = min(abs(q2 - q1) / (t2 - t1) for (t1, q1), (t2, q2) in zip(blend, blend[1:]))
    assert raw < 0.35 * v                                   # what the old sample-to-sample speed saw
    lows = analysis.min_speed_near(blend, points, 0.03)
    assert all(low > 0.8 * v > STOP_SPEED * v for low in lows), lows
    assert analysis.top_speed([s for _, s in analysis.steady_speeds(blend)]) == pytest.approx(v, rel=0.05)
    stop, q = [], 0.0
    for i in range(60):                                     # a stop at 7.2: slow for 4 records
        speed = 3.0 if 18 <= i < 22 else v
        stop.append((0.01 * i, q))
        q += speed * 0.01
    assert analysis.min_speed_near(stop, [q for t, q in stop if t == pytest.approx(0.2)], 0.03)[0] < STOP_SPEED * v


def test_a_record_dated_early_at_the_end_is_not_the_cruise():
    """The look-ahead stream of a fresh-clone run beside the soak (its cycle log replayed): joint_1
    blended through four points at a steady 60 deg/s, then the tool's bus stalled 60 ms and the
    stream's last record (the arm at its end) came 2.4 ms after the one before, 1.4 deg further: 583
    deg/s. The end's median of two kept that, it set the "cruise", and every point read as a stop
    ("stops at 4 of 4 inner points at smooth 5: look-ahead 0" for a G2 that blends). Neither the
    steady speeds nor the cruise may take it, at either end of the samples."""
    v, points = 60.0, [8.0, 16.0, 24.0, 32.0]
    blend = [(0.01 * i, v * 0.01 * i) for i in range(65)]          # 0 .. 38.4 deg
    blend.append((blend[-1][0] + 0.0024, 40.0))                   # the last record, dated 2.4 ms later
    speeds = [s for _, s in analysis.steady_speeds(blend)]
    assert max(speeds) < 1.1 * v, max(speeds)
    assert analysis.top_speed(speeds) == pytest.approx(v, rel=0.02)
    lows = analysis.min_speed_near(blend, points, 0.047)
    assert all(low > STOP_SPEED * v for low in lows), lows
    first = [(0.0, 0.0), (0.0024, 1.4)] + [(0.0024 + 0.01 * i, 1.4 + v * 0.01 * i) for i in range(1, 60)]
    assert max(s for _, s in analysis.steady_speeds(first)) < 1.1 * v     # the same at the start
    # two outliers together (a pair of records, one dated early) do not set the cruise either
    assert analysis.top_speed([v] * 40 + [583.0, 560.0]) == pytest.approx(v)
    assert analysis.top_speed([0.0, 0.0]) == 0.0 and analysis.top_speed([]) == 0.0


def test_min_speed_near_points():
    stop = [(0.01 * i, min(i, 20) * 0.01 + max(0, i - 25) * 0.01) for i in range(50)]   # rests at 0.2 for 5 samples
    assert analysis.min_speed_near(stop, [0.2], 0.03)[0] == 0.0
    assert analysis.passing_times(stop, [0.1])[0] == pytest.approx(0.1)
    assert analysis.passing_times(stop, [5.0]) == [None]


def test_lookahead_verdicts():
    assert _verdict([True, True, None, True]) == (True, "stops at 3 of 3 inner points (1 left out: the next "
                                                        "target came late)")
    assert _verdict([False, False, False])[0] is False
    assert _verdict([True, False, False])[0] is None
    assert _verdict([None, None, True])[0] is None          # one point does not decide
    assert _verdict(None)[0] is None


def test_driver_values_and_joint_limits():
    assert driver_values({"interpreter_lookahead": 0, "byte_order": "big"})["stream_smooth"] == 0
    assert "stream_smooth" not in driver_values({"interpreter_lookahead": 1})
    values = driver_values({"accelerations": {2: 10.0}, "speed_scale": 0.6, "interpreter_lookahead": None})
    assert values["controller"] == {"accelerations": {"joint_2": 10.0}, "speed_scale": 0.6}   # only the measured
    assert values["protocol"] == "v3"
    blocking = driver_values({"loop_blocks_during_move": True, "interpreter_lookahead": 0})
    assert blocking["protocol"] == "v1" and blocking["stream_smooth"] == 0
    names, vel, acc = ("j1", "j2"), (2.0, 4.0), (20.0, 40.0)
    lim = joint_limits(names, vel, acc, {"speed_scale": 0.6, "accelerations": {2: 10.0}})
    assert lim["j1"] == {"has_velocity_limits": True, "max_velocity": 1.2, "has_acceleration_limits": True,
                         "max_acceleration": 20.0}
    assert lim["j2"]["max_acceleration"] == 10.0
    # within the measurement's 2 % the unit is as assumed; above 1 speed 1000 still stops at the limit
    assert joint_limits(names, vel, acc, {"speed_scale": 0.99})["j1"]["max_velocity"] == 2.0
    assert joint_limits(names, vel, acc, {"speed_scale": 1.3})["j1"]["max_velocity"] == 2.0


def test_port_users_reads_proc(tmp_path):
    dev = tmp_path / "ttyUSB9"
    dev.write_text("")
    proc = tmp_path / "proc"
    (proc / "4242" / "fd").mkdir(parents=True)
    (proc / "4242" / "fd" / "3").symlink_to(dev)
    (proc / "4242" / "cmdline").write_bytes(b"python3\0interface\0")
    (proc / "77" / "fd").mkdir(parents=True)
    assert port_users(str(dev), proc=str(proc)) == [(4242, "python3 interface")]
    assert port_users("/dev/pts/0", proc=str(proc)) == []       # a pty's other end holds it on purpose


def test_cli_refuses_bad_arguments_and_asks_before_anything_is_sent(tmp_path):
    out = io.StringIO()
    assert main(["--skip", "nope"], out=out, ask=lambda q: "y") == 2
    assert "unknown step nope" in out.getvalue()
    assert main(["--speed-percent", "150"], out=io.StringIO(), ask=lambda q: "y") == 2
    out = io.StringIO()
    assert main(["--rt-priority", "120"], out=out, ask=lambda q: "y") == 2
    assert "--rt-priority 120: give 0 (normal scheduling) or 1..99" in out.getvalue()
    asked = []
    out = io.StringIO()
    port = tmp_path / "ttyUSB7"
    port.write_text("")                     # a port that exists (a file here): the question comes first
    assert main(["--port", str(port), "--out", str(tmp_path / "c.yaml")], out=out,
                ask=lambda q: asked.append(q) or "n") == 1
    assert asked and "clear space" in asked[0]
    assert "nothing was sent" in out.getvalue()
    assert not (tmp_path / "c.yaml").exists()


def test_a_missing_port_is_said_at_once():
    """A port that does not exist: said at once, before any question or the connect timeout (it was
    said after the whole 10 s), with the serial ports there; the exit status of a controller that
    cannot be reached."""
    out, asked = io.StringIO(), []
    t0 = time.monotonic()
    assert main(["--port", "/dev/ttyUSB_nope", "--connect-timeout", "30"], out=out,
                ask=lambda q: asked.append(q) or "y") == 1
    assert time.monotonic() - t0 < 5.0 and not asked
    text = out.getvalue()
    assert "the port /dev/ttyUSB_nope does not exist" in text and "serial ports here:" in text
    assert "give --port" in text


def test_the_analysis_thread_leaves_the_bus_threads_real_time_priority(monkeypatch):
    """--rt-priority puts the bus thread at SCHED_FIFO; the analyses it starts (while_cycling) must
    not inherit it: the first thing the worker does is normal_scheduling() (recorded here: the real
    call needs a privilege a test cannot count on)."""
    from vr_driver.commission import steps

    calls = []
    monkeypatch.setattr(steps, "normal_scheduling", lambda: calls.append(threading.get_ident()))

    class Bus:
        def run(self, until, timeout):
            while not until(None):
                time.sleep(0.001)           # one bus cycle, as the real bus runs until the worker ends
    ctx = steps.Context.__new__(steps.Context)
    ctx.bus = Bus()
    assert ctx.while_cycling(lambda x: threading.get_ident() + x, 0) == calls[0] != threading.get_ident()


def test_loops_are_counted_by_the_heartbeats_advance_not_by_the_records():
    """At the user's default bus (20 cycles/s) against a 10 ms program loop each record brings about
    five new loops: a 0.4 s move with the loop running is ~40 loops, not the ~8 records that brought
    them (the tool once took that for a loop blocked by the MOVE and wrote protocol v1)."""
    from vr_driver.commission.bus import heartbeat_brackets, Cycle
    from vr_driver.driver.link.link import LinkState
    loop, cycle = 0.010, 0.050
    cycles = []
    for i in range(9):                                   # 0.4 s of records, one every 50 ms
        t = i * cycle
        cycles.append(Cycle(i, t, t + 0.02, LinkState.CONNECTED, _Fb(int(t / loop) % 65536), t + 0.02, b""))
    brackets = heartbeat_brackets(cycles)
    assert len(brackets) == 8                            # the records that brought a new heartbeat
    assert analysis.loops_seen(brackets) == 40           # the loops they counted
    # a loop blocked during the move: the heartbeat stands still until the record that shows it done
    blocked = [Cycle(i, i * cycle, i * cycle + 0.02, LinkState.CONNECTED, _Fb(7 if i < 8 else 8), i * cycle + 0.02, b"")
               for i in range(9)]
    assert analysis.loops_seen(heartbeat_brackets(blocked)) == 1
    assert analysis.loops_seen([]) == 0


class _Fb:
    """A record as heartbeat_brackets reads it: only its heartbeat."""

    def __init__(self, heartbeat):
        self.heartbeat = heartbeat


def test_an_analysis_runs_while_the_bus_keeps_cycling():
    """Context.while_cycling: the work runs in a thread of its own while the step's thread cycles
    the bus (the card's watchdog must not see it stand still); its value or its error comes back."""
    import threading
    from vr_driver.commission.steps import Context

    class Bus:
        def __init__(self):
            self.cycles = 0
            self.fifth = threading.Event()

        def run(self, until, timeout):
            while True:
                self.cycles += 1
                if self.cycles == 5:
                    self.fifth.set()
                if until(None):
                    return None

    class Ctx:
        bus = Bus()

    def work(x):
        assert Ctx.bus.fifth.wait(10.0), "the bus did not cycle while the analysis ran"
        return x * 2
    assert Context.while_cycling(Ctx, work, 21) == 42
    assert Ctx.bus.cycles >= 5

    def broken():
        raise ValueError("bad record")
    Ctx.bus = Bus()
    with pytest.raises(ValueError, match="bad record"):
        Context.while_cycling(Ctx, broken)


def test_cruise_move_from_a_move_without_a_cruise():
    # a linear ramp: a = 4 rad/s^2, a move of 0.5 rad peaked at sqrt(a d) = 1.414 rad/s
    a, d = 4.0, 0.5
    peak = math.sqrt(a * d)
    distance, speed = analysis.cruise_move(d, peak, 2.0, room=10.0, cruise_time=0.3, margin=1.0)
    assert speed == 2.0
    assert distance == pytest.approx(2.0 ** 2 / a + 2.0 * 0.3)
    # the room too short: the speed lowered until ramps and cruise fit in it
    distance, speed = analysis.cruise_move(d, peak, 2.0, room=1.0, cruise_time=0.3, margin=1.0)
    assert distance == 1.0 and speed < 2.0
    assert speed ** 2 / a + speed * 0.3 == pytest.approx(1.0)
    # the margin is room taken, not speed given
    long, _ = analysis.cruise_move(d, peak, 2.0, room=10.0, cruise_time=0.3, margin=1.3)
    assert long == pytest.approx(1.3 * (1.0 + 0.6))


def test_cruise_move_says_none_when_it_cannot():
    assert analysis.cruise_move(0.5, 0.0, 2.0, room=10.0, cruise_time=0.3) is None          # no peak
    assert analysis.cruise_move(0.5, float("nan"), 2.0, room=10.0, cruise_time=0.3) is None
    assert analysis.cruise_move(0.5, 1.0, 2.0, room=0.0, cruise_time=0.3) is None           # no room
    # room for only a crawl (under a tenth of the cruise asked)
    assert analysis.cruise_move(0.5, 1.0, 2.0, room=0.01, cruise_time=0.3) is None


def test_ramp_time_from_all_six_joints_with_its_uncertainty():
    """Six joints sharing one ramp time (0.5 s), four ramps each, every duration off by up to a record
    (20 cycles/s: +-25 ms) and the cruise at 60 % of full speed: one ramp time from all 24 ramps,
    within its error of the truth -- not the largest of six (that came out 13 % long) -- and each
    joint's acceleration its full speed over it, with an error."""
    rng = random.Random(7)
    vmax = {1: 2.09, 2: 2.09, 3: 2.18, 4: 3.49, 5: 3.49, 6: 6.11}
    true = 0.5
    largest = []
    for trial in range(5):
        ramps = {axis: (0.6 * v, [0.6 * true + rng.uniform(-0.025, 0.025) for _ in range(4)])
                 for axis, v in vmax.items()}
        fit = analysis.ramp_times(ramps, vmax)
        assert fit.shared, fit.words
        assert abs(fit.ramp_time - true) <= max(3.0 * fit.uncertainty, 0.01), (fit.ramp_time, fit.uncertainty)
        assert 0.0 < fit.uncertainty < 0.03
        for axis, (a, da) in fit.accelerations.items():
            assert a == pytest.approx(vmax[axis] / fit.ramp_time) and 0.0 < da < 0.1 * a
        largest.append(max(t for t, _ in fit.per_axis.values()))
        assert "one ramp time for joints 1, 2, 3, 4, 5, 6" in fit.words
    assert max(largest) > true * 1.02         # what taking the largest would have written


def test_ramp_times_of_their_own_keep_each_joint_and_count_the_slowest():
    vmax = {1: 2.0, 2: 2.0, 3: 2.0}
    ramps = {1: (2.0, [0.25, 0.26, 0.25, 0.24]), 2: (1.0, [0.05, 0.051, 0.049, 0.05]), 3: (2.0, [0.1, 0.1, 0.11, 0.09])}
    fit = analysis.ramp_times(ramps, vmax)
    assert not fit.shared
    assert fit.ramp_time == pytest.approx(0.25) and "joint_1's, the slowest" in fit.words
    assert fit.accelerations[2][0] == pytest.approx(2.0 / 0.1)          # 1 rad/s in 0.05 s: full speed in 0.1 s
    assert fit.accelerations[3][0] == pytest.approx(20.0)


DOC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "doc", "commissioning.md")


def test_the_clear_space_is_computed_from_the_moves_and_the_same_everywhere(tmp_path):
    """Every clear-space figure from one function over the moves the steps make (Step.reach): the
    table in doc/commissioning.md is its output at the default sizes; the configuration step's words
    and the docs' row give its 220 / 140 deg and the 250 deg turn back; the start text and
    ``--clear-space`` say the same per joint, with and without skipped steps."""
    from vr_driver.commission.steps import ConfigurationStep, Sizes, clear_space, clear_space_table, clear_space_words
    sizes = Sizes()
    with open(DOC, encoding="utf-8") as fh:
        doc = fh.read()
    assert clear_space_table(sizes) in doc
    space = clear_space(sizes)
    ahead, back = ConfigurationStep().reach(sizes)[6]
    assert (ahead, back) == (2 * sizes.config_turn, 360.0 - 2 * sizes.config_turn)      # 220 one way, 140 the other
    assert space[6] == (max(ahead, 2 * sizes.ramp_move_max), back)                       # the ramps: 240 one way
    assert space[5] == (2 * sizes.ramp_move_max, 0.0) and space[1] == (sizes.ramp_move_max, sizes.speed_move)
    turn_back = sizes.config_turn + back
    assert "turns back %.0f°, to %.0f° the other side" % (turn_back, back) in doc
    assert "goes on %.0f°, to %.0f° from where it stood" % (sizes.config_turn, ahead) in doc

    words = ConfigurationStep().describe(type("Ctx", (), {"sizes": sizes})())      # it reads only the sizes
    assert "turns back %.0f deg, to %.0f deg the other side" % (turn_back, back) in words
    assert "%.0f deg one way and %.0f deg the other" % (ahead, back) in words
    # the start text and --clear-space: the same figures
    port = tmp_path / "ttyUSB7"
    port.write_text("")
    out = io.StringIO()
    assert main(["--port", str(port)], out=out, ask=lambda q: "n") == 1
    said = " ".join(out.getvalue().split())               # the lines unwrapped
    assert "up to %.0f deg from where the arm stands: %s." % (max(f for f, _ in space.values()),
                                                             clear_space_words(sizes)) in said
    out = io.StringIO()
    assert main(["--clear-space", "--skip", "ramps"], out=out) == 0
    assert out.getvalue().startswith("clear space: joint_1 50 deg one way, 20 the other; joint_2 3 deg; "
                                     "joint_6 220 deg one way, 140 the other")


def test_joints_with_accelerations_of_their_own_are_not_averaged():
    """The virtual G2's per-axis accelerations of the pty test (8, 12, 15, 20, 30, 45 rad/s^2): full
    speed in 0.26, 0.17, 0.15, 0.10, 0.17, 0.12 s -- every joint keeps its own figure (the scatter
    must not widen the test of agreement until they all pass)."""
    vmax = {1: 2.094, 2: 2.094, 3: 2.18, 4: 2.094, 5: 5.236, 6: 5.236}
    acc = {1: 8.0, 2: 12.0, 3: 15.0, 4: 20.0, 5: 30.0, 6: 45.0}
    rng = random.Random(2)
    ramps = {axis: (0.6 * vmax[axis], [0.6 * vmax[axis] / acc[axis] * (1 + rng.uniform(-0.03, 0.03)) for _ in range(4)])
             for axis in vmax}
    fit = analysis.ramp_times(ramps, vmax, spacing=0.004)
    assert not fit.shared and "joint_1's, the slowest" in fit.words
    for axis, (a, _) in fit.accelerations.items():
        assert a == pytest.approx(acc[axis], rel=0.05)


def test_a_move_time_is_dated_by_its_brackets_and_a_late_cycle_says_how_unsure_it_is():
    """The speed step's move times (a loop that blocks during a MOVE: no record while it moves): each
    event dated at the middle of the time between the last record without it and the first with it.
    On a bus cycling every 4 ms that is the request times' difference, sure to the cycle; a cycle 30
    ms late at the move's end lengthened the time by all of 30 ms (by request times alone), now by
    half that, and says those 15 ms are unsure -- the step then gives no figure (SPEED_SURE)."""
    from vr_driver.commission.bus import Cycle
    from vr_driver.commission.steps import _move_time
    from vr_driver.driver.link.link import LinkState
    from vr_driver.protocol.common import StatusBits
    from vr_driver.protocol.v3 import StreamState

    class Fb:
        def __init__(self, active, done, moving):
            self.active_seq, self.done_seq = active, done
            self.state = StreamState.MOVING if moving else StreamState.IDLE
            self.status = StatusBits.IN_MOTION if moving else StatusBits(0)

    period = 0.004

    def cycles(late_at_end=0.0):
        """A move from 0.100 s to 0.520 s (the records change in the loop's writes at those times),
        requests every 4 ms -- the one that first shows it done ``late_at_end`` s late."""
        out, t, i = [], 0.0, 0
        while t < 0.7:
            fb = Fb(0, 0, False) if t < 0.100 else Fb(5, 0, True) if t < 0.520 else Fb(5, 5, False)
            out.append(Cycle(i, t, t + 0.002, LinkState.CONNECTED, fb, t + 0.002, b""))
            i += 1
            t = round(t + period, 6)
            if out[-1].feedback.done_seq == 0 and t >= 0.520:
                t = round(t + late_at_end, 6)
        return out
    span, late = _move_time(cycles(), period)
    assert span == pytest.approx(0.420, abs=period) and late == pytest.approx(0.0, abs=1e-9)
    span, late = _move_time(cycles(late_at_end=0.030), period)
    assert span == pytest.approx(0.420 + 0.015, abs=period) and late == pytest.approx(0.015)
    assert _move_time(cycles()[:20], period) is None       # never seen active: no time


def test_one_move_at_speed_from_rounds_that_agree():
    """The speed step's time of one L at speed (a loop that blocks during a MOVE): per round of +L,
    -2L, +L the 2L move less the mean of the L moves; two rounds must agree within SPEED_SURE, or no
    figure is given -- a controller that answered a move late lengthens it with every bus cycle on
    time (a fresh-clone run read x 1.094 for x 1 from one round); a round the bus's own lateness
    leaves unsure is not used, and none usable gives no figure, in words."""
    from vr_driver.commission.steps import SPEED_SURE, _one_move_at_speed
    ok = [(0.468, 0.0), (0.888, 0.0), (0.468, 0.0)]
    d, why = _one_move_at_speed(ok + ok)
    assert d == pytest.approx(0.420) and why == ""
    assert _one_move_at_speed(ok)[0] == pytest.approx(0.420)                   # one round: as before
    late_answer = [(0.468, 0.0), (0.888, 0.0), (0.540, 0.0)]                     # an L move 72 ms long
    d, why = _one_move_at_speed(late_answer + ok)
    assert d is None and "0.384 and 0.420 s for one L at speed" in why, why
    within = [(0.468, 0.0), (0.888 + 0.5 * SPEED_SURE * 0.42, 0.0), (0.468, 0.0)]
    assert _one_move_at_speed(within + ok)[0] == pytest.approx(0.420 + 0.25 * SPEED_SURE * 0.42)
    unsure = [(0.468, 0.0), (0.918, 0.015), (0.468, 0.0)]                        # a cycle late at its end
    assert _one_move_at_speed(unsure + ok)[0] == pytest.approx(0.420)          # the sure round alone
    d, why = _one_move_at_speed(unsure)
    assert d is None and "unsure by up to 15 ms" in why, why
    d, why = _one_move_at_speed([(0.5, 0.0), (0.5, 0.0), (0.5, 0.0)])
    assert d is None and "no longer than the L moves" in why
