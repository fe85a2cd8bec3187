"""The virtual G2's command line: ``python3 -m vr_driver.controller`` (``--help``): options
-> :class:`~vr_driver.controller.options.SimOptions` -> a started
:class:`~vr_driver.controller.virtual_controller.VirtualController`, its device path the first line
on stdout, stopped by SIGINT / SIGTERM (:func:`~vr_driver.controller.simulator.run_simulator`). ROS-free."""
from __future__ import annotations

import argparse
import logging
import sys
from typing import IO, Optional, Sequence

from ..kinematics.solver import ConfigurationRule
from ..poses import HOME_POSE
from ..protocol import registry as protocols
from ..protocol.v1 import PROGRAM_PATH_SPEED, PROGRAM_SPEED
from .options import (DEFAULT_ADDRESS, DEFAULT_BAUD, DEFAULT_BRAKE_TIME, DEFAULT_LOOP_PERIOD, PARAM_NAMES, PROTOCOLS,
                      SimOptions)
from .program_v3 import DEFAULT_INTERPRETER_LOOKAHEAD, DEFAULT_RING_SIZE, SendAhead
from .session import Unreachable
from .simulator import EXIT_USAGE, SimError, parse_simulator_args, run_simulator, simulator_parser
from .stream_arm import DEFAULT_RAMP_TIME, RampShape
from .virtual_controller import VirtualController

__all__ = ["main"]

log = logging.getLogger(__name__)


