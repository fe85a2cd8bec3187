"""The virtual G2 controller: a DP slave running a robot-side program (doc/controller_program.md)
against a simulated arm, on a link. ROS-free.

- :class:`VirtualController`: a :class:`~pyprofibus_vendor.DpSlave` (ident 0x06C6, address 4, the
  protocol's Chk_Cfg: v1 the default ``13 13 13 11 23 23 23 21``, :func:`robot_slave`) served on
  a pty pair it creates (optionally symlinked), on a device, or on any link
  (:class:`~vr_driver.controller.pty_link.SimPort`), plus the program loop in a thread at a fixed
  period (:class:`~vr_driver.controller.options.LoopTiming`).
- The program is the one the protocol object names (:meth:`vr_driver.protocol.base.Protocol.
  controller_program`, registered by :mod:`vr_driver.controller.programs`), never one chosen by the
  protocol's name or its capabilities: v1 :class:`~vr_driver.controller.program_v1.ControllerProgramV1`
  (the thesis' 14-byte handshake on a :class:`~vr_driver.controller.arm.SimArm`), v2
  :class:`~vr_driver.controller.program_v2.ControllerProgramV2` (streamed joint targets with
  look-ahead blending on a :class:`~vr_driver.controller.stream_arm.SimStreamArm`), v3
  :class:`~vr_driver.controller.program_v3.ControllerProgramV3` (Cartesian targets into a ring of
  ``ring_size`` positions, solved by the controller's own IK, run as MOVEP with an
  ``interpreter_lookahead`` of MOVEs read ahead, on a SimStreamArm). A protocol without a
  registered program is refused in words.
- The command line: :mod:`vr_driver.controller.cli` (``python3 -m vr_driver.controller``).

**Every assumption about the real G2 is a parameter** (:data:`~vr_driver.controller.options.ASSUMPTIONS`,
the table in doc/controller_program.md §10.9; each a SimOptions field, a ``--option`` of the CLI and
a ``~param`` of the ROS node; the defaults are the model the rest of the stack is tested against):
the card's ``byte_order``, the program's ``loop_period`` and its spread ``loop_jitter`` (seeded by
``loop_jitter_seed``, :class:`~vr_driver.controller.options.LoopTiming`), ``loop_blocks_during_move``
and ``unreachable`` (:mod:`vr_driver.controller.session`), ``data_exchange_bit``, ``configuration``,
v3's ``interpreter_lookahead`` and ``send_ahead`` (:mod:`vr_driver.controller.program_v3`), and the
streaming arm's ``speed_scale`` (MOVEP's speed unit), ``blend_across_input_read``, ``ramp_time``,
``ramp_shape`` and ``accelerations`` (:mod:`vr_driver.controller.stream_arm`).
"""
from __future__ import annotations

import logging
import math
import threading
import time
from typing import IO, Any, Callable, Optional, Sequence, Tuple, Union

from pyprofibus_vendor.config import default_robot_config
from pyprofibus_vendor.dp_slave import DpSlave, SlaveServer, SlaveState
from pyprofibus_vendor.phy import Link

from ..errors import ProtocolError, VrDriverError
from ..kinematics.solver import ConfigurationRule, Kinematics
from ..poses import HOME_POSE, ControllerPose
from ..protocol import registry as protocols
from ..protocol.common import ByteOrder, FeedbackRecord, StreamState
from ..protocol.v1 import PROGRAM_PATH_SPEED, PROGRAM_SPEED, ControllerState
from .arm import ExecutionLog, IntPose, LogEntry, SimArm
from .options import (DEFAULT_ADDRESS, DEFAULT_BAUD, DEFAULT_BRAKE_TIME, DEFAULT_LOOP_PERIOD, LoopTiming, SimOptions,
                      protocol_option, true_kinematics, true_zero_offsets)
from .program_v3 import DEFAULT_INTERPRETER_LOOKAHEAD, DEFAULT_RING_SIZE, SendAhead
from . import programs  # noqa: F401  (registers the built-in protocols' programs)
from .pty_link import SimPort
from .session import Unreachable
from .simulator import SimError, Simulator
from .stream_arm import RampShape, SimStreamArm, StreamLogEntry

__all__ = ["FAULTS", "robot_slave", "VirtualController"]

log = logging.getLogger(__name__)

Clock = Callable[[], float]

#: the faults a test or the ROS node injects (:meth:`VirtualController.set_fault`)
FAULTS = ("estop", "drives_powered", "error")


def robot_slave(address: int = DEFAULT_ADDRESS, clock: Clock = time.monotonic,
                protocol: Any = protocols.DEFAULT) -> DpSlave:
    """The G2's DP slave: ident 0x06C6 and the protocol's Chk_Cfg (v1: the one of
    ``config.default_robot_config()``, 14 bytes each way; v2: ``protocol.v2.CHK_CFG_V2``, 72 bytes;
    v3: ``protocol.v3.CHK_CFG_V3``, 28 bytes in, 24 out)."""
    wire = protocol_option(protocol)
    slave_cfg = default_robot_config("virtual", phy_type="memory", slave_address=address).slave(address)
    cfg = wire.chk_cfg or slave_cfg.cfg
    return DpSlave(address, slave_cfg.ident, cfg, clock=clock)


