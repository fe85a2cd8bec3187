"""The virtual G2's options: :class:`SimOptions` (every setting validated once; the CLI's options and
the ROS node's private parameters both end up here, :data:`PARAM_NAMES`), the assumptions about the
real G2 among them (:data:`ASSUMPTIONS`, doc/controller_program.md §10.9), the program loop's
periods (:class:`LoopTiming`) and the simulated robot's own model (``true_model``). ROS-free."""
from __future__ import annotations

import math
import random
import re
from dataclasses import dataclass, fields
from typing import Any, Dict, Mapping, Optional, Tuple

from pyprofibus_vendor.config import default_robot_config
from pyprofibus_vendor.errors import ProfibusError

from .. import validate
from ..errors import ProtocolError, VrDriverError
from ..kinematics.solver import ConfigurationRule, Kinematics
from ..poses import HOME_POSE, ControllerPose
from ..protocol import registry as protocols
from ..protocol.base import Protocol
from ..protocol.common import ByteOrder
from ..protocol.v1 import PROGRAM_PATH_SPEED, PROGRAM_SPEED
from .program_v3 import DEFAULT_INTERPRETER_LOOKAHEAD, DEFAULT_RING_SIZE, SendAhead
from .session import Unreachable
from .simulator import SimError, int_option, positive_option
from .stream_arm import RampShape, check_accelerations

__all__ = ["DEFAULT_ADDRESS", "DEFAULT_BAUD", "DEFAULT_LOOP_PERIOD", "DEFAULT_BRAKE_TIME", "PARAM_NAMES",
           "ASSUMPTIONS", "PROTOCOLS", "SimOptions", "LoopTiming", "protocol_option", "true_kinematics",
           "true_zero_offsets"]

DEFAULT_ADDRESS = 4
DEFAULT_BAUD = 19200
DEFAULT_LOOP_PERIOD = 0.01
#: robot time [s] a controlled stop takes to bring the arm from path speed to rest
DEFAULT_BRAKE_TIME = 0.3

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
               "ramp_shape": "ramp_shape", "accelerations": "accelerations", "program_speed": "program_speed",
               "program_path_speed": "program_path_speed"}

#: the SimOptions fields that are assumptions about the real G2 (doc/controller_program.md §10.9, one
#: row each): what a commissioning measures and the virtual G2 lets a test set either way
ASSUMPTIONS = ("byte_order", "loop_period", "loop_jitter", "loop_blocks_during_move", "data_exchange_bit",
               "configuration", "interpreter_lookahead", "blend_across_input_read", "send_ahead",
               "unreachable", "speed_scale", "ramp_time", "ramp_shape", "accelerations", "program_speed",
               "program_path_speed")

#: the controller programs (vr_driver.protocol): v1 the thesis' 14-byte handshake (default), v2
#: streamed joint targets, v3 streamed Cartesian targets for the G2 as it is
PROTOCOLS = protocols.names()


# ------------------------------------------------------------------------------------------- options

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
    #: v1: the program's constant move speeds [m/min] -- MOVEP's (a PTP target) and MOVEL's / MOVEC's (a
    #: LIN, a CIRC): each move runs the arm's own profile slowed down evenly until the TCP never exceeds
    #: it (the documented program's 10 and 5 m/min; the protocol carries no speed)
    program_speed: float = PROGRAM_SPEED
    program_path_speed: float = PROGRAM_PATH_SPEED

    def __post_init__(self) -> None:
        protocol_option(self.protocol)
        for name in ("device", "pty_link", "log_file", "true_model"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                raise SimError("%s must be a path, got %r" % (name, value))
            object.__setattr__(self, name, value or None)
        if self.device and self.pty_link:
            raise SimError("give either device (serve an existing device) or pty_link (create a pty "
                           "and link it there), not both")
        object.__setattr__(self, "address", int_option(self.address, "addr", 0, 125))
        object.__setattr__(self, "baud", int_option(self.baud, "baud", 9600, 12_000_000))
        object.__setattr__(self, "interpreter_lookahead",
                           int_option(self.interpreter_lookahead, "interpreter_lookahead", 0, 100))
        object.__setattr__(self, "ring_size", int_option(self.ring_size, "ring_size", 1, 1000))
        try:  # the DP bit rates, checked by the bus configuration
            default_robot_config("virtual", self.baud, phy_type="memory", slave_address=self.address)
        except ProfibusError as exc:
            raise SimError(str(exc)) from exc
        object.__setattr__(self, "speed_factor", positive_option(self.speed_factor, "speed_factor"))
        object.__setattr__(self, "loop_period", positive_option(self.loop_period, "loop_period"))
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
        for name in ("program_speed", "program_path_speed"):
            value = getattr(self, name)
            object.__setattr__(self, name, validate.number(value, lambda _, n=name, v=value: SimError(
                "%s must be a finite number in (0, 1000] (m/min, the v1 program's move speed), got %r" % (n, v)),
                0.0, 1000.0, lo_open=True))
        object.__setattr__(self, "loop_jitter", validate.number(self.loop_jitter, lambda _: SimError(
            "loop_jitter must be a finite number >= 0 and below loop_period (%g s), got %r"
            % (self.loop_period, self.loop_jitter)), 0.0))
        if self.loop_jitter >= self.loop_period:
            raise SimError("loop_jitter must be a finite number >= 0 and below loop_period (%g s), got %r"
                           % (self.loop_period, self.loop_jitter))
        object.__setattr__(self, "loop_jitter_seed",
                           int_option(self.loop_jitter_seed, "loop_jitter_seed", 0, 2 ** 32 - 1))
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
        device, apart): every option but the device, by its own name. What the CLI and the ROS node
        build it from."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "device"}


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


def protocol_option(name: Any) -> Protocol:
    """The protocol object called ``name``; SimError naming the known ones otherwise."""
    try:
        return protocols.get(name)
    except ProtocolError:
        raise SimError("protocol must be one of %s, got %r" % (", ".join(PROTOCOLS), name)) from None