def _parser() -> argparse.ArgumentParser:
    p = simulator_parser(
        "",
        "Virtual Panasonic G2 controller: a PROFIBUS-DP slave (ident 0x06C6) running the "
        "robot-side program of the 14-byte protocol (or, with --protocol v2, the 72-byte "
        "joint-target streaming protocol; with --protocol v3, Cartesian-target streaming "
        "for the G2 as it is) against a simulated VR-006L. Without "
        "--device it creates a pty pair; the first line on stdout is the device path "
        "for the master. Stops cleanly on SIGINT / SIGTERM.")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--pty-link", metavar="PATH",
                       help="create a pty pair and symlink its device end at PATH (removed on exit)")
    where.add_argument("--device", metavar="DEV", help="serve an existing serial device (or pyserial URL)")
    p.add_argument("--addr", type=int, default=DEFAULT_ADDRESS, help="DP slave address (default 4)")
    p.add_argument("--baud", type=int, default=DEFAULT_BAUD, help="DP bit rate (default 19200)")
    p.add_argument("--speed-factor", type=float, default=1.0,
                   help="play motions this many times faster than real time (default 1)")
    p.add_argument("--initial-pose", type=float, nargs=6, metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   default=list(HOME_POSE.as_tuple()),
                   help="start pose in mm / deg (default home 1120 0 725 0 45 0)")
    p.add_argument("--loop-period", type=float, default=DEFAULT_LOOP_PERIOD,
                   help="program loop period in seconds (default 0.01)")
    p.add_argument("--byte-order", choices=("little", "big"), default="little",
                   help="byte order of the int16 words (default little)")
    p.add_argument("--brake-time", type=float, default=DEFAULT_BRAKE_TIME,
                   help="robot time in seconds a stop takes from path speed to rest (default %g; "
                        "0 halts at once)" % DEFAULT_BRAKE_TIME)
    p.add_argument("--protocol", choices=PROTOCOLS, default=protocols.DEFAULT,
                   help="the robot program: v1 the 14-byte Cartesian handshake (default), v2 streamed "
                        "joint targets with look-ahead (72 bytes each way, doc/controller_program.md §9), "
                        "v3 streamed Cartesian targets into a ring (24 bytes out, 28 in, §10)")
    p.add_argument("--interpreter-lookahead", type=int, default=DEFAULT_INTERPRETER_LOOKAHEAD, metavar="N",
                   help="v3: MOVEs the G2's interpreter reads beyond the running one (default %d; 0: the "
                        "arm stops at every point)" % DEFAULT_INTERPRETER_LOOKAHEAD)
    p.add_argument("--ring-size", type=int, default=DEFAULT_RING_SIZE, metavar="N",
                   help="v3: positions in the program's ring (default %d)" % DEFAULT_RING_SIZE)
    p.add_argument("--ramp-time", type=float, default=None, metavar="S",
                   help="v2, v3: robot time in seconds the arm takes from rest to full speed (default: from "
                        "the model's joint limits, max velocity / acceleration, %g s; e.g. 0.5 for an older "
                        "controller)" % DEFAULT_RAMP_TIME)
    p.add_argument("--true-model", metavar="FILE", default=None,
                   help="the simulated robot's own dimensions, joint limits and joint zero offsets: a YAML of "
                        "the layout of kinematics_vr006l.yaml plus zero_offset [rad] per joint (reported angle "
                        "= true angle - zero_offset); default: the model's. The arm and the v3 program's IK "
                        "use it, the driver keeps the model: a robot that differs from the model")
    p.add_argument("--configuration", choices=[r.value for r in ConfigurationRule],
                   default=ConfigurationRule.PREVIOUS_TARGET.value,
                   help="v1, v3: the joint solution the G2 takes for a Cartesian target: nearest the previous "
                        "target's joints (default) or nearest the arm's joints (doc/controller_program.md §7)")
    p.add_argument("--no-data-exchange-bit", dest="data_exchange_bit", action="store_false",
                   help="the program reads only its input bytes, not its card's Data_Exchange status (a G2 "
                        "whose card offers none): v1 then cannot see a reset of the card, v2 / v3 see it in "
                        "the card's safe image (doc/controller_program.md §4 rule 10)")
    g2 = p.add_argument_group("assumptions about the real G2 (doc/controller_program.md §10.9; the defaults "
                              "are the model the driver is tested against)")
    g2.add_argument("--speed-scale", type=float, default=1.0, metavar="K",
                    help="v2, v3: MOVEP's speed unit: the commanded speed times K is the real one, capped at the "
                         "joint limits (default 1: 0.1 %% of the joint speed limits as assumed)")
    g2.add_argument("--loop-blocks-during-move", action="store_true",
                    help="a MOVE blocks the program loop until the motion ended: no record is read and the "
                         "feedback (heartbeat included) is frozen meanwhile (default: the loop keeps running)")
    g2.add_argument("--no-blend-across-input-read", dest="blend_across_input_read", action="store_false",
                    help="v2, v3: the program's input read between two MOVEs ends the blend: an exact stop at "
                         "every point (default: it keeps the blend)")
    g2.add_argument("--loop-jitter", type=float, default=0.0, metavar="S",
                    help="spread of the program loop's period: each drawn uniformly from loop period +- S "
                         "(default 0: a steady loop; below the loop period)")
    g2.add_argument("--loop-jitter-seed", type=int, default=0, metavar="N",
                    help="seed of the loop periods' generator (default 0)")
    g2.add_argument("--send-ahead", choices=[v.value for v in SendAhead], default=SendAhead.ACCEPTED.value,
                    help="v3: a target one number ahead waits (accepted, default) or is refused OUT_OF_ORDER")
    g2.add_argument("--unreachable", choices=[v.value for v in Unreachable], default=Unreachable.SKIP.value,
                    help="an unreachable target is refused and the program goes on (skip, default), or raises "
                         "an alarm that stops the arm and halts the program until the error is cleared "
                         "(alarm_halt)")
    g2.add_argument("--ramp-shape", choices=[v.value for v in RampShape], default=RampShape.LINEAR.value,
                    help="v2, v3: the arm's speed ramps, linear (default) or s_curve (smoothstep, same duration)")
    g2.add_argument("--accelerations", type=float, nargs=6, metavar="A", default=None,
                    help="v2, v3: per-axis acceleration limits in rad/s^2, joint_1 .. joint_6 (the mean over a "
                         "ramp from rest to full speed), instead of --ramp-time (default: none; every joint "
                         "ramps in the ramp time)")
    g2.add_argument("--program-speed", type=float, metavar="M_PER_MIN", default=PROGRAM_SPEED,
                    help="v1: the program's MOVEP speed in m/min (default %g, the documented program's)" % PROGRAM_SPEED)
    g2.add_argument("--program-path-speed", type=float, metavar="M_PER_MIN", default=PROGRAM_PATH_SPEED,
                    help="v1: its MOVEL / MOVEC speed in m/min (default %g)" % PROGRAM_PATH_SPEED)
    p.add_argument("--log-file", metavar="FILE",
                   help="append one JSON line per executed / rejected target")
    return p


def main(argv: Optional[Sequence[str]] = None, stdout: Optional[IO[str]] = None) -> int:
    parser = _parser()
    args = parse_simulator_args(parser, argv)
    out = stdout if stdout is not None else sys.stdout
    try:
        # the options' destinations are the ROS node's parameter names (PARAM_NAMES): one validation
        options = SimOptions.from_mapping({name: getattr(args, name) for name in PARAM_NAMES})
    except SimError as exc:
        parser.print_usage(sys.stderr)
        print("%s: error: %s" % (parser.prog, exc), file=sys.stderr)
        return EXIT_USAGE

    def make() -> VirtualController:
        controller = VirtualController(options.device, **options.controller_kwargs())
        controller.start()
        if controller.symlink:
            log.info("pty %s linked at %s", controller.device_path, controller.symlink)
        return controller
    return run_simulator(parser.prog, make, out, usage=lambda: parser.print_usage(sys.stderr))
