"""``rosrun vr_driver commission``: measure the G2's unknowns from the bus and write the driver's
settings (vr_driver/doc/commissioning.md). ROS-free: it needs no roscore, only the serial port --
the driver node must not be running.

The steps (vr_driver.commission.steps) run in order; each says what it will do before the arm moves,
asks (y: run, s: skip, q: stop here; ``--yes``: no questions) and prints its verdict. The end: the
table, the robot time, ONE YAML file (``--out``) for ``driver.launch commissioning:=FILE`` and a
MoveIt ``joint_limits.yaml`` beside it; every bus cycle is logged (``--log``, JSON lines).

Exit status: 0 the run ended (whatever it found), 1 a step could not be run to its end or the
controller could not be reached, 2 bad arguments, 3 the port is in use.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import textwrap
import time
from typing import Callable, List, Optional, Sequence, TextIO

from ..bus.worker import set_priority
from ..errors import VrDriverError
from ..params import DriverParams, ParamError
from .bus import CommissionBus, CommissionError, LinkDown, port_problem, port_users
from .report import joint_limits, table, write_joint_limits, write_yaml
from .steps import (STEP_NAMES, STEPS, Context, Finding, Sizes, StepResult, _Abort, clear_space, clear_space_table,
                    clear_space_words)

__all__ = ["main", "build_parser"]

log = logging.getLogger("vr_driver.commission")

PENDANT = """\
Before you start, at the pendant (doc/commissioning.md, "What to have ready"):
  - the card configured for protocol v3: modules 8 Bytes In x3, 4 Bytes In, 8 Bytes Out x3
    (Chk_Cfg 17 17 17 13 27 27 27), station address {address}, {baud} bit/s
    (doc/controller_program.md section 10.8 step 1);
  - the v3 program (ROSLINK3, section 10.7) loaded and running, override low, the arm's
    e-stop and the pendant's stop at hand;
  - the driver node stopped (this tool needs the port alone);
  - the arm in a clear space, near the middle of each joint's range: the steps turn single joints
    up to {reach:.0f} deg from where the arm stands:
{joints}."""


def build_parser() -> argparse.ArgumentParser:
    d = Sizes()
    p = argparse.ArgumentParser(prog="commission", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="steps: %s" % ", ".join(STEP_NAMES))
    p.add_argument("--port", default="", help="serial device (default: the bus config's, /dev/ttyUSB0)")
    p.add_argument("--baud", type=int, default=None, help="bit rate (default: the bus config's, 19200)")
    p.add_argument("--cycle-rate", type=float, default=20.0, help="bus cycles per second (default 20)")
    p.add_argument("--bus-config", default="", help="pyprofibus bus config YAML (default: the built-in one)")
    p.add_argument("--slave-address", type=int, default=4, help="the controller's DP address (default 4)")
    p.add_argument("--watchdog-ms", type=int, default=None,
                   help="the card's DP watchdog [ms] (default: the bus config's, 300)")
    p.add_argument("--byte-order", choices=("little", "big"), default="little",
                   help="the byte order tried first (the other is tried if the records fail)")
    p.add_argument("--model", default="", help="kinematics YAML of the arm (default: the package's model)")
    p.add_argument("--out", default="commissioning.yaml", help="the YAML written at the end (default %(default)s)")
    p.add_argument("--log", default="", help="every bus cycle as JSON lines (default: OUT with .cycles.jsonl)")
    p.add_argument("--yes", action="store_true", help="ask nothing: the arm's space is clear, run every step")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run the bus at SCHED_FIFO priority N (1..99) where the system allows it, as the "
                        "driver's bus process does (doc/reliability.md, \"Real-time priority\"): the tool "
                        "dates the program loop to the millisecond; its analyses stay at normal priority "
                        "(default 0: normal scheduling)")
    p.add_argument("--skip", action="append", default=[], metavar="NAME",
                   help="skip a step (repeat, or a comma list): %s" % ", ".join(STEP_NAMES))
    p.add_argument("--clear-space", action="store_true",
                   help="print how far the steps (less --skip, at these sizes) turn each joint from where the arm "
                        "stands, and exit: nothing is opened or sent")
    g = p.add_argument_group("sizes of the moves (degrees, percent of the joint speed limits, seconds)")
    g.add_argument("--connect-timeout", type=float, default=d.connect_timeout)
    g.add_argument("--heartbeat-time", type=float, default=d.heartbeat_time, help="loop: seconds at rest")
    g.add_argument("--loop-move", type=float, default=d.loop_move, help="loop: joint_6 move during which it is watched")
    g.add_argument("--loop-percent", type=float, default=d.loop_percent)
    g.add_argument("--speed-joint", type=int, default=d.speed_joint, choices=range(1, 7))
    g.add_argument("--speed-move", type=float, default=d.speed_move, help="speed: L of the moves +L, -2L, +L")
    g.add_argument("--speed-percent", type=float, default=d.speed_percent)
    g.add_argument("--stream-points", type=int, default=d.stream_points)
    g.add_argument("--stream-step", type=float, default=d.stream_step, help="lookahead: joint_1 per point")
    g.add_argument("--stream-percent", type=float, default=d.stream_percent)
    g.add_argument("--config-turn", type=float, default=d.config_turn, help="configuration: joint_6 turn (90..180)")
    g.add_argument("--config-percent", type=float, default=d.config_percent)
    g.add_argument("--axes", default=",".join(str(a) for a in d.ramp_axes), help="ramps: the joints (1..6)")
    g.add_argument("--ramp-move", type=float, default=d.ramp_move, help="ramps: joints 1-4 (joints 5-6 twice)")
    g.add_argument("--ramp-move-max", type=float, default=d.ramp_move_max,
                   help="ramps: a joint that reaches no cruise speed moves again, up to this far (joints 5-6 twice)")
    g.add_argument("--ramp-percent", type=float, default=d.ramp_percent)
    g.add_argument("--hold-time", type=float, default=d.hold_time,
                   help="seconds a record that must not be taken is held (at least 10 loops)")
    p.add_argument("-v", "--verbose", action="count", default=0)
    return p


def _sizes(args: argparse.Namespace) -> Sizes:
    try:
        axes = tuple(int(a) for a in str(args.axes).replace(" ", "").split(",") if a)
    except ValueError:
        raise ValueError("--axes: a comma list of joints 1..6, got %r" % args.axes) from None
    if not axes or any(not 1 <= a <= 6 for a in axes):
        raise ValueError("--axes: a comma list of joints 1..6, got %r" % args.axes)
    for name in ("heartbeat_time", "loop_move", "loop_percent", "speed_move", "speed_percent", "stream_step",
                 "stream_percent", "config_percent", "ramp_move", "ramp_move_max", "ramp_percent", "hold_time",
                 "connect_timeout"):
        value = getattr(args, name)
        if not value > 0:
            raise ValueError("--%s must be > 0, got %r" % (name.replace("_", "-"), value))
    for name in ("loop_percent", "speed_percent", "stream_percent", "config_percent", "ramp_percent"):
        if getattr(args, name) > 100:
            raise ValueError("--%s must be at most 100, got %r" % (name.replace("_", "-"), getattr(args, name)))
    if args.stream_points < 3:
        raise ValueError("--stream-points must be at least 3, got %d" % args.stream_points)
    return Sizes(connect_timeout=args.connect_timeout, heartbeat_time=args.heartbeat_time, loop_move=args.loop_move,
                 loop_percent=args.loop_percent, speed_joint=args.speed_joint, speed_move=args.speed_move,
                 speed_percent=args.speed_percent, stream_points=args.stream_points, stream_step=args.stream_step,
                 stream_percent=args.stream_percent, config_turn=args.config_turn,
                 config_percent=args.config_percent, ramp_axes=axes, ramp_move=args.ramp_move,
                 ramp_move_max=max(args.ramp_move, args.ramp_move_max), ramp_percent=args.ramp_percent,
                 hold_time=args.hold_time)


def _params(args: argparse.Namespace, byte_order: str) -> DriverParams:
    cycle = float(args.cycle_rate)
    watchdog = args.watchdog_ms
    return DriverParams.from_dict({
        "protocol": "v3", "port": args.port, "baud": args.baud, "cycle_rate": cycle,
        "bus_config": args.bus_config, "slave_address": args.slave_address, "byte_order": byte_order,
        "watchdog_ms": watchdog, "model": args.model, "bus_process": False,
        "link_timeout": max(0.5, 4.0 / cycle, (watchdog or 0) / 1000.0),
        "stop_settle_time": max(0.25, 2.0 / cycle), "joint_command_timeout": max(0.2, 2.0 / cycle),
        "bus_node_timeout": max(3.0, 2.0 / cycle), "reconnect_period": 0.5})


class _Runner:
    def __init__(self, args: argparse.Namespace, out: TextIO, ask: Callable[[str], str]) -> None:
        self.args = args
        self.out = out
        self.ask = ask
        self.clock = time.monotonic

    def say(self, text: str = "") -> None:
        self.out.write(text + "\n")
        self.out.flush()

    def confirm(self, question: str, choices: str = "yn") -> str:
        """The user's answer, one of ``choices`` (the first is the default on an empty line; EOF is
        'q' when offered, else 'n')."""
        while True:
            try:
                answer = self.ask(question).strip().lower()
            except EOFError:
                return "q" if "q" in choices else "n"
            if not answer:
                return choices[0]
            if answer[0] in choices:
                return answer[0]

    # ------------------------------------------------------------------------------ connect
    def connect(self, sizes: Sizes) -> Optional[CommissionBus]:
        """The bus with the link up, in the byte order the program writes (the other one tried when
        the records fail the check word); None (said why) when it cannot be reached."""
        orders = [self.args.byte_order, "big" if self.args.byte_order == "little" else "little"]
        why = ""
        for i, order in enumerate(orders):
            bus = CommissionBus(_params(self.args, order))
            sample = bus.connect(sizes.connect_timeout if i == 0 else max(3.0, sizes.connect_timeout / 3))
            if sample.connected:
                return bus
            why = sample.error_reason or sample.reason
            bus.supervisor.close()
            if "check word" not in why and "invalid feedback" not in why:
                break
            self.say("  the records fail in %s byte order (%s): trying %s" % (order, why, orders[1]))
        self.say("cannot reach the controller: %s" % why)
        if "Cfg_Fault" in why or "rejects the configuration" in why:
            self.say("  the card is not configured for v3: at the pendant set its modules to 8 Bytes In x3, "
                     "4 Bytes In, 8 Bytes Out x3 (17 17 17 13 27 27 27) and try again (section 10.8 step 1)")
        return None

    # ------------------------------------------------------------------------------ the run
    def run(self) -> int:
        args = self.args
        try:
            sizes = _sizes(args)
            params = _params(args, args.byte_order)
            bus_config = params.bus()
        except (ValueError, ParamError) as exc:
            self.say("commission: %s" % exc)
            return 2
        if not 0 <= args.rt_priority <= 99:
            self.say("commission: --rt-priority %d: give 0 (normal scheduling) or 1..99" % args.rt_priority)
            return 2
        skip = {name.strip() for item in args.skip for name in item.split(",") if name.strip()}
        unknown = sorted(skip - set(STEP_NAMES))
        if unknown:
            self.say("commission: unknown step %s (steps: %s)" % (", ".join(unknown), ", ".join(STEP_NAMES)))
            return 2
        if args.clear_space:
            self.say("clear space: %s (deg from where the arm stands)" % (
                clear_space_words(sizes, tuple(skip)) or "none (no step moves)"))
            if not skip:
                self.say(clear_space_table(sizes))
            return 0
        device = bus_config.phy.device
        problem = port_problem(device)
        if problem:
            self.say("commission: %s" % problem)          # at once: not after the connect timeout
            return 1
        users = port_users(device)
        if users:
            self.say("commission: %s is open by %s -- stop the driver (and anything else on the port) first: "
                     "the commissioning needs the port alone" % (device, "; ".join(
                         "pid %d (%s)" % (pid, cmd[:80]) for pid, cmd in users)))
            return 3
        from ..kinematics.solver import Kinematics
        try:
            kin = Kinematics.from_true_model(params.model or None)
        except VrDriverError as exc:
            self.say("commission: the model: %s" % exc)
            return 2
        space = clear_space(sizes, tuple(skip))
        reach = max([far for far, _ in space.values()] or [0.0])
        self.say(PENDANT.format(address=bus_config.slaves[0].address, baud=bus_config.baud, reach=reach,
                                joints=textwrap.fill(clear_space_words(sizes, tuple(skip)) or "none (no step moves)",
                                                     98, initial_indent="      ", subsequent_indent="      ")))
        self.say()
        if not args.yes and self.confirm("Is the arm in a clear space and the program running? [y/N] ", "ny") != "y":
            self.say("not started: nothing was sent")
            return 1
        log_path = args.log or os.path.splitext(args.out)[0] + ".cycles.jsonl"
        results: List[StepResult] = []
        self.say("scheduling: %s" % set_priority(args.rt_priority))
        t_connect = self.clock()
        self.say("connecting to %s at %d bit/s (%g cycles/s)..." % (device, bus_config.baud, args.cycle_rate))
        try:
            bus = self.connect(sizes)
        except (VrDriverError, OSError) as exc:
            self.say("cannot open the bus: %s" % exc)
            return 1
        if bus is None:
            return 1
        connect_time = self.clock() - t_connect
        ctx = Context(bus, kin, sizes, self.say)
        ctx.measured["byte_order_tried"] = args.byte_order
        ctx.seq = bus.feedback.accepted_seq if bus.feedback is not None else 0
        failed = False
        try:
            with open(log_path, "w", encoding="utf-8") as log_fh:
                for i, step in enumerate(STEPS):
                    result = StepResult(step.name)
                    results.append(result)
                    self.say()
                    self.say("[%d/%d] %s: %s" % (i + 1, len(STEPS), step.name, step.title))
                    if step.name in skip:
                        result.status = "skipped"
                        self.say("  skipped (--skip)")
                        continue
                    self.say("  " + step.describe(ctx))
                    if not args.yes:
                        answer = self.confirm("  run it? [Y]es / [s]kip / [q]uit: ", "ysq")
                        if answer == "s":
                            result.status = "skipped"
                            continue
                        if answer == "q":
                            result.status = "skipped"
                            break
                    t0 = self.clock()
                    stop = False
                    try:
                        result.findings = step.run(ctx)
                    except _Abort as exc:
                        result.findings, result.status, result.error, stop = exc.findings, "failed", str(exc), True
                    except LinkDown as exc:
                        result.status, result.error, stop = "failed", str(exc), True
                    except CommissionError as exc:
                        result.status, result.error = "failed", str(exc)
                    result.seconds = self.clock() - t0 + (connect_time if step.name == "card" else 0.0)
                    bus.dump(log_fh)
                    for f in result.findings:
                        self.say("  %s %s: %s" % ({True: "ok     ", False: "DIFFERS", None: "--     "}[f.ok],
                                                  f.assumption, f.measured))
                    if result.error:
                        failed = True
                        self.say("  step failed: %s" % result.error)
                    self.say("  (%.1f s)" % result.seconds)
                    if stop or (step.name == "unreachable" and ctx.measured.get("unreachable") == "alarm_halt"):
                        if ctx.measured.get("unreachable") == "alarm_halt":
                            self.say("  the program halted: reset the alarm at the pendant and start the program "
                                     "again before the driver connects")
                        break
        finally:
            bus.close()
        if "card" in skip:
            connect_step = next(r for r in results if r.name == "card")
            connect_step.seconds = connect_time
        robot_time = sum(r.seconds for r in results)
        findings: List[Finding] = [f for r in results for f in r.findings]
        self.say()
        self.say("=" * 100)
        self.say(table(findings))
        self.say("=" * 100)
        self.say("robot time: %.1f s (%s)" % (robot_time, ", ".join(
            "%s %.1f s" % (r.name, r.seconds) for r in results if r.status != "skipped" or r.seconds)))
        measured = dict(ctx.measured)
        measured.pop("byte_order_tried", None)
        limits = joint_limits(kin.limits.names, kin.limits.velocity, kin.limits.acceleration, measured)
        limits_path = os.path.join(os.path.dirname(os.path.abspath(args.out)), "joint_limits.yaml")
        write_yaml(args.out, measured, ctx.identity, results, limits_path, robot_time,
                   not_measured=ctx.not_measured)
        write_joint_limits(limits_path, limits, args.out, sorted((measured.get("accelerations") or {}).keys()))
        self.say("written: %s (driver.launch commissioning:=%s), %s, the bus log %s"
                 % (args.out, os.path.abspath(args.out), limits_path, log_path))
        return 1 if failed else 0


def main(argv: Optional[Sequence[str]] = None, out: Optional[TextIO] = None,
         ask: Optional[Callable[[str], str]] = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING - 10 * min(args.verbose, 2),
                        format="%(levelname)s %(name)s: %(message)s")
    stream = out or sys.stdout

    def default_ask(question: str) -> str:
        stream.write(question)
        stream.flush()
        line = sys.stdin.readline()
        if not line:
            raise EOFError
        return line

    return _Runner(args, stream, ask or default_ask).run()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

