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
from vr_driver.commission import analysis
from vr_driver.commission.bus import CommissionBus
from vr_driver.commission.cli import _params, _sizes, build_parser
from vr_driver.commission.report import driver_values
from vr_driver.commission.steps import CardStep, Context, LookAheadStep, LoopStep
from vr_driver.controller.options import LoopTiming, SimOptions
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.driver.commissioned import controller_notes
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
    ctx.seq = bus.feedback.accepted_seq
    return ctx, said


def loop_verdict(kin, loop: float, jitter: float, seed: int) -> Tuple[Dict[str, Any], List[Any], List[str]]:
    g2 = PacedG2(kin, loop_period=loop, loop_jitter=jitter, loop_jitter_seed=seed)
    ctx, said = commission_context(kin, g2, "--loop-move", "10", "--loop-percent", "50")
    CardStep().run(ctx)
    findings = LoopStep().run(ctx)
    return ctx.measured, findings, said
