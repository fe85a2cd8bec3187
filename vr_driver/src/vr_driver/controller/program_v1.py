"""The virtual G2 controller's program for protocol v1 (doc/controller_program.md): the thesis'
14-byte Cartesian targets, one at a time through the request handshake, on a DP slave with the
default Chk_Cfg, moving a :class:`~vr_driver.controller.arm.SimArm`. ROS-free.

Each :meth:`ControllerProgramV1.step` (``now`` injected) checks the DP watchdog, reads the slave's
output image (the master's command), runs :class:`~vr_driver.protocol.v1.ControllerHandshake` and
the arm, and writes the :class:`~vr_driver.protocol.v1.Feedback` into the slave's input image.
Every handled request becomes one :class:`~vr_driver.controller.arm.LogEntry` in the
:class:`~vr_driver.controller.arm.ExecutionLog`.

Rules of the program (also in ``doc/controller_program.md``; the link side is
:mod:`vr_driver.controller.session`'s, shared with the streaming programs):

- Only a record the master sent in the current Data_Exchange session counts (a session starts
  each time the slave enters Data_Exchange). Outside Data_Exchange, and in a new session before
  the master's first Data_Exchange, there is no command (flag 0); the slave itself replaces its
  outputs by the safe image (all zero) when it leaves Data_Exchange.
- Two-telegram rule (``confirm_records``, the virtual controller's default for v1, which has no
  integrity check of its own): a record counts only once it arrived unchanged in two consecutive
  Data_Exchange telegrams of the session (the master repeats its record every cycle, so this costs
  one bus cycle per change). A telegram corrupted on the line in a way the PROFIBUS checks miss
  (the 8-bit FCS passes about 1 in 256 multi-byte corruptions) is then never acted on; without the
  rule such a telegram can start a wrong target, re-start the previous one (flag 0 turned into 1),
  or release a DONE early so that the still raised flag starts the same target again.
- Disarmed at start and after every link loss: a request counts only after a record with the flag
  at 0 (it arms the program when it arrives, even if the program loop never saw it: the flag may
  rise in the very next telegram). A flag still raised from before the loss is answered REJECTED
  (held until the flag drops, logged with the reason) and nothing moves, so a motion never starts
  from a stale request.
- Exactly once across a reset (doc/controller_program.md §4 rule 10): after the card's watchdog or
  a new Set_Prm the program takes a new command only after the idle record came in a Data_Exchange
  of the new session, where it can read its card's Data_Exchange status (``data_exchange_bit``,
  an assumption); without it the card's safe image is v1's idle record, the program cannot see a
  reset, and the master's idle record at the start of every session keeps v1 exactly once.
- Link loss (the DP watchdog expired, or the master re-parameterised the slave -- also when it
  did so between two loops): the arm stops at once -- at the position of the watchdog deadline, so
  it never moves longer than the watchdog time after the master's last telegram --, the target in
  flight ends REJECTED in the log, the via point is dropped and the handshake restarts at READY.
  The master must send a new target.
- Flag 2 (stop, ``Command.stop``) while BUSY is a controlled stop: the arm decelerates along its
  path over ``brake_time`` (default 0.3 s of robot time; 0 halts at once) with IN_MOTION set, and
  the target ends REJECTED once the arm is at rest (the state stays BUSY until then). Outside BUSY
  flag 2 is "no request".
- E-stop, drives off or an error during a motion stop the arm at once (controller.arm); the target
  ends REJECTED (state 3, held until the flag drops). While any of them is active a request is
  REJECTED and the status bits say which (ESTOP; DRIVES_POWERED clear; ERROR). The e-stop switches
  the drives off; after it is released they stay off until switched on again (``set_fault
  ("drives_powered", True)``, the node's ``~set_drives_powered`` service), as on a real G2.
- A target the arm cannot reach or plan (outside the reach, joint limits, joint jump, singular,
  degenerate circle) is REJECTED without motion; a CIRC_END without a stored via as well.
- A record the program cannot decode (flag byte not 0/1/2, unknown move type) is treated as flag 0
  and counted in :attr:`ControllerProgramV1.bad_records` (a log warning names the bytes); the
  master then sees no answer and times out.
- PROGRAM_RUNNING is set in every record the program writes.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable, Optional

from pyprofibus_vendor.dp_slave import DpSlave

from ..errors import VrDriverError
from ..poses import ControllerPose
from ..protocol.common import ByteOrder, StatusBits
from ..protocol.v1 import Command, ControllerHandshake, ControllerState, Feedback
from .arm import ExecutionLog, LogEntry, MotionResult, Outcome, SimArm
from .session import SessionProgram, Unreachable, arm_status_bits

__all__ = ["ControllerProgramV1"]

log = logging.getLogger(__name__)


@dataclass
class _Pending:
    seq: int
    command: Command
    via: Optional[Command]
    start_time: float


class ControllerProgramV1(SessionProgram):
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

    # ------------------------------------------------------------------- built by the virtual G2
    ARM_TYPE = SimArm

    @classmethod
    def make_arm(cls, kinematics: Any, options: Any, clock: Callable[[], float]) -> SimArm:
        return SimArm(kinematics, speed_factor=options.speed_factor, initial_pose=ControllerPose(*options.initial_pose),
                      clock=clock, brake_time=options.brake_time, configuration=options.configuration,
                      program_speeds=(options.program_speed, options.program_path_speed))

    @classmethod
    def from_options(cls, slave: DpSlave, arm: SimArm, options: Any, *, execution_log: Any,
                     confirm_records: bool, kinematics: Any = None) -> "ControllerProgramV1":
        return cls(slave, arm, byte_order=options.byte_order, execution_log=execution_log,
                   confirm_records=confirm_records, **cls.loop_options(options))

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
