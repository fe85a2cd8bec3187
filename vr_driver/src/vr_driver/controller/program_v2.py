"""The virtual G2 controller's program for protocol v2 (doc/controller_program.md §9): streamed
joint targets with sequence numbers and a look-ahead slot, on a DP slave configured with
``CHK_CFG_V2`` (72 bytes each way), moving a :class:`~vr_driver.controller.stream_arm.SimStreamArm`. ROS-free.

Each :meth:`ControllerProgramV2.step` (``now`` injected):

1. the link side shared with v1 (:class:`~vr_driver.controller.session.SessionProgram`): watchdog,
   session (no two-telegram rule by default: the CRC-16 does its job, rule 9.3.7), disarmed at
   start and after a link loss until a record with
   both slots empty arrived; a link loss brakes the arm along its path (rule 9.3.5), drops the
   queue, and the next stream needs START. A record whose CRC or version is wrong does not decode:
   counted in ``bad_records`` and ignored;
2. the arm advances to ``now`` (targets passed, reached or stopped go to the execution log);
3. STOP brakes the arm and drops the queue; otherwise the slots are taken by rules 9.3:

   - ``seq`` 0: an empty slot; a ``seq`` not after ``accepted_seq`` is a repeat and is ignored;
   - while disarmed: refused NOT_ARMED (2);
   - slot 0 with START while the arm is IDLE with nothing queued begins a new stream (needed at
     start and after a link loss); otherwise only ``accepted_seq + 1`` is taken. Any other new
     ``seq`` is refused OUT_OF_ORDER (1); the arm then stops at the last point it was given;
   - no room in the queue of two (or the arm is stopping): the slot waits (neither taken nor
     refused); the master repeats it;
   - a fault active: refused FAULT (3); joints outside the limits: refused UNREACHABLE (4);
   - else taken: ``accepted_seq`` = its seq. Slot 1 is looked at only if slot 0 was taken or a
     repeat.

   A refusal is logged once per (seq, code), however often the master repeats the record;
4. the :class:`~vr_driver.protocol.v2.FeedbackV2` goes into the slave's input image: the arm's
   state, status bits, accepted / done / active / rejected seq and the reject code, the exact joints
   and the TCP pose in the wire's units, and a heartbeat that grows by one every loop.

Every target taken ends in exactly one :class:`~vr_driver.controller.stream_arm.StreamLogEntry` (executed,
blended or stopped), every refusal in one entry with outcome ``rejected``.

A streaming program of another record (protocol v3's Cartesian targets,
:class:`~vr_driver.controller.program_v3.ControllerProgramV3`) keeps these rules and overrides the
small hooks of the loop: :meth:`~ControllerProgramV2.command_slots`,
:meth:`~ControllerProgramV2.command_outputs`, :meth:`~ControllerProgramV2.room`,
:meth:`~ControllerProgramV2.stream_idle`, :meth:`~ControllerProgramV2.prepare`,
:meth:`~ControllerProgramV2.queue`, :meth:`~ControllerProgramV2.brake`,
:meth:`~ControllerProgramV2.on_arm_advanced`, :meth:`~ControllerProgramV2.make_feedback` and
:meth:`~ControllerProgramV2.refusal_entry`.
"""
from __future__ import annotations

import logging
from typing import Any, Callable, Optional, Sequence, Tuple

from pyprofibus_vendor.dp_slave import DpSlave

from ..poses import ControllerPose
from ..protocol.common import (SEQ_MAX, Control, RejectCode, StreamState, joints_to_wire, next_seq, seq_after,
                               seq_offset)
from ..protocol.v2 import V2, CommandV2, FeedbackV2
from .session import SessionProgram, Unreachable, arm_status_bits
from .arm import ExecutionLog, Outcome
from .stream_arm import SimStreamArm, StreamLogEntry, StreamTarget, wire_pose

__all__ = ["ControllerProgramV2", "GRIPPER_DELAY"]

#: s from setting output 1 to input 1 ("gripper closed") following it (the simulated gripper)
GRIPPER_DELAY = 0.3

