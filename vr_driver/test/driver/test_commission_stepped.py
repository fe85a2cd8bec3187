"""`commission`'s steps against the virtual G2 on the paced 19.2 kbit/s line, stepped with the fake
clock in one thread (no pty, no sleeps: a 20 s watch of the heartbeat costs a fraction of a second):
the thesis' line at 20 bus cycles/s, the G2's program loop as the virtual G2 runs it
(controller.options.LoopTiming: periods drawn from loop_period +- loop_jitter by a seeded generator).

- the loop step against loops of 10-20 ms, steady and +-2-6 ms, five seeds each: the verdict right
  (steady / irregular) or "not resolved" in words -- never "steady" for a jittery loop;
- a loop that blocks during a MOVE: the look-ahead and the ring written as not measured, never as
  values, and the driver keeping its assumptions (a stop at every stream point under v3);
- the card's Data_Exchange bit (both settings): listed as not measurable, with the reason.

The real-time runs over a pty (test_commission.py) show the same tool end to end at other rates."""
from __future__ import annotations

import math
from typing import Any, Dict, List, Tuple

import pytest

from _paced import PacedLink
from _world import FakeClock
from vr_driver.commission.bus import CommissionBus
from vr_driver.commission.cli import _params, _sizes, build_parser
from vr_driver.commission.report import driver_values
from vr_driver.commission.steps import CardStep, Context, LookAheadStep, LoopStep, RampStep
from vr_driver.controller.options import LoopTiming, SimOptions
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.driver.checks.commissioned import controller_notes
from vr_driver.params import DriverParams
from vr_driver.protocol import registry

BAUD = 19200
CYCLE_RATE = 20.0


class PacedG2:
    """The virtual G2's v3 program and arm on a paced line at ``baud`` (no I/O island on it: the
    commissioning runs alone), its loop timed by LoopTiming: ``advance(t)`` runs the loops due."""

    def __init__(self, kin: Any, **options: Any) -> None:
        self.options = SimOptions(protocol="v3", baud=BAUD, **options)
        self.clock = FakeClock()
        self.slave = robot_slave(self.options.address, self.clock, registry.get("v3"))
        arm = ControllerProgramV3.make_arm(kin, self.options, self.clock)
        self.program = ControllerProgramV3.from_options(self.slave, arm, self.options, execution_log=None,
                                                        confirm_records=False, kinematics=kin)
        self.timing = LoopTiming(self.options.loop_period, self.options.loop_jitter, self.options.loop_jitter_seed)
        self.next_loop = self.clock.t
        self.link = PacedLink(self.slave, self, BAUD, island_chars=0)

    def advance(self, until: float) -> None:
        while self.next_loop <= until:
            if self.next_loop > self.clock.t:
                self.clock.t = self.next_loop
            self.program.step(self.clock.t)
            self.next_loop += self.timing.next_period()
        if until > self.clock.t:
            self.clock.t = until

    def sleep(self, seconds: float) -> None:
        self.advance(self.clock.t + max(0.0, seconds))


def commission_context(kin: Any, g2: PacedG2, *args: str) -> Tuple[Context, List[str]]:
    """The tool's context on ``g2``'s line, connected, with the command line's sizes (``args``)."""
    ns = build_parser().parse_args(["--port", "world", "--baud", str(BAUD), "--cycle-rate", str(CYCLE_RATE)]
                                   + list(args))
    bus = CommissionBus(_params(ns, "little"), clock=g2.clock, sleep=g2.sleep,
                        open_link=lambda device, baud: g2.link)
    said: List[str] = []
    sample = bus.connect(10.0)
    assert sample.connected, sample.reason
    ctx = Context(bus, kin, _sizes(ns), said.append)
    # an analysis takes no time on the fake clock: run it in this thread (on the wall clock the tool
    # runs it in a thread of its own while the bus keeps cycling; here that would make the number of
    # bus cycles, and so the run, depend on this machine's speed)
    ctx.while_cycling = lambda fn, *fn_args: fn(*fn_args)
    ctx.seq = bus.feedback.accepted_seq
    return ctx, said