class VirtualController(Simulator):
    """The virtual G2: DP slave + program loop + simulated arm, on a link.

    ``link``: None (default) creates a raw pty pair -- clients open :attr:`device_path`; with
    ``pty_link`` a symlink to it is made there (replacing a stale symlink, never another file) and
    removed by :meth:`stop`. A string serves that existing device (``SerialLink(link, baud)``). A
    :class:`~pyprofibus_vendor.phy.Link` is used as it is (the caller closes it).
    ``confirm_records`` (default: the protocol's ``confirm_records``, True for v1): the program acts
    on a master record only once it arrived in two consecutive Data_Exchange telegrams
    (:mod:`vr_driver.controller.program_v1`; v2's CRC-16 and v3's check word close the gap the rule
    closes for v1, without costing a bus cycle per target).
    ``protocol`` (a name or a protocol object) runs the program the protocol object names
    (:meth:`~vr_driver.protocol.base.Protocol.controller_program`; SimError for a protocol without
    one) on a slave with its Chk_Cfg and the arm that program moves (its ``make_arm``; a given
    ``arm`` must be of its ``ARM_TYPE``): ``"v1"`` (default)
    :class:`~vr_driver.controller.program_v1.ControllerProgramV1` on a 14-byte slave and a
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
                 accelerations: Optional[Sequence[float]] = None, program_speed: float = PROGRAM_SPEED,
                 program_path_speed: float = PROGRAM_PATH_SPEED) -> None:
        pose = initial_pose.as_tuple() if isinstance(initial_pose, ControllerPose) else initial_pose
        self.options = SimOptions(device=link if isinstance(link, str) else None, pty_link=pty_link,
                                  address=address, baud=baud, speed_factor=speed_factor,
                                  initial_pose=tuple(pose), loop_period=loop_period,
                                  byte_order=ByteOrder.parse(byte_order).value, log_file=log_file,
                                  brake_time=brake_time, protocol=protocol_option(protocol).name,
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
                                  accelerations=None if accelerations is None else tuple(accelerations),
                                  program_speed=program_speed, program_path_speed=program_path_speed)
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
        try:
            program_type = self.wire.controller_program()      # its own, never another protocol's
        except ProtocolError as exc:
            raise SimError(str(exc)) from None
        if confirm_records is None:
            confirm_records = self.wire.confirm_records
        if arm is None:
            try:
                arm = program_type.make_arm(kinematics, self.options, clock)
            except VrDriverError as exc:
                raise SimError("initial pose %s: %s" % (self.options.initial_pose, exc)) from exc
        if not isinstance(arm, program_type.ARM_TYPE):
            raise SimError("protocol %s needs a %s, got a %s" % (self.protocol, program_type.ARM_TYPE.__name__,
                                                                 type(arm).__name__))
        self.arm: Any = arm
        self.execution_log = ExecutionLog()
        self.slave = robot_slave(self.options.address, clock, self.wire)
        #: the protocol's program (:meth:`vr_driver.protocol.base.Protocol.controller_program`)
        self.program: Any = program_type.from_options(self.slave, arm, self.options,
                                                      execution_log=self.execution_log,
                                                      confirm_records=confirm_records,
                                                      kinematics=controller_kinematics)
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
        self.server = SlaveServer(self.port.link, self.slave, clock=clock)

    # ----------------------------------------------------------------------- set-up / tear-down
    def start(self) -> "VirtualController":
        """Serve the bus and run the program loop in background threads."""
        if self._thread is not None:
            return self
        self._stop.clear()
        self.server.start()
        self._thread = threading.Thread(target=self._run, name="vr-sim-program", daemon=True)
        self._thread.start()
        log.info("virtual G2 controller on %s: DP slave %d (ident 0x%04X), protocol %s, loop %.0f ms, "
                 "speed x%g", self.device_path or self.port.link, self.slave.address, self.slave.ident,
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

    def step(self, now: Optional[float] = None) -> Optional[FeedbackRecord]:
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
    def feedback(self) -> Optional[FeedbackRecord]:
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

    def true_joints_sample(self) -> Tuple[Tuple[float, ...], float]:
        """(:attr:`true_joints`, their age [s]: the time since the arm's step that put it there,
        0 before the first step), read together: a sample's stamp is then now minus the age, the
        time the arm was there, however late the reader runs."""
        joints, stepped = self.arm.stepped_joints()
        age = self.arm.clock() - stepped if math.isfinite(stepped) else 0.0
        return tuple(q + z for q, z in zip(joints, self.zero_offsets)), max(0.0, age)

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