log = logging.getLogger(__name__)


class ControllerProgramV2(SessionProgram):
    """The v2 program loop on one DP slave (``CHK_CFG_V2``) and one :class:`SimStreamArm`.

    Call :meth:`step` once per loop with the clock time; it returns the FeedbackV2 it wrote. One
    thread runs it (the arm and the log are thread-safe, so faults can be injected from anywhere).
    """

    #: a slot 0 this many numbers beyond ``accepted_seq + 1`` waits (neither taken nor refused): the
    #: master sent it before the acknowledgement of the one before it (protocol.send_ahead beyond
    #: the record's slots); v2's two slots leave none
    waits_ahead = V2.send_ahead - V2.look_ahead_slots

    def __init__(self, slave: DpSlave, arm: SimStreamArm, *, execution_log: Optional[ExecutionLog] = None,
                 confirm_records: bool = False, data_exchange_bit: bool = True,
                 loop_blocks_during_move: bool = False, unreachable: Any = Unreachable.SKIP) -> None:
        super().__init__(slave, arm, confirm_records=confirm_records, data_exchange_bit=data_exchange_bit,
                         loop_blocks_during_move=loop_blocks_during_move, unreachable=unreachable)
        self.arm: SimStreamArm = arm
        self.log = execution_log if execution_log is not None else ExecutionLog()
        self.last_feedback: Optional[FeedbackV2] = None
        self.last_command: Optional[CommandV2] = None
        self.accepted_seq = 0
        self.rejected_seq = 0
        self.reject_code = RejectCode.NONE
        self.need_start = True              # a stream begins with START (at start, after a link loss)
        self._refused: Optional[Tuple[int, RejectCode]] = None
        # the controller's own general-purpose I/O (§9.5): outputs 1..16 as the master sets them
        # (0 = the safe state: at start and after a link loss); a gripper wired to output 1 reports
        # closed on input 1 GRIPPER_DELAY after output 1 was set; inputs 2..16 set by set_input()
        self.io_outputs = 0
        self._gripper_cmd = (0, 0.0)        # (output 1, when it last changed)
        self._forced_inputs = 0

    # ------------------------------------------------------------------- built by the virtual G2
    ARM_TYPE = SimStreamArm

    @classmethod
    def make_arm(cls, kinematics: Any, options: Any, clock: Callable[[], float], **extra: Any) -> SimStreamArm:
        """The streaming arm of the options (``extra``: a subclass's further arguments)."""
        return SimStreamArm(kinematics, speed_factor=options.speed_factor,
                            initial_pose=ControllerPose(*options.initial_pose), clock=clock,
                            brake_time=options.brake_time, configuration=options.configuration,
                            ramp_time=options.ramp_time, speed_scale=options.speed_scale,
                            blend_across_input_read=options.blend_across_input_read,
                            ramp_shape=options.ramp_shape, accelerations=options.accelerations, **extra)

    @classmethod
    def from_options(cls, slave: DpSlave, arm: SimStreamArm, options: Any, *, execution_log: Any,
                     confirm_records: bool, kinematics: Any = None) -> "ControllerProgramV2":
        return cls(slave, arm, execution_log=execution_log, confirm_records=confirm_records,
                   **cls.loop_options(options))

    # ------------------------------------------------------------------- SessionProgram hooks
    def decode_record(self, raw: bytes) -> CommandV2:
        return CommandV2.decode(raw)

    def is_idle_command(self, command: CommandV2) -> bool:
        return command.slot0.empty and command.slot1.empty

    def on_link_lost(self, why: str, stop_time: float) -> None:
        self.brake(why, stop_time)
        self._log_entries(self.arm.collect())
        self.need_start = True
        self._set_outputs(0, stop_time)            # the outputs' safe state until the master sets them

    def advance_suspended(self, now: float) -> None:
        self._log_entries(self.arm.step(now))

    def on_halt(self, reason: str, now: float) -> None:
        self._log_entries(self.arm.collect())      # the arm's error stopped it and dropped its queue

    def on_restart(self, now: float) -> None:
        """A fresh program: nothing taken, a new stream begins with START, no refusal shown."""
        self.accepted_seq = 0
        self.rejected_seq = 0
        self.reject_code = RejectCode.NONE
        self.need_start = True
        self._refused = None

    # ------------------------------------------------------------------- general-purpose I/O
    def set_input(self, number: int, value: bool) -> None:
        """Set general-purpose input ``number`` (2..16; input 1 is the simulated gripper's)."""
        if not 2 <= number <= 16:
            raise ValueError("input %r: 2..16 can be set (1 is the gripper's 'closed')" % (number,))
        bit = 1 << (number - 1)
        self._forced_inputs = (self._forced_inputs | bit) if value else (self._forced_inputs & ~bit)

    def inputs(self, now: float) -> int:
        out1, since = self._gripper_cmd
        closed = 1 if out1 and now - since >= GRIPPER_DELAY else 0
        return self._forced_inputs | closed

    def _set_outputs(self, value: int, now: float) -> None:
        if (value & 1) != self._gripper_cmd[0]:
            self._gripper_cmd = (value & 1, now)
        self.io_outputs = value

    # ---------------------------------------------------------------------------- read-outs
    @property
    def state(self) -> StreamState:
        return self.arm.state

    # ------------------------------------------------------------------------------ the loop
    def step(self, now: float) -> Any:
        """One program loop at clock time ``now`` (none while a MOVE blocks it or an alarm halted it:
        the last feedback stays on the bus, :meth:`~vr_driver.controller.session.SessionProgram.suspended`)."""
        if self.suspended(now):
            return self.last_feedback
        command, stale = self.read_command(now)
        self._log_entries(self.arm.step(now))
        self.on_arm_advanced(now)
        if command is not None and not stale:
            outputs = self.command_outputs(command)
            if outputs is not None:
                self._set_outputs(outputs, now)
        if command is not None:
            if Control.STOP in command.control:
                if self.brake("STOP from the master", now):
                    log.info("STOP: braking, queue dropped")
            else:
                alarm = self._take(command, now, stale)
                if alarm is not None:                 # halted before this loop wrote its record
                    self.halt(alarm, now)
                    return self.last_feedback
            self._log_entries(self.arm.collect())
        feedback, raw = self.make_feedback(now)
        self.slave.inputs = raw
        self.last_feedback = feedback
        return feedback

    # ---------------------------------------------------------------------- hooks of the loop
    def command_slots(self, command: Any) -> Sequence[Any]:
        """The command's target slots in order (v2: slot 0, then the look-ahead slot 1)."""
        return (command.slot0, command.slot1)

    def command_outputs(self, command: Any) -> Optional[int]:
        """The general-purpose outputs a command sets, or None where the record carries none."""
        return command.outputs

    def room(self) -> int:
        """How many more targets the program takes now (v2: the arm's queue of two)."""
        return self.arm.room()

    def stream_idle(self) -> bool:
        """At rest with nothing taken but not yet run: a START may begin a new stream."""
        return self.arm.state is StreamState.IDLE and not self.arm.queued

    def prepare(self, slot: Any, now: float) -> Tuple[Optional[StreamTarget], RejectCode, str]:
        """The target to queue for a slot that may be taken, or (None, code, reason) to refuse it
        (v2: joints outside the limits -> UNREACHABLE)."""
        target = StreamTarget(slot.seq, slot.joints, slot.speed, slot.smooth, now)
        bad = self.arm.limit_violation(target.joints)
        if bad is not None:
            return None, RejectCode.UNREACHABLE, bad
        return target, RejectCode.NONE, ""

    def queue(self, target: StreamTarget, now: float) -> None:
        """Queue a target taken (v2: to the arm; it starts at once from rest)."""
        self.arm.push(target, now)

    def brake(self, reason: str, now: float) -> bool:
        """STOP or a link loss: brake the arm along its path and drop what is queued; True if the
        arm was moving and not braking already."""
        return self.arm.brake(reason, now=now)

    def on_arm_advanced(self, now: float) -> None:
        """Called each loop once the arm has advanced to ``now``, before the command is handled."""

    def make_feedback(self, now: float) -> Tuple[Any, bytes]:
        """The feedback record of this loop and its bytes for the slave's input image."""
        feedback = FeedbackV2(
            state=self.arm.state, status=arm_status_bits(self.arm), reject_code=self.reject_code,
            accepted_seq=self.accepted_seq, done_seq=self.arm.done_seq, active_seq=self.arm.active_seq,
            rejected_seq=self.rejected_seq, joints=joints_to_wire(self.arm.joints),
            tcp=wire_pose(self.arm.pose), heartbeat=self.loops % (SEQ_MAX + 1),
            inputs=self.inputs(now), outputs=self.io_outputs, armed=self.armed)
        return feedback, feedback.encode()

    def refusal_entry(self, slot: Any, code: RejectCode, now: float, reason: str) -> StreamLogEntry:
        """The execution-log entry of a refused slot."""
        return StreamLogEntry(slot.seq, slot.joints, slot.speed, slot.smooth, Outcome.REJECTED, reason, now,
                              None, now, joints_to_wire(self.arm.joints), reject_code=int(code))

    # ------------------------------------------------------------------------------- helpers
    def _take(self, command: Any, now: float, stale: bool) -> Optional[str]:
        """Take the command's slots by the rules; returns the alarm that halts the program (an
        unreachable target with ``unreachable`` = alarm_halt), else None."""
        for index, slot in enumerate(self.command_slots(command)):
            if slot.empty:
                return None
            if not seq_after(slot.seq, self.accepted_seq):
                continue                                    # taken already: a repeat
            if stale:
                self._refuse(slot, RejectCode.NOT_ARMED, now,
                             "raised before the controller saw a record with both slots empty "
                             "after (re)start / link loss")
                return None
            start = index == 0 and Control.START in command.control
            if not start and 2 <= seq_offset(slot.seq, self.accepted_seq) <= 1 + self.waits_ahead:
                return None         # sent ahead of the acknowledgement of the one before it: it waits
            idle = self.stream_idle()
            if start and not idle and self.need_start:
                return None                                     # wait until the arm is at rest
            if not (start and idle) and (self.need_start or slot.seq != next_seq(self.accepted_seq)):
                why = "a new stream (at start, after a link loss) begins with START" if self.need_start \
                    else "expected %d (after %d)" % (next_seq(self.accepted_seq), self.accepted_seq)
                self._refuse(slot, RejectCode.OUT_OF_ORDER, now, why)
                return None
            if self.room() <= 0:
                return None                                     # the queue is full: it waits
            blocked = self.arm.blocked_reason()
            if blocked is not None:
                self._refuse(slot, RejectCode.FAULT, now, blocked)
                return None
            target, code, why = self.prepare(slot, now)
            if target is None and code is RejectCode.UNREACHABLE and self.unreachable is Unreachable.ALARM_HALT:
                why = "target %d unreachable: %s" % (slot.seq, why)
                self.log.append(self.refusal_entry(slot, code, now, "alarm, the program halted: %s" % why))
                return why
            if target is None:
                self._refuse(slot, code, now, why)
                return None
            self.queue(target, now)
            self.accepted_seq = slot.seq
            self.need_start = False
            self._refused = None            # a later refusal of a reused number is logged again
            log.debug("taken: %s", slot.describe())
        return None

    def _refuse(self, slot: Any, code: RejectCode, now: float, reason: str) -> None:
        self.rejected_seq, self.reject_code = slot.seq, code
        if self._refused == (slot.seq, code):
            return                                          # the master repeats its record
        self._refused = (slot.seq, code)
        log.info("target %d refused (%s): %s", slot.seq, code.name, reason)
        self.log.append(self.refusal_entry(slot, code, now, reason))

    def _log_entries(self, entries) -> None:
        for entry in entries:
            if entry.outcome is Outcome.STOPPED:
                log.info("target %d stopped: %s", entry.seq, entry.reason)
            self.log.append(entry)