def loop_verdict(kin, loop: float, jitter: float, seed: int, *args: str
                 ) -> Tuple[Dict[str, Any], List[Any], List[str], Dict[str, str]]:
    """The card and loop steps against a G2 whose loop runs ``loop`` +- ``jitter`` (seeded): what
    they measured, the loop step's findings, what the tool said, what it could not measure."""
    g2 = PacedG2(kin, loop_period=loop, loop_jitter=jitter, loop_jitter_seed=seed)
    ctx, said = commission_context(kin, g2, "--loop-move", "10", "--loop-percent", "50", *args)
    CardStep().run(ctx)
    findings = LoopStep().run(ctx)
    return ctx.measured, findings, said, ctx.not_measured


@pytest.mark.parametrize("loop, jitter", [(0.016, 0.004), (0.016, 0.0), (0.010, 0.002), (0.020, 0.006),
                                          (0.020, 0.0)])
def test_the_loop_step_at_19200_bit_s_never_calls_a_jittery_loop_steady(kin, loop, jitter):
    """The issue's case (16 ms +-4 ms: a true spread of 2.3 ms, seen through 50 ms bus cycles) and
    its neighbours, five seeds of the loop's periods each: "steady" only for a steady loop,
    "irregular" with the spread within -35 % / +60 % of the true one for a jittery loop, or "not
    resolved" in words; the spread written only when resolved, else listed as not measured."""
    true = jitter / math.sqrt(3.0)
    for seed in range(5):
        measured, findings, said, not_measured = loop_verdict(kin, loop, jitter, seed)
        rest = findings[0]
        assert rest.assumption == "program loop at rest (heartbeat)"
        assert abs(measured["loop_period"] - loop) < 0.0005, measured
        if rest.ok is None:
            assert "spread not resolved: " in rest.measured and "loop_period_spread" not in measured
            assert "loop_period_spread" in not_measured
            continue
        if jitter:
            assert rest.ok is False and "irregular: spread" in rest.measured, (seed, rest.measured)
            assert 0.65 * true <= measured["loop_period_spread"] <= 1.6 * true, (seed, measured)
        else:
            assert rest.ok is True and "steady: spread under 0.5 ms" in rest.measured, (seed, rest.measured)
        assert "the bus cycle, 50 ms, is longer than the loop" in rest.measured
        # the loop keeps running during the MOVE: said so (the move is 2-3 bus cycles long here)
        assert findings[1].ok is True and findings[1].measured.startswith("runs: "), findings[1].measured


def test_a_steady_20_ms_loop_is_watched_longer_until_it_is_resolved(kin):
    """20 s of a steady 20 ms loop are too few loops at 50 ms cycles to tell 0.5 ms from none: the step
    says so and watches longer (up to 4 times), then calls it steady."""
    measured, findings, said, _ = loop_verdict(kin, 0.020, 0.0, 3, "--heartbeat-time", "12")
    assert any("the loop's spread is not resolved in 12 s at this bus rate: watching" in line for line in said), said
    assert findings[0].ok is True, findings[0].measured


def test_a_loop_that_blocks_during_a_move_leaves_lookahead_and_ring_not_measured(kin):
    """The hidden G2 reads 3 MOVEs ahead and holds 4 in its ring, but its loop blocks during a MOVE:
    the bus hides both. The file lists them as not measured (never ``interpreter_lookahead: 0`` or
    ``ring_size: 1``); the driver takes it (protocol v1), and a user who later moves the program's
    fieldbus part to a parallel task and goes back to v3 with the file gets a stop at every stream
    point (the look-ahead unknown) and the words why, not a look-ahead of 0 as a fact."""
    g2 = PacedG2(kin, loop_period=0.016, loop_blocks_during_move=True, interpreter_lookahead=3, ring_size=4)
    ctx, _said = commission_context(kin, g2, "--loop-move", "10", "--loop-percent", "50", "--heartbeat-time", "3",
                                    "--stream-step", "4", "--stream-percent", "50")
    CardStep().run(ctx)
    LoopStep().run(ctx)
    assert ctx.measured["loop_blocks_during_move"] is True
    findings = LookAheadStep().run(ctx)
    assert "interpreter_lookahead" not in ctx.measured and "ring_size" not in ctx.measured
    assert set(ctx.not_measured) >= {"interpreter_lookahead", "ring_size"}
    rows = {f.assumption: f for f in findings}
    assert rows["interpreter look-ahead (blending through a point)"].ok is None
    assert rows["interpreter look-ahead (blending through a point)"].measured.startswith("not measured")
    assert rows["the program's ring (§10.4 rule 2)"].ok is None
    values = driver_values(ctx.measured, ctx.not_measured)
    facts = values["controller"]
    assert "interpreter_lookahead" not in facts and "ring_size" not in facts
    assert {"interpreter_lookahead", "ring_size"} <= set(facts["not_measured"])
    params = DriverParams.from_dict(dict(values, port="/dev/null"))
    assert params.protocol == "v1" and params.controller.interpreter_lookahead == 1     # the assumption kept
    # later: the fieldbus part in a parallel task, v3 again with this file
    later = dict(values, port="/dev/null", protocol="v3", controller=dict(facts, loop_blocks_during_move=False))
    params = DriverParams.from_dict(later)
    assert params.stream_smooth == 0
    notes = " ".join(controller_notes(params, kin))
    assert "could not measure interpreter_lookahead" in notes and "ring_size" in notes
    assert "every stream point as an exact stop" in notes and "commission again" in notes


