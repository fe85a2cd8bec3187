"""The virtual G2 controller: a DP slave running the robot-side program of doc/controller_program.md against a
simulated arm. ROS-free.

Pieces:

- :class:`~vr_driver.controller.arm.SimArm` (``controller/arm.py``): joints, planned motions played back
  ``speed_factor`` times faster, e-stop / drives / error, whole-mm/deg pose reports.
- :class:`ControllerProgram`: the program loop. Each :meth:`~ControllerProgram.step` (``now``
  injected) checks the DP watchdog, reads the slave's output image (the master's command), runs
  :class:`~vr_driver.protocol.v1.ControllerHandshake` and the arm, and writes the
  :class:`~vr_driver.protocol.v1.Feedback` into the slave's input image. Every handled request becomes
  one :class:`~vr_driver.controller.arm.LogEntry` in the :class:`~vr_driver.controller.arm.ExecutionLog`.
- :class:`VirtualController`: a :class:`~pyprofibus_vendor.DpSlave` (ident 0x06C6, address 4, the
  default Chk_Cfg ``13 13 13 11 23 23 23 21``) served on a pty pair it creates (optionally
  symlinked), on a device, or on any link, plus the program loop in a thread at a fixed period.
- Protocol v2 (``protocol="v2"``, ``--protocol v2``): the slave takes ``CHK_CFG_V2`` (72 bytes each
  way) and runs :class:`~vr_driver.controller.program_v2.ControllerProgramV2` on a
  :class:`~vr_driver.controller.stream_arm.SimStreamArm` (streamed joint targets, look-ahead blending); the
  link-side rules below are shared (:mod:`vr_driver.controller.session`).
- Protocol v3 (``protocol="v3"``, ``--protocol v3``): the slave takes ``CHK_CFG_V3`` (28 bytes in,
  24 out) and runs :class:`~vr_driver.controller.program_v3.ControllerProgramV3` (Cartesian targets
  into a ring of ``ring_size`` positions, solved by the controller's own IK, run as MOVEP with an
  ``interpreter_lookahead`` of MOVEs read ahead) on a SimStreamArm. The program is chosen by the
  protocol's capabilities (``streams``, ``joint_targets``), never by its name.
- :func:`main`: ``python3 -m vr_driver.controller.program`` (see ``--help``).

Rules of the program (also in ``doc/controller_program.md``):

- Only a record the master sent in the current Data_Exchange session counts (a session starts
  each time the slave enters Data_Exchange). Outside Data_Exchange, and in a new session before
  the master's first Data_Exchange, there is no command (flag 0); the slave itself replaces its
  outputs by the safe image (all zero) when it leaves Data_Exchange.
- Two-telegram rule (``confirm_records``, the VirtualController's default for v1): a record counts
  only once it arrived unchanged in two consecutive Data_Exchange telegrams of the session (the
  master repeats its record every cycle, so this costs one bus cycle per change). Protocol v2 does
  not need it: its records carry a CRC-16 (§9.3 rule 7), and the program acts on a record at the
  first telegram that brings it. A telegram corrupted
  on the line in a way the PROFIBUS checks miss (the 8-bit FCS passes about 1 in 256 multi-byte
  corruptions) is then never acted on; without the rule such a telegram can start a wrong
  target, re-start the previous one (flag 0 turned into 1), or release a DONE early so that the
  still raised flag starts the same target again.
- Disarmed at start and after every link loss: a request counts only after a record with the flag
  at 0 (it arms the program when it arrives, even if the program loop never saw it: the flag may
  rise in the very next telegram). A flag still raised from before the loss is answered REJECTED (held until the flag drops,
  logged with the reason) and nothing moves, so a motion never starts from a stale request.
- Exactly once across a reset (doc/controller_program.md §4 rule 10): after the card's watchdog or
  a new Set_Prm the program takes a new command only after the idle record came in a Data_Exchange
  of the new session. That the program can tell is an assumption about the G2,
  ``data_exchange_bit`` (VirtualController / SimOptions, ``--no-data-exchange-bit``; default True:
  it reads its card's Data_Exchange status). Without it the program reads only its input bytes
  (:mod:`vr_driver.controller.session`): v1 cannot see a reset then -- the card's safe image is its
  idle record -- and no link loss stops the arm; the master's idle record at the start of every
  session is what keeps v1 exactly once; v2 and v3 see the safe image (no record of theirs) and
  stop, disarm as with the bit.
- Link loss (the DP watchdog expired, or the master re-parameterised the slave -- also when it
  did so between two loops): the arm stops at
  once -- at the position of the watchdog deadline, so it never moves longer than the watchdog
  time after the master's last telegram --, the target in flight ends REJECTED in the log, the via
  point is dropped and the handshake restarts at READY. The master must send a new target.
- Flag 2 (stop, ``Command.stop``) while BUSY is a controlled stop: the arm decelerates along its
  path over ``brake_time`` (default 0.3 s of robot time; 0 halts at once) with IN_MOTION set, and
  the target ends REJECTED once the arm is at rest (the state stays BUSY until then). Outside BUSY
  flag 2 is "no request".
- E-stop, drives off or an error during a motion stop the arm at once (controller.arm); the target ends
  REJECTED (state 3, held until the flag drops). While any of them is active a request is
  REJECTED and the status bits say which (ESTOP; DRIVES_POWERED clear; ERROR). The e-stop switches
  the drives off; after it is released they stay off until switched on again (``set_fault
  ("drives_powered", True)``, the node's ``~set_drives_powered`` service), as on a real G2.
- A target the arm cannot reach or plan (outside the reach, joint limits, joint jump, singular,
  degenerate circle) is REJECTED without motion; a CIRC_END without a stored via as well.
- A record the program cannot decode (flag byte not 0/1/2, unknown move type) is treated as flag 0
  and counted in :attr:`ControllerProgram.bad_records` (a log warning names the bytes); the
  master then sees no answer and times out.
- PROGRAM_RUNNING is set in every record the program writes.

**Every assumption about the real G2 is a parameter** (:data:`ASSUMPTIONS`, the table in
doc/controller_program.md §10.9; each a SimOptions field, a ``--option`` of the CLI and a ``~param``
of the ROS node; the defaults are the model the rest of the stack is tested against): the card's
``byte_order``, the program's ``loop_period`` and its spread ``loop_jitter`` (seeded by
``loop_jitter_seed``, :class:`LoopTiming`), ``loop_blocks_during_move`` and ``unreachable``
(:mod:`vr_driver.controller.session`), ``data_exchange_bit``, ``configuration``, v3's
``interpreter_lookahead`` and ``send_ahead`` (:mod:`vr_driver.controller.program_v3`), and the
streaming arm's ``speed_scale`` (MOVEP's speed unit), ``blend_across_input_read``, ``ramp_time``,
``ramp_shape`` and ``accelerations`` (:mod:`vr_driver.controller.stream_arm`).
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import random
import re
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import IO, Any, Callable, Dict, Mapping, Optional, Sequence, Tuple, Union

from pyprofibus_vendor.config import default_robot_config
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer, SlaveState
from pyprofibus_vendor.errors import PhyError, ProfibusError
from pyprofibus_vendor.phy import Link
from pyprofibus_vendor.phy_serial import PtyPair, SerialLink, open_pty_pair

from .. import validate
from ..errors import ProtocolError, VrDriverError
from ..kinematics.solver import ConfigurationRule, Kinematics
from ..poses import HOME_POSE, ControllerPose
from .session import SessionProgram, Unreachable, arm_status_bits
from .program_v2 import ControllerProgramV2
from .program_v3 import DEFAULT_INTERPRETER_LOOKAHEAD, DEFAULT_RING_SIZE, ControllerProgramV3, SendAhead
from ..protocol.v1 import ByteOrder, Command, ControllerHandshake, ControllerState, Feedback, StatusBits
from ..protocol.v2 import FeedbackV2, StreamState
from ..protocol.v3 import FeedbackV3
from ..protocol import registry as protocols
from ..protocol.base import Protocol
from .arm import ExecutionLog, IntPose, LogEntry, MotionResult, Outcome, SimArm
from .stream_arm import DEFAULT_RAMP_TIME, RampShape, SimStreamArm, StreamLogEntry, check_accelerations

__all__ = [
    "ASSUMPTIONS",
    "DEFAULT_ADDRESS",
    "DEFAULT_BAUD",
    "DEFAULT_LOOP_PERIOD",
    "FAULTS",
    "LoopTiming",
    "PARAM_NAMES",
    "PROTOCOLS",
    "SimError",
    "SimDeviceError",
    "SimOptions",
    "ControllerProgram",
    "Simulator",
    "VirtualController",
    "SimPort",
    "robot_slave",
    "main",
    "run_simulator",
]

log = logging.getLogger(__name__)

Clock = Callable[[], float]

DEFAULT_ADDRESS = 4
DEFAULT_BAUD = 19200
DEFAULT_LOOP_PERIOD = 0.01
#: robot time [s] a controlled stop takes to bring the arm from path speed to rest
DEFAULT_BRAKE_TIME = 0.3

#: exit codes of the command line
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_DEVICE = 0, 1, 2, 3

FAULTS = ("estop", "drives_powered", "error")

#: ROS private parameter name -> SimOptions field
PARAM_NAMES = {"pty_link": "pty_link", "device": "device", "addr": "address", "baud": "baud",
               "speed_factor": "speed_factor", "initial_pose": "initial_pose", "loop_period": "loop_period",
               "byte_order": "byte_order", "log_file": "log_file", "brake_time": "brake_time",
               "protocol": "protocol", "interpreter_lookahead": "interpreter_lookahead",
               "ring_size": "ring_size", "ramp_time": "ramp_time", "true_model": "true_model",
               "configuration": "configuration", "data_exchange_bit": "data_exchange_bit",
               "speed_scale": "speed_scale", "loop_blocks_during_move": "loop_blocks_during_move",
               "blend_across_input_read": "blend_across_input_read", "loop_jitter": "loop_jitter",
               "loop_jitter_seed": "loop_jitter_seed", "send_ahead": "send_ahead", "unreachable": "unreachable",
               "ramp_shape": "ramp_shape", "accelerations": "accelerations"}

#: the SimOptions fields that are assumptions about the real G2 (doc/controller_program.md §10.9, one
#: row each): what a commissioning measures and the virtual G2 lets a test set either way
ASSUMPTIONS = ("byte_order", "loop_period", "loop_jitter", "loop_blocks_during_move", "data_exchange_bit",
               "configuration", "interpreter_lookahead", "blend_across_input_read", "send_ahead",
               "unreachable", "speed_scale", "ramp_time", "ramp_shape", "accelerations")

#: the controller programs (vr_driver.protocol): v1 the thesis' 14-byte handshake (default), v2
#: streamed joint targets, v3 streamed Cartesian targets for the G2 as it is
PROTOCOLS = protocols.names()


class SimError(VrDriverError):
    """A bad virtual-controller option (the message names it), or its device cannot be served."""


class SimDeviceError(SimError):
    """The link / device / pty / symlink cannot be created or served."""


# ------------------------------------------------------------------------------------------- options

def _positive(value: Any, name: str) -> float:
    return validate.number(value, lambda _: SimError("%s must be a finite number > 0, got %r" % (name, value)),
                           0.0, lo_open=True)


def _int_option(value: Any, name: str, lo: int, hi: int) -> int:
    def fail(got: Optional[float]) -> SimError:
        if got is None:
            return SimError("%s must be an integer in %d..%d, got %r" % (name, lo, hi, value))
        return SimError("%s = %d is outside %d..%d" % (name, got, lo, hi))
    return validate.integer(value, fail, lo, hi, text=True, integral=True)


@dataclass(frozen=True)
class SimOptions:
    """The virtual controller's settings, validated (CLI options and ROS private parameters both
    end up here). ``device``: serve this existing device; else a pty pair is created and, with
    ``pty_link``, its device end is symlinked there."""

    device: Optional[str] = None
    pty_link: Optional[str] = None
    address: int = DEFAULT_ADDRESS
    baud: int = DEFAULT_BAUD
    speed_factor: float = 1.0
    initial_pose: Tuple[float, ...] = HOME_POSE.as_tuple()
    loop_period: float = DEFAULT_LOOP_PERIOD
    byte_order: str = ByteOrder.LITTLE.value
    log_file: Optional[str] = None
    brake_time: float = DEFAULT_BRAKE_TIME
    protocol: str = protocols.DEFAULT
    #: protocol v3: MOVEs the G2's interpreter reads beyond the running one (0: a stop at every
    #: point); the positions of the program's ring
    interpreter_lookahead: int = DEFAULT_INTERPRETER_LOOKAHEAD
    ring_size: int = DEFAULT_RING_SIZE
    #: protocol v2 / v3: robot time [s] the streaming arm takes from rest to full speed (the limiting
    #: joint accelerates at vmax / ramp_time); None: from the model's joint limits, max velocity /
    #: acceleration (0.1 s; an assumption to measure); e.g. 0.5 for an older controller. v1's arm
    #: ramps over a share of each move instead and ignores it
    ramp_time: Optional[float] = None
    #: the simulated robot's own kinematics: a YAML of the layout of kinematics_vr006l.yaml (plus
    #: ``zero_offset`` per joint, panasonic_vr006l_support.true_model); None: the model's. The arm
    #: (its FK, the pose it reports) and the v3 program's IK use it; v2 joints are its angles
    true_model: Optional[str] = None
    #: the G2 program can read its card's Data_Exchange status (an assumption, doc/controller_program.md
    #: §7 / §10.9): it sees every reset of the card and takes the master's records of the new session
    #: only. False: it reads nothing but its input bytes (controller.session)
    data_exchange_bit: bool = True
    #: v1, v3: the joint solution the G2 takes for a Cartesian target (kinematics.solver.ConfigurationRule,
    #: an assumption, doc/controller_program.md §7): previous_target or current_joints
    configuration: Any = ConfigurationRule.PREVIOUS_TARGET.value
    #: v2 / v3: MOVEP's speed unit -- the commanded speed fraction times this is the arm's real one
    #: (capped at the joint limits): 1.0 the assumed 0.1 % of the joint limits; e.g. 0.6
    speed_scale: float = 1.0
    #: every protocol: a MOVE blocks the program loop until the motion ended (no record read, the
    #: feedback frozen meanwhile); False: the loop keeps running while the arm moves
    loop_blocks_during_move: bool = False
    #: v2 / v3: the program's read of its inputs between two MOVEs keeps the blend (True) or ends it
    #: in an exact stop at every point (False)
    blend_across_input_read: bool = True
    #: every protocol: the spread [s] of the program loop's period, each period drawn uniformly from
    #: loop_period +- loop_jitter (0: a steady loop), from a generator seeded with loop_jitter_seed
    loop_jitter: float = 0.0
    loop_jitter_seed: int = 0
    #: v3: a target one number ahead waits (accepted) or is refused OUT_OF_ORDER (refused)
    send_ahead: str = SendAhead.ACCEPTED.value
    #: every protocol: an unreachable target is refused and the program goes on (skip), or raises an
    #: alarm that halts the program (alarm_halt)
    unreachable: str = Unreachable.SKIP.value
    #: v2 / v3: the arm's speed ramps, linear or s_curve
    ramp_shape: str = RampShape.LINEAR.value
    #: v2 / v3: per-axis acceleration limits [rad/s^2] (6 numbers, the mean over a ramp from rest to
    #: full speed), instead of one ramp_time for every joint; None: ramp_time's model
    accelerations: Optional[Tuple[float, ...]] = None

    def __post_init__(self) -> None:
        _protocol(self.protocol)
        for name in ("device", "pty_link", "log_file", "true_model"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                raise SimError("%s must be a path, got %r" % (name, value))
            object.__setattr__(self, name, value or None)
        if self.device and self.pty_link:
            raise SimError("give either device (serve an existing device) or pty_link (create a pty "
                           "and link it there), not both")
        object.__setattr__(self, "address", _int_option(self.address, "addr", 0, 125))
        object.__setattr__(self, "baud", _int_option(self.baud, "baud", 9600, 12_000_000))
        object.__setattr__(self, "interpreter_lookahead",
                           _int_option(self.interpreter_lookahead, "interpreter_lookahead", 0, 100))
        object.__setattr__(self, "ring_size", _int_option(self.ring_size, "ring_size", 1, 1000))
        try:  # the DP bit rates, checked by the bus configuration
            default_robot_config("virtual", self.baud, phy_type="memory", slave_address=self.address)
        except ProfibusError as exc:
            raise SimError(str(exc)) from exc
        object.__setattr__(self, "speed_factor", _positive(self.speed_factor, "speed_factor"))
        object.__setattr__(self, "loop_period", _positive(self.loop_period, "loop_period"))
        object.__setattr__(self, "brake_time", validate.number(self.brake_time, lambda _: SimError(
            "brake_time must be a finite number >= 0 (seconds), got %r" % (self.brake_time,)), 0.0))
        if self.ramp_time is not None:
            object.__setattr__(self, "ramp_time", validate.number(self.ramp_time, lambda _: SimError(
                "ramp_time must be a finite number > 0 (seconds of robot time from rest to full speed), "
                "got %r" % (self.ramp_time,)), 0.0, lo_open=True))
        if self.true_model:
            _check_true_model(self.true_model)
        for name in ("data_exchange_bit", "loop_blocks_during_move", "blend_across_input_read"):
            if not isinstance(getattr(self, name), bool):
                raise SimError("%s must be true or false, got %r" % (name, getattr(self, name)))
        object.__setattr__(self, "speed_scale", validate.number(self.speed_scale, lambda _: SimError(
            "speed_scale must be a finite number in (0, 10] (the real speed per commanded speed), got %r"
            % (self.speed_scale,)), 0.0, 10.0, lo_open=True))
        object.__setattr__(self, "loop_jitter", validate.number(self.loop_jitter, lambda _: SimError(
            "loop_jitter must be a finite number >= 0 and below loop_period (%g s), got %r"
            % (self.loop_period, self.loop_jitter)), 0.0))
        if self.loop_jitter >= self.loop_period:
            raise SimError("loop_jitter must be a finite number >= 0 and below loop_period (%g s), got %r"
                           % (self.loop_period, self.loop_jitter))
        object.__setattr__(self, "loop_jitter_seed",
                           _int_option(self.loop_jitter_seed, "loop_jitter_seed", 0, 2 ** 32 - 1))
        for name, kind in (("send_ahead", SendAhead), ("unreachable", Unreachable), ("ramp_shape", RampShape)):
            try:
                object.__setattr__(self, name, kind.parse(getattr(self, name)).value)
            except VrDriverError as exc:
                raise SimError(str(exc)) from None
        try:
            object.__setattr__(self, "accelerations", check_accelerations(_numbers(self.accelerations)))
        except VrDriverError as exc:
            raise SimError(str(exc)) from None
        if self.accelerations is not None and self.ramp_time is not None:
            raise SimError("give ramp_time (every joint ramps in that time) or accelerations (per axis), not both")
        try:
            object.__setattr__(self, "configuration", ConfigurationRule.parse(self.configuration).value)
        except VrDriverError as exc:
            raise SimError("configuration: %s" % exc) from None
        try:
            pose = ControllerPose.from_sequence(self.initial_pose)
        except VrDriverError as exc:
            raise SimError("initial_pose: %s" % exc) from exc
        object.__setattr__(self, "initial_pose", pose.as_tuple())
        try:
            object.__setattr__(self, "byte_order", ByteOrder.parse(self.byte_order).value)
        except ProtocolError as exc:
            raise SimError(str(exc)) from exc

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> "SimOptions":
        """From ROS-style private parameters: pty_link, device, addr, baud, speed_factor,
        initial_pose (6 numbers), loop_period, byte_order, log_file, brake_time, protocol (v1 | v2 |
        v3), interpreter_lookahead, ring_size (v3), ramp_time (v2, v3), configuration (v1, v3), true_model (a file; "" the
        model's), and the assumptions of :data:`ASSUMPTIONS` (accelerations: a list, or a string of 6
        numbers).
        Unknown keys are refused."""
        unknown = sorted(set(params) - set(PARAM_NAMES))
        if unknown:
            raise SimError("unknown parameter(s) %s (known: %s)"
                           % (", ".join(unknown), ", ".join(sorted(PARAM_NAMES))))
        return cls(**{PARAM_NAMES[k]: v for k, v in params.items()})


    def controller_kwargs(self) -> Dict[str, Any]:
        """The keyword arguments of :class:`VirtualController` for these options (its ``link``, the
        device, apart): what the CLI and the ROS node build it from."""
        return dict(address=self.address, baud=self.baud, speed_factor=self.speed_factor,
                    initial_pose=self.initial_pose, loop_period=self.loop_period, byte_order=self.byte_order,
                    pty_link=self.pty_link, log_file=self.log_file, brake_time=self.brake_time,
                    protocol=self.protocol, interpreter_lookahead=self.interpreter_lookahead,
                    ring_size=self.ring_size, ramp_time=self.ramp_time, true_model=self.true_model,
                    data_exchange_bit=self.data_exchange_bit, configuration=self.configuration,
                    speed_scale=self.speed_scale, loop_blocks_during_move=self.loop_blocks_during_move,
                    blend_across_input_read=self.blend_across_input_read, loop_jitter=self.loop_jitter,
                    loop_jitter_seed=self.loop_jitter_seed, send_ahead=self.send_ahead,
                    unreachable=self.unreachable, ramp_shape=self.ramp_shape, accelerations=self.accelerations)


def _numbers(value: Any) -> Any:
    """A list of numbers given as a string ("5, 20.9 ..." or "[5, 20.9, ...]": a launch argument) as
    a list of floats (a word that is no number stays a string, for the caller's error); anything
    else as it is."""
    if not isinstance(value, str):
        return value
    words = [w for w in re.split(r"[\s,]+", value.strip().strip("[]")) if w]
    out: list = []
    for w in words:
        try:
            out.append(float(w))
        except ValueError:
            out.append(w)
    return out if out else None


class LoopTiming:
    """The periods of the virtual G2's program loop: ``period`` each, or (``jitter`` > 0) each drawn
    uniformly from ``period - jitter .. period + jitter`` by a generator seeded with ``seed`` -- an
    irregular loop (an assumption to measure: the driver dates records by the heartbeat, assuming a
    steady loop, doc/controller_program.md §10.9). The same seed gives the same periods."""

    def __init__(self, period: float, jitter: float = 0.0, seed: int = 0) -> None:
        if not (math.isfinite(period) and period > 0.0 and math.isfinite(jitter) and 0.0 <= jitter < period):
            raise SimError("loop timing: period %r must be > 0 and jitter %r in [0, period)" % (period, jitter))
        self.period = float(period)
        self.jitter = float(jitter)
        self.seed = seed
        self._rng = random.Random(seed)

    def next_period(self) -> float:
        """The period of the next loop [s]."""
        if self.jitter == 0.0:
            return self.period
        return self._rng.uniform(self.period - self.jitter, self.period + self.jitter)


def _check_true_model(path: str) -> None:
    """SimError naming the file and the key when the true-model file is unusable."""
    from panasonic_vr006l_support import true_model
    try:
        true_model.load(path)
    except true_model.TrueModelError as exc:
        raise SimError("true_model: %s" % exc) from exc


def true_kinematics(path: Optional[str]) -> Kinematics:
    """The kinematics of the simulated robot of the true-model file ``path`` (None: the model's)."""
    try:
        return Kinematics.from_true_model(path)
    except VrDriverError as exc:
        raise SimError("true_model: %s" % exc) from exc


def true_zero_offsets(path: Optional[str]) -> Tuple[float, ...]:
    """The joint zero offsets [rad] of the true-model file ``path``, joint_1 .. joint_6 (None or "":
    the model's, all 0)."""
    if not path:
        return (0.0,) * 6
    from panasonic_vr006l_support import true_model
    try:
        model = true_model.load(path)
    except true_model.TrueModelError as exc:
        raise SimError("true_model: %s" % exc) from exc
    return tuple(float(model.zero_offsets.get(name, 0.0)) for name in true_model.JOINT_NAMES)


def _protocol(name: Any) -> Protocol:
    try:
        return protocols.get(name)
    except ProtocolError:
        raise SimError("protocol must be one of %s, got %r" % (", ".join(PROTOCOLS), name)) from None


def robot_slave(address: int = DEFAULT_ADDRESS, clock: Clock = time.monotonic,
                protocol: Any = protocols.DEFAULT) -> DpSlave:
    """The G2's DP slave: ident 0x06C6 and the protocol's Chk_Cfg (v1: the one of
    ``config.default_robot_config()``, 14 bytes each way; v2: ``protocol.v2.CHK_CFG_V2``, 72 bytes;
    v3: ``protocol.v3.CHK_CFG_V3``, 28 bytes in, 24 out)."""
    proto = _protocol(protocol)
    slave_cfg = default_robot_config("virtual", phy_type="memory", slave_address=address).slave(address)
    cfg = proto.chk_cfg or slave_cfg.cfg
    return DpSlave(address, slave_cfg.ident, cfg, clock=clock)


# -------------------------------------------------------------------------------------- the program

@dataclass
class _Pending:
    seq: int
    command: Command
    via: Optional[Command]
    start_time: float


class ControllerProgram(SessionProgram):
    """The robot-side program loop (doc/controller_program.md) on one DP slave and one simulated arm.

    Call :meth:`step` once per loop with the clock time; it returns the Feedback it wrote. Not
    thread-safe by itself: one thread runs it (the arm and the log are thread-safe, so faults can be
    injected from anywhere).

    The session, the two-telegram rule, arming and link-loss detection are
    :class:`~vr_driver.controller.session.SessionProgram`'s (shared with protocol v2): a *session*
    starts each time the slave enters Data_Exchange; until the master's first Data_Exchange of that
    session there is no command at all. A session that ended (or was replaced by a new one between
    two loops) is a link loss. After a link loss, and at start, the program is *disarmed*: a request
    only counts after a record with the flag at 0 -- a flag still raised from before is answered
    REJECTED (held until the flag drops) and nothing moves.
    """

    def __init__(self, slave: DpSlave, arm: SimArm, *, byte_order: Any = ByteOrder.LITTLE,
                 execution_log: Optional[ExecutionLog] = None, confirm_records: bool = False,
                 data_exchange_bit: bool = True, loop_blocks_during_move: bool = False,
                 unreachable: Any = Unreachable.SKIP) -> None:
        self.byte_order = ByteOrder.parse(byte_order)
        super().__init__(slave, arm, confirm_records=confirm_records, data_exchange_bit=data_exchange_bit,
                         loop_blocks_during_move=loop_blocks_during_move, unreachable=unreachable)
        self.arm: SimArm = arm
        self.log = execution_log if execution_log is not None else ExecutionLog()
        self.handshake = ControllerHandshake()
        self.last_feedback: Optional[Feedback] = None
        self.last_command: Optional[Command] = None
        self._seq = 0
        self._pending: Optional[_Pending] = None
        self._held: Optional[MotionResult] = None      # the arm's result while the loop was blocked
        self._alarm: Optional[str] = None               # unreachable, alarm_halt: halts after this loop

    # ------------------------------------------------------------------- SessionProgram hooks
    def decode_record(self, raw: bytes) -> Command:
        return Command.decode(raw, self.byte_order)

    def is_idle_command(self, command: Command) -> bool:
        return not command.request

    # ---------------------------------------------------------------------------- read-outs
    @property
    def state(self) -> ControllerState:
        return self.handshake.state

    def status_bits(self) -> StatusBits:
        return arm_status_bits(self.arm) | self.handshake.status_bits()

    # ------------------------------------------------------------------------------- the loop
    def step(self, now: float) -> Optional[Feedback]:
        """One program loop at clock time ``now`` (none while a MOVE blocks it or an alarm halted
        it: the last feedback stays, :meth:`~vr_driver.controller.session.SessionProgram.suspended`)."""
        if self.suspended(now):
            return self.last_feedback
        command, stale = self.read_command(now)
        result = self._arm_result(now)
        if result is not None and self._pending is not None:
            self.handshake.finish(result.ok, result.reason)
            self._record(Outcome.EXECUTED if result.ok else Outcome.REJECTED, result.reason,
                         result.end_time, result.aborted)

        before = self.handshake.state
        blocked = self.arm.blocked_reason()
        if stale:
            blocked = "the request flag was already raised when the link (re)started; the controller " \
                      "accepts a request only after it has seen the flag at 0"
        start = self.handshake.step(command, arm_idle=blocked is None and not self.arm.moving)
        if self.handshake.stop_requested and self._pending is not None:
            self._stop_on_request(now)
        if before is ControllerState.READY and self.handshake.state is not ControllerState.READY:
            assert command is not None
            self._seq += 1
            via = self.handshake.active_via if start is not None else None
            self._pending = _Pending(self._seq, command, via, now)
            if start is not None:
                self._begin(start, via, now)
            elif self.handshake.state is ControllerState.DONE:       # a via point, stored
                self._record(Outcome.VIA_STORED, "", now)
            else:
                self._record(Outcome.REJECTED, blocked or self.handshake.reason, now)

        feedback = self.handshake.feedback(self.arm.reported_pose(), self.status_bits())
        self.slave.inputs = feedback.encode(self.byte_order)
        self.last_feedback = feedback
        if self._alarm is not None:         # BUSY went out before the MOVE (§5): now the alarm
            reason, self._alarm = self._alarm, None
            self.halt(reason, now)
        return feedback

    # ------------------------------------------------------------------- SessionProgram hooks
    def advance_suspended(self, now: float) -> None:
        result = self.arm.step(now)
        if result is not None:
            self._held = result

    def on_restart(self, now: float) -> None:
        self.handshake.reset()
        self._held = None

    # ------------------------------------------------------------------------------- helpers
    def _arm_result(self, now: float) -> Optional[MotionResult]:
        """The arm's result of a motion that ended since the last loop that ran (also one that
        ended while a MOVE blocked the loop)."""
        result = self.arm.step(now)
        if result is None:
            result, self._held = self._held, None
        return result

    def _begin(self, command: Command, via: Optional[Command], now: float) -> None:
        kind = command.move_type.to_move_type()
        if self.unreachable is Unreachable.ALARM_HALT:
            try:
                self.arm.plan(kind, command.pose, via=None if via is None else via.pose)
            except VrDriverError as exc:
                why = "%s: %s" % (type(exc).__name__, exc)
                self._alarm = why
                self._record(Outcome.REJECTED, "alarm, the program halted: %s" % why, now)
                return
        ok, reason = self.arm.begin(kind, command.pose, via=None if via is None else via.pose, now=now)
        if not ok:
            self.handshake.finish(False, reason)
            self._record(Outcome.REJECTED, reason, now)

    def _stop_on_request(self, now: float) -> None:
        """Flag 2 while BUSY: a controlled stop -- the arm decelerates along its path (the arm's
        ``brake_time``) and the target ends REJECTED once it is at rest (DONE if the ramp carried
        it to the target). The handshake stays BUSY meanwhile; the loop's arm step ends it."""
        why = "stopped by the master (flag 2)"
        if self.arm.brake(why, now=now):
            log.info("target %d: stop requested, braking", self._pending.seq if self._pending else 0)
        result = self.arm.step(now)
        if result is not None:
            self.handshake.finish(result.ok, result.reason)
            self._record(Outcome.EXECUTED if result.ok else Outcome.REJECTED, result.reason,
                         result.end_time, result.aborted)

    def on_link_lost(self, why: str, stop_time: float) -> None:
        self.arm.stop(why, now=stop_time)
        result = self._arm_result(stop_time)
        if self._pending is not None and self.handshake.state is ControllerState.BUSY:
            ok = result is not None and result.ok
            reason = "" if ok else why
            self.handshake.finish(ok, reason)
            end = result.end_time if result is not None else stop_time
            self._record(Outcome.EXECUTED if ok else Outcome.REJECTED, reason, end,
                         result is not None and result.aborted)
        self.handshake.reset()

    def _record(self, outcome: Outcome, reason: str, end_time: float, aborted: bool = False) -> None:
        p = self._pending
        if p is None:
            return
        self._pending = None
        entry = LogEntry(
            seq=p.seq, move_type=p.command.move_type.name, target=p.command.values, outcome=outcome,
            reason=reason, start_time=p.start_time, end_time=end_time,
            final_pose=self.arm.reported_pose(), aborted=aborted,
            via=None if p.via is None else p.via.values)
        if outcome is Outcome.REJECTED:
            log.info("target %d %s %s rejected: %s", p.seq, entry.move_type, entry.target, reason)
        else:
            log.debug("target %d %s %s %s", p.seq, entry.move_type, entry.target, outcome.value)
        self.log.append(entry)


# -------------------------------------------------------------------------------- the pty link

#: the value of ``pty_link`` (and of the driver's ``port``) that means "this launch's own link"
AUTO_LINK = "auto"


def auto_pty_link(environ: Optional[Mapping[str, str]] = None, station: str = "g2") -> str:
    """This launch's pty link: ``<ROS log dir>/vr006l_virtual_<station>_<master port>`` (``station``
    ``g2`` the virtual controller, ``io_island`` the virtual I/O island, ``line`` the line hub's
    master end, :mod:`vr_driver.controller.line`), followed by ``_<namespace>`` for nodes in a namespace
    (``/arm1`` -> ``..._11311_arm1``, ``/cell/arm1`` -> ``..._11311_cell_arm1``).

    Both the virtual controller and the driver resolve ``auto`` with this function from the
    environment roslaunch gives its nodes (ROS_MASTER_URI; ROS_NAMESPACE, set for the nodes of a
    ``<group ns>``; ROS_LOG_DIR, else ROS_HOME/log, else ~/.ros/log), so they agree on the path,
    launches on different masters never share one, and two drivers in two namespaces of one launch
    get one each."""
    env = os.environ if environ is None else environ
    uri = env.get("ROS_MASTER_URI", "") or "http://localhost:11311"
    port = uri.rstrip("/").rsplit(":", 1)[-1]
    if not port.isdigit():
        raise SimError("cannot take a port from ROS_MASTER_URI=%r for pty_link %r" % (uri, AUTO_LINK))
    log_dir = env.get("ROS_LOG_DIR") or os.path.join(
        env.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros"), "log")
    if not re.match(r"[A-Za-z0-9_]+\Z", station):
        raise SimError("bad station name %r for an auto pty link" % (station,))
    ns = "_".join(part for part in (env.get("ROS_NAMESPACE") or "").split("/") if part)
    return os.path.join(log_dir, "vr006l_virtual_%s_%s" % (station, port) + ("_" + ns if ns else ""))


def resolve_link(value: str, station: str = "g2") -> str:
    """A pty link given as a parameter: ``auto`` is this launch's link of ``station``, ``auto:NAME``
    this launch's link of station NAME (:func:`auto_pty_link`); anything else is a path."""
    if value == AUTO_LINK:
        return auto_pty_link(station=station)
    if value.startswith(AUTO_LINK + ":"):
        return auto_pty_link(station=value[len(AUTO_LINK) + 1:])
    return value


def _remove_quietly(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:          # another user's live process
        return True
    return True


def _take_link_lock(path: str) -> str:
    """Create ``path.lock`` holding our pid; refuse (SimDeviceError) while another live process
    holds it. A lock whose process is gone is stale and taken over. Returns the lock's path."""
    lock = path + ".lock"
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            try:
                with open(lock) as f:
                    text = f.read().strip()
            except FileNotFoundError:
                continue                 # released meanwhile: try again
            except OSError as exc:
                raise SimDeviceError("cannot read the pty link lock %s: %s" % (lock, exc)) from exc
            if text.isdigit() and _pid_alive(int(text)):
                raise SimDeviceError(
                    "pty link %s is in use by the live process %s (lock %s): another virtual controller "
                    "serves it; give this one another link (sim_port:=..., --pty-link)" % (path, text, lock))
            try:
                os.unlink(lock)          # stale (its process is gone) or unreadable: take it over
            except FileNotFoundError:
                pass
            continue
        except OSError as exc:
            raise SimDeviceError("cannot create the pty link lock %s: %s" % (lock, exc)) from exc
        with os.fdopen(fd, "w") as f:
            f.write("%d\n" % os.getpid())
        return lock
    raise SimDeviceError("cannot take the pty link lock %s: it keeps changing" % lock)


# -------------------------------------------------------------------------------- the whole device

class SimPort:
    """Where a simulated DP station serves the bus (shared by the virtual controller and the virtual
    I/O island, :mod:`vr_driver.controller.io_island`).

    ``link``: None creates a raw pty pair -- masters (or the line hub, :mod:`pyprofibus_vendor.line`)
    open :attr:`device_path`; with ``pty_link`` a symlink to it is made there (replacing a stale
    symlink, never another file; guarded by ``<pty_link>.lock`` holding our pid) and removed by
    :meth:`close`. A string serves that existing device (``SerialLink(link, baud)``). A
    :class:`~pyprofibus_vendor.phy.Link` is used as it is (the caller closes it).
    SimDeviceError when the pty, device or symlink cannot be made."""

    def __init__(self, link: Union[None, str, Link], baud: int, pty_link: Optional[str] = None) -> None:
        if pty_link is not None and link is not None:
            raise SimError("pty_link is only for a pty the station creates (link=None)")
        self.pty: Optional[PtyPair] = None
        self.symlink: Optional[str] = None
        self.device_path = ""                     # what a master opens (pty slave path or the device)
        self._owns_link = False
        self.link = self._open(link, baud, pty_link)

    def _open(self, link: Union[None, str, Link], baud: int, pty_link: Optional[str]) -> Link:
        if isinstance(link, Link):
            return link
        if isinstance(link, str):
            try:
                made = SerialLink(link, baud)
            except ProfibusError as exc:
                raise SimDeviceError(str(exc)) from exc
            self._owns_link = True
            self.device_path = link
            return made
        try:
            self.pty = open_pty_pair()
        except ProfibusError as exc:
            raise SimDeviceError(str(exc)) from exc
        self.device_path = self.pty.slave_path
        if pty_link:
            try:
                self._make_symlink(pty_link, self.pty.slave_path)
            except SimDeviceError:
                self.pty.close()
                raise
        self._owns_link = True
        return self.pty.master_link()

    def _make_symlink(self, path: str, target: str) -> None:
        if os.path.lexists(path) and not os.path.islink(path):
            raise SimDeviceError("pty link %s exists and is not a symlink: not replacing it" % path)
        lock = _take_link_lock(path)
        tmp = "%s.%d.tmp" % (path, os.getpid())
        try:
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(target, tmp)
            os.replace(tmp, path)
        except OSError as exc:
            _remove_quietly(lock)
            raise SimDeviceError("cannot create the pty link %s -> %s: %s" % (path, target, exc)) from exc
        self.symlink = path

    def close(self) -> None:
        """Close what this object opened, remove the pty symlink and its lock. Idempotent."""
        if self._owns_link:
            self.link.close()
            self._owns_link = False
        if self.pty is not None:
            self.pty.close()
            self.pty = None
        if self.symlink is not None:
            try:
                if os.path.islink(self.symlink):
                    os.unlink(self.symlink)
            except OSError as exc:
                log.warning("cannot remove the pty link %s: %s", self.symlink, exc)
            _remove_quietly(self.symlink + ".lock")
            self.symlink = None



class Simulator:
    """The life-cycle the simulators share (VirtualController, VirtualIoIsland, LineHub): a
    background thread started by the subclass's ``start()`` (returning self) and watching
    ``self._stop``; :meth:`stop` ends it and then :meth:`_close` closes what the subclass opened;
    a context manager. The subclass calls ``Simulator.__init__`` and opens ``self.port`` (the
    :class:`SimPort` a master connects to)."""

    port: SimPort

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.error: Optional[BaseException] = None     # what ended the thread, if anything did

    @property
    def device_path(self) -> str:
        """What a master opens (pty slave path or the device)."""
        return self.port.device_path

    @property
    def symlink(self) -> Optional[str]:
        return self.port.symlink

    def start(self) -> Any:
        raise NotImplementedError

    def _close(self) -> None:
        """Close what the simulator opened (after its thread ended)."""

    def request_stop(self) -> None:
        """Ask the threads to end, without waiting (safe from a signal handler / ROS shutdown hook,
        which may interrupt a thread holding a lock that :meth:`stop` needs)."""
        self._stop.set()

    def stop(self) -> None:
        """Stop the threads, close what this object opened (removes a pty symlink). Idempotent."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(5.0)
        self._close()

    def close(self) -> None:
        self.stop()

    def __enter__(self) -> Any:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()


class VirtualController(Simulator):
    """The virtual G2: DP slave + program loop + simulated arm, on a link.

    ``link``: None (default) creates a raw pty pair -- clients open :attr:`device_path`; with
    ``pty_link`` a symlink to it is made there (replacing a stale symlink, never another file) and
    removed by :meth:`stop`. A string serves that existing device (``SerialLink(link, baud)``). A
    :class:`~pyprofibus_vendor.phy.Link` is used as it is (the caller closes it).
    ``confirm_records`` (default: True for v1, False for v2): the program acts on a master record
    only once it arrived in two consecutive Data_Exchange telegrams (see the module docstring; v2's
    CRC-16 closes the gap the rule closes for v1, without costing a bus cycle per target).
    ``protocol``: ``"v1"`` (default) runs :class:`ControllerProgram` on a 14-byte slave and a
    :class:`~vr_driver.controller.arm.SimArm`; ``"v2"`` runs :class:`~vr_driver.controller.program_v2.
    ControllerProgramV2` on a 72-byte slave (``CHK_CFG_V2``) and a :class:`~vr_driver.controller.stream_arm.
    SimStreamArm` (streamed joint targets, look-ahead blending); its feedback is a FeedbackV2.
    ``"v3"`` runs :class:`~vr_driver.controller.program_v3.ControllerProgramV3` on a slave with
    ``CHK_CFG_V3`` and a SimStreamArm whose look-ahead is ``interpreter_lookahead`` (a given
    ``arm`` keeps its own); the program's ring holds ``ring_size`` positions and it solves the
    targets with ``controller_kinematics`` (default: its own instance of the model's); its feedback
    is a FeedbackV3 in ``byte_order``. Both options are ignored by v1 and v2. ``ramp_time`` (v2,
    v3; a given ``arm`` keeps its own): robot time [s] the SimStreamArm takes from rest to full
    speed; None (default) from the kinematics' joint limits, max velocity / acceleration (0.1 s for
    the model); v1's SimArm ignores it.
    ``configuration`` (v1, v3; a given ``arm`` keeps its own): the joint solution the G2 takes for a
    Cartesian target, ``previous_target`` (default) or ``current_joints``
    (:class:`~vr_driver.kinematics.solver.ConfigurationRule`, an assumption: doc/controller_program.md §7).
    ``data_exchange_bit`` (default True): whether the program can read its card's Data_Exchange
    status (an assumption about the G2, :mod:`vr_driver.controller.session`); False: it reads only
    its input bytes, as a G2 whose card offers no such status would.
    The other assumptions about the real G2 (:data:`ASSUMPTIONS`; SimOptions documents each):
    ``loop_blocks_during_move``, ``unreachable`` (every protocol), ``loop_jitter`` /
    ``loop_jitter_seed`` (the threaded loop's periods, :attr:`loop_timing`), ``send_ahead`` (v3),
    ``speed_scale``, ``blend_across_input_read``, ``ramp_shape``, ``accelerations`` (v2, v3; a given
    ``arm`` keeps its own).
    ``true_model``: a YAML file of the simulated robot's own dimensions, joint limits and joint zero
    offsets (panasonic_vr006l_support.true_model; None, default: the model's). The arm (its FK: the
    pose it reports and where it really is; v1's SimArm also its IK and planner) and the v3
    program's IK both use it -- the G2 knows its own robot --, and the joints the arm holds, reports
    (v2) and takes (v2 targets) are in its zero convention (``q_true - zero_offset``). With it,
    ``kinematics`` and ``arm`` must not be given; a given ``controller_kinematics`` still wins for
    the v3 program.

    Thread-safe read-outs: :attr:`state`, :attr:`feedback`, :attr:`slave_state`, :attr:`log`,
    :attr:`pose`, :attr:`joints`, :attr:`true_joints`; injections :meth:`set_estop`, :meth:`set_drives_powered`,
    :meth:`set_error`, :meth:`clear_faults`. :meth:`wait_until` blocks on a condition over the
    feedback. :meth:`step` runs one program loop by hand (tests with an injected clock; do not mix
    with :meth:`start`).
    """

    def __init__(self, link: Union[None, str, Link] = None, *, address: int = DEFAULT_ADDRESS,
                 baud: int = DEFAULT_BAUD, speed_factor: float = 1.0, initial_pose: Any = HOME_POSE,
                 loop_period: float = DEFAULT_LOOP_PERIOD, byte_order: Any = ByteOrder.LITTLE,
                 pty_link: Optional[str] = None, log_file: Optional[str] = None,
                 kinematics: Optional[Kinematics] = None, arm: Union[None, SimArm, SimStreamArm] = None,
                 clock: Clock = time.monotonic, confirm_records: Optional[bool] = None,
                 brake_time: float = DEFAULT_BRAKE_TIME, protocol: Any = protocols.DEFAULT,
                 interpreter_lookahead: int = DEFAULT_INTERPRETER_LOOKAHEAD, ring_size: int = DEFAULT_RING_SIZE,
                 controller_kinematics: Optional[Kinematics] = None, ramp_time: Optional[float] = None,
                 true_model: Optional[str] = None, data_exchange_bit: bool = True,
                 configuration: Any = ConfigurationRule.PREVIOUS_TARGET, speed_scale: float = 1.0,
                 loop_blocks_during_move: bool = False, blend_across_input_read: bool = True,
                 loop_jitter: float = 0.0, loop_jitter_seed: int = 0, send_ahead: Any = SendAhead.ACCEPTED,
                 unreachable: Any = Unreachable.SKIP, ramp_shape: Any = RampShape.LINEAR,
                 accelerations: Optional[Sequence[float]] = None) -> None:
        pose = initial_pose.as_tuple() if isinstance(initial_pose, ControllerPose) else initial_pose
        self.options = SimOptions(device=link if isinstance(link, str) else None, pty_link=pty_link,
                                  address=address, baud=baud, speed_factor=speed_factor,
                                  initial_pose=tuple(pose), loop_period=loop_period,
                                  byte_order=ByteOrder.parse(byte_order).value, log_file=log_file,
                                  brake_time=brake_time, protocol=_protocol(protocol).name,
                                  interpreter_lookahead=interpreter_lookahead, ring_size=ring_size,
                                  ramp_time=ramp_time, true_model=true_model,
                                  data_exchange_bit=data_exchange_bit,
                                  configuration=configuration, speed_scale=speed_scale,
                                  loop_blocks_during_move=loop_blocks_during_move,
                                  blend_across_input_read=blend_across_input_read, loop_jitter=loop_jitter,
                                  loop_jitter_seed=loop_jitter_seed,
                                  send_ahead=send_ahead.value if isinstance(send_ahead, SendAhead) else send_ahead,
                                  unreachable=unreachable.value if isinstance(unreachable, Unreachable)
                                  else unreachable,
                                  ramp_shape=ramp_shape.value if isinstance(ramp_shape, RampShape) else ramp_shape,
                                  accelerations=None if accelerations is None else tuple(accelerations))
        if pty_link is not None and link is not None:
            raise SimError("pty_link is only for a pty the controller creates (link=None)")
        if self.options.true_model:
            if kinematics is not None or arm is not None:
                raise SimError("true_model gives the simulated arm its kinematics: do not give kinematics "
                               "or arm as well")
            kinematics = true_kinematics(self.options.true_model)
            if controller_kinematics is None:
                controller_kinematics = kinematics     # the G2 knows its own robot
        #: the true robot's joint zero offsets [rad] (true_joints = joints + these)
        self.zero_offsets = true_zero_offsets(self.options.true_model)
        self.clock = clock
        self.loop_period = self.options.loop_period
        #: the periods of the program loop (steady, or spread by loop_jitter)
        self.loop_timing = LoopTiming(self.options.loop_period, self.options.loop_jitter,
                                      self.options.loop_jitter_seed)
        self.protocol = self.options.protocol
        self.wire = protocols.get(self.protocol)
        streams = self.wire.streams
        cartesian_stream = streams and not self.wire.joint_targets   # the controller solves the IK
        if confirm_records is None:
            confirm_records = self.wire.confirm_records
        if arm is None:
            extra: Dict[str, Any] = {"look_ahead": self.options.interpreter_lookahead} if cartesian_stream else {}
            if streams:
                extra.update(ramp_time=self.options.ramp_time, speed_scale=self.options.speed_scale,
                             blend_across_input_read=self.options.blend_across_input_read,
                             ramp_shape=self.options.ramp_shape, accelerations=self.options.accelerations)
            try:
                arm = (SimStreamArm if streams else SimArm)(
                    kinematics, speed_factor=self.options.speed_factor,
                    initial_pose=ControllerPose(*self.options.initial_pose), clock=clock,
                    brake_time=self.options.brake_time, configuration=self.options.configuration, **extra)
            except VrDriverError as exc:
                raise SimError("initial pose %s: %s" % (self.options.initial_pose, exc)) from exc
        if isinstance(arm, SimStreamArm) != streams:
            raise SimError("protocol %s needs a %s" % (self.protocol, "SimStreamArm" if streams else "SimArm"))
        self.arm: Any = arm
        self.execution_log = ExecutionLog()
        self.slave = robot_slave(self.options.address, clock, self.protocol)
        self.program: Union[ControllerProgram, ControllerProgramV2, ControllerProgramV3]
        loop: Dict[str, Any] = dict(data_exchange_bit=self.options.data_exchange_bit,
                                    loop_blocks_during_move=self.options.loop_blocks_during_move,
                                    unreachable=self.options.unreachable)
        if cartesian_stream:
            self.program = ControllerProgramV3(self.slave, arm, kinematics=controller_kinematics,
                                               ring_size=self.options.ring_size,
                                               byte_order=self.options.byte_order,
                                               execution_log=self.execution_log,
                                               confirm_records=confirm_records,
                                               send_ahead=self.options.send_ahead, **loop)
        elif streams:
            self.program = ControllerProgramV2(self.slave, arm, execution_log=self.execution_log,
                                               confirm_records=confirm_records, **loop)
        else:
            self.program = ControllerProgram(self.slave, arm, byte_order=self.options.byte_order,
                                             execution_log=self.execution_log,
                                             confirm_records=confirm_records, **loop)
        self._cond = threading.Condition()
        super().__init__()
        self.overruns = 0
        self._log_fh: Optional[IO[str]] = None
        if self.options.log_file:
            try:
                self._log_fh = open(self.options.log_file, "a", encoding="utf-8")
            except OSError as exc:
                raise SimError("cannot open the log file %s: %s" % (self.options.log_file, exc)) from exc
            self.execution_log.add_listener(self._write_log_line)
        try:
            self.port = SimPort(link, self.options.baud, self.options.pty_link)
        except BaseException:
            self._close_log()
            raise
        self.server = SlaveServer(self.link, self.slave, clock=clock)

    # ----------------------------------------------------------------------- set-up / tear-down
    @property
    def link(self) -> Link:
        return self.port.link

    @property
    def pty(self) -> Optional[PtyPair]:
        return self.port.pty

    def start(self) -> "VirtualController":
        """Serve the bus and run the program loop in background threads."""
        if self._thread is not None:
            return self
        self._stop.clear()
        self.server.start()
        self._thread = threading.Thread(target=self._run, name="vr-sim-program", daemon=True)
        self._thread.start()
        log.info("virtual G2 controller on %s: DP slave %d (ident 0x%04X), protocol %s, loop %.0f ms, "
                 "speed x%g", self.device_path or self.link, self.slave.address, self.slave.ident,
                 self.protocol, self.loop_period * 1e3, self.arm.speed_factor)
        return self

    def _close(self) -> None:
        self.server.stop()
        self.port.close()
        self._close_log()

    def _close_log(self) -> None:
        fh, self._log_fh = self._log_fh, None
        if fh is not None:
            self.execution_log.remove_listener(self._write_log_line)
            fh.close()

    def _write_log_line(self, entry: Union[LogEntry, StreamLogEntry]) -> None:
        fh = self._log_fh
        if fh is not None:
            fh.write(entry.to_json() + "\n")
            fh.flush()

    # ----------------------------------------------------------------------------- the loop
    def _run(self) -> None:
        next_time = self.clock()
        while not self._stop.is_set():
            now = self.clock()
            try:
                self.step(now)
            except Exception as exc:  # noqa: BLE001 - record, report, end the loop
                self.error = exc
                log.exception("program loop failed")
                with self._cond:
                    self._cond.notify_all()
                return
            next_time += self.loop_timing.next_period()
            now = self.clock()
            if next_time < now:
                self.overruns += 1
                next_time = now
            self._stop.wait(next_time - now)

    def step(self, now: Optional[float] = None) -> Union[None, Feedback, FeedbackV2, FeedbackV3]:
        """One program loop (at ``now``, default the clock); the feedback on the bus after it (the
        last one written, while a MOVE blocks the loop or an alarm halted it)."""
        feedback = self.program.step(self.clock() if now is None else now)
        with self._cond:
            self._cond.notify_all()
        return feedback

    def wait_until(self, predicate: Callable[[Any], bool], timeout: float) -> bool:
        """Block until ``predicate(feedback)`` holds after a program loop (True) or ``timeout``."""
        def check() -> bool:
            if self.error is not None:
                return True
            fb = self.program.last_feedback
            return fb is not None and predicate(fb)
        with self._cond:
            ok = self._cond.wait_for(check, timeout)
        return bool(ok) and self.error is None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def server_error(self) -> Optional[BaseException]:
        return self.server.error

    # ---------------------------------------------------------------------------- read-outs
    @property
    def state(self) -> Union[ControllerState, StreamState]:
        return self.program.state

    @property
    def feedback(self) -> Union[None, Feedback, FeedbackV2, FeedbackV3]:
        return self.program.last_feedback

    @property
    def slave_state(self) -> SlaveState:
        return self.slave.state

    @property
    def log(self) -> ExecutionLog:
        return self.execution_log

    @property
    def pose(self) -> IntPose:
        """The reported pose (whole mm / deg)."""
        return self.arm.reported_pose()

    @property
    def joints(self) -> Tuple[float, ...]:
        return self.arm.joints

    @property
    def true_joints(self) -> Tuple[float, ...]:
        """The arm's joints [rad] in the true robot's angles, measured from the model's zero pose:
        :attr:`joints` (the controller's, ``q_true - zero_offset``) plus the true model's zero
        offsets (without ``true_model``: equal to :attr:`joints`). A simulation-only read-out."""
        return tuple(q + z for q, z in zip(self.arm.joints, self.zero_offsets))

    # ---------------------------------------------------------------------------- injections
    def set_estop(self, pressed: bool) -> None:
        log.warning("e-stop %s", "pressed" if pressed else "released")
        self.arm.set_estop(pressed)

    def set_drives_powered(self, powered: bool) -> bool:
        ok = self.arm.set_drives_powered(powered)
        if ok:
            log.warning("drives %s", "on" if powered else "off")
        else:
            log.warning("drives not switched on: the e-stop is pressed")
        return ok

    def set_error(self, error: Any = True) -> None:
        log.warning("controller error %s", "cleared" if not error else "set: %s" % (error,))
        self.arm.set_error(error)

    def clear_faults(self) -> None:
        """Release the e-stop, power the drives, clear the error."""
        self.arm.set_estop(False)
        self.arm.set_drives_powered(True)
        self.arm.set_error(None)

    def set_fault(self, fault: str, active: bool) -> Tuple[bool, str]:
        """Service-style injection (the ROS node's handlers): ``fault`` one of ``estop``,
        ``drives_powered``, ``error``. Returns (success, message)."""
        if fault == "estop":
            self.set_estop(active)
            return True, "e-stop %s" % ("pressed (drives off)" if active else
                                        "released; the drives stay off until switched on")
        if fault == "drives_powered":
            if not self.set_drives_powered(active):
                return False, "drives stay off: release the e-stop first"
            return True, "drives %s" % ("on" if active else "off")
        if fault == "error":
            self.set_error("injected error" if active else None)
            return True, "error %s" % ("set" if active else "cleared")
        return False, "unknown fault %r (one of %s)" % (fault, ", ".join(FAULTS))


# ============================================================================================== CLI

def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python3 -m vr_driver.controller.program",
        description="Virtual Panasonic G2 controller: a PROFIBUS-DP slave (ident 0x06C6) running the "
                    "robot-side program of the 14-byte protocol (or, with --protocol v2, the 72-byte "
                    "joint-target streaming protocol; with --protocol v3, Cartesian-target streaming "
                    "for the G2 as it is) against a simulated VR-006L. Without "
                    "--device it creates a pty pair; the first line on stdout is the device path "
                    "for the master. Stops cleanly on SIGINT / SIGTERM.",
        epilog="exit status: 0 stopped by a signal, 2 bad option, 3 device problem, 1 internal error")
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
    p.add_argument("--log-file", metavar="FILE",
                   help="append one JSON line per executed / rejected target")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output on stderr")
    return p


def _watch(sim: Any, stop: threading.Event, prog: str) -> int:
    """Wait for ``stop`` while ``sim``'s threads run; end early on their device or internal error."""
    while not stop.wait(0.2):
        if sim.server_error is not None:
            print("%s: device error: %s" % (prog, sim.server_error), file=sys.stderr)
            return EXIT_DEVICE
        if sim.error is not None:
            print("%s: internal error: %s" % (prog, sim.error), file=sys.stderr)
            return EXIT_FAILURE
    return EXIT_OK


def run_simulator(prog: str, make: Callable[[], Any], out: IO[str],
                  serve: Optional[Callable[[Any, threading.Event, str], int]] = None,
                  usage: Optional[Callable[[], None]] = None) -> int:
    """The command-line life of a simulator (virtual controller, I/O island, line hub): SIGINT /
    SIGTERM stop it; ``make()`` builds and starts it (SimDeviceError -> EXIT_DEVICE, SimError ->
    ``usage()`` and EXIT_USAGE); its ``device_path`` is the first line on ``out``; ``serve(sim,
    stop, prog)`` (default: watch its threads' errors) runs until a signal and gives the exit status
    (a PhyError -> EXIT_DEVICE); ``sim.stop()`` and the old signal handlers always come back."""
    stop = threading.Event()
    old = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    sim: Any = None
    try:
        try:
            sim = make()
        except SimDeviceError as exc:
            print("%s: device error: %s" % (prog, exc), file=sys.stderr)
            return EXIT_DEVICE
        except SimError as exc:
            if usage is not None:
                usage()
            print("%s: error: %s" % (prog, exc), file=sys.stderr)
            return EXIT_USAGE
        print(sim.device_path, file=out, flush=True)
        try:
            return (serve or _watch)(sim, stop, prog)
        except PhyError as exc:
            print("%s: device error: %s" % (prog, exc), file=sys.stderr)
            return EXIT_DEVICE
    finally:
        if sim is not None:
            sim.stop()
        for sig, handler in old.items():
            signal.signal(sig, handler)


def main(argv: Optional[Sequence[str]] = None, stdout: Optional[IO[str]] = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)          # exits 2 on a bad option
    out = stdout if stdout is not None else sys.stdout
    level = logging.WARNING - 10 * min(2, args.verbose)
    logging.basicConfig(level=level, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        options = SimOptions(device=args.device, pty_link=args.pty_link, address=args.addr, baud=args.baud,
                             speed_factor=args.speed_factor, initial_pose=tuple(args.initial_pose),
                             loop_period=args.loop_period, byte_order=args.byte_order,
                             log_file=args.log_file, brake_time=args.brake_time, protocol=args.protocol,
                             interpreter_lookahead=args.interpreter_lookahead, ring_size=args.ring_size,
                             ramp_time=args.ramp_time, true_model=args.true_model,
                             data_exchange_bit=args.data_exchange_bit, configuration=args.configuration,
                             speed_scale=args.speed_scale, loop_blocks_during_move=args.loop_blocks_during_move,
                             blend_across_input_read=args.blend_across_input_read, loop_jitter=args.loop_jitter,
                             loop_jitter_seed=args.loop_jitter_seed, send_ahead=args.send_ahead,
                             unreachable=args.unreachable, ramp_shape=args.ramp_shape,
                             accelerations=None if args.accelerations is None else tuple(args.accelerations))
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


if __name__ == "__main__":
    sys.exit(main())