@pytest.mark.parametrize("bit", [True, False])
def test_the_data_exchange_bit_is_listed_as_not_measurable_and_the_bus_shows_why(kin, bit):
    """Both settings of the card's Data_Exchange status (§10.9): the card step lists it as not
    measurable, with the reason -- the quickest reset the master can make takes 63 ms at 19.2
    kbit/s, longer than the loop, and a program without the status sees such a reset in the card's
    safe image. Shown: the master's watchdog lets the card go (the bus silent 0.5 s), then it comes
    back: the program disarms and arms again on the idle record either way -- the same on the bus."""
    g2 = PacedG2(kin, loop_period=0.016, data_exchange_bit=bit)
    ctx, _said = commission_context(kin, g2)
    findings = CardStep().run(ctx)
    row = next(f for f in findings if f.assumption.startswith("the card's Data_Exchange status"))
    assert row.ok is None and row.measured.startswith("not measurable from the bus")
    assert "63.0 ms at 19200 bit/s, longer than a loop of 10-20 ms" in row.measured
    g2.sleep(0.5)                                   # no telegram: the card's 300 ms watchdog expires
    assert g2.program.armed is False
    seen: List[bool] = []                          # the armed flag of every record after it

    def back(c) -> bool:
        if c.feedback is not None:
            seen.append(c.feedback.armed)
        return bool(seen) and seen[-1] and False in seen
    ctx.bus.run(back, 10.0, need_link=False)
    assert seen[0] is False and seen[-1] is True


def test_ramps_through_a_slow_bus_and_an_irregular_loop_come_from_every_joint(kin):
    """The issue's slow bus and irregular loop (20 cycles/s, a 16 ms loop +-4 ms) against a G2 whose
    joints all take 0.5 s to full speed: one ramp time from every measured joint's ramps, with its
    error, within 4 errors and 8 % of the truth (eight seeds: -5 .. +2 %, errors 0.010-0.018 s; the
    largest of six figures, what the tool took before: -2 .. +11 %), each sharing joint's
    acceleration within 8 % (one joint off the others -- 0.37 s in two of the eight -- keeps its own
    figure, said)."""
    g2 = PacedG2(kin, loop_period=0.016, loop_jitter=0.004, loop_jitter_seed=6, ramp_time=0.5)
    ctx, said = commission_context(kin, g2)
    CardStep().run(ctx)
    findings = RampStep().run(ctx)
    row = next(f for f in findings if f.assumption.startswith("ramp time"))
    assert "one ramp time for joints" in row.measured, row.measured
    ramp = ctx.measured["ramp_time"]
    error = float(row.measured.split("+-")[1].split()[0])
    assert abs(ramp - 0.5) <= min(4.0 * error, 0.08 * 0.5), (ramp, error)
    # the joints that share it (all, or all but one whose own figure is said): within 8 %
    group = [int(a) for a in row.measured.split("one ramp time for joints ")[1].split(":")[0].split(", ")]
    assert len(group) >= 4 and (len(group) == len(ctx.measured["accelerations"]) or "on its own" in row.measured)
    for axis in group:
        a = ctx.measured["accelerations"][axis]
        assert a == pytest.approx(kin.limits.velocity[axis - 1] / 0.5, rel=0.08), (axis, a)
