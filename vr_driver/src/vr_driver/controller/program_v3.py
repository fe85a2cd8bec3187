"""The virtual G2 controller's program for protocol v3 (doc/controller_program.md §10): Cartesian
targets streamed one per record into a ring of positions, run as MOVEP joint moves with a speed and
a smooth level by an interpreter that reads ``interpreter_lookahead`` MOVEs ahead. ROS-free.

It is :class:`~vr_driver.controller.program_v2.ControllerProgramV2`'s loop and rules (session,
arming, exactly once, START / STOP, link loss, refusals and their log entries), with the v3 record
and these differences, through the v2 program's hooks:

- **One slot per record**, decoded in the ``byte_order`` parameter; a record whose check word or
  seq copy fails does not decode: counted in ``bad_records``, ignored.
- **The ring** (``ring_size`` positions, default 4): a slot is taken (``accepted_seq``) into the
  ring only while it has room; otherwise it waits (neither taken nor refused) and the master
  repeats it. A target occupies the ring from being taken until it is passed, reached or dropped:
  the one the arm moves to and those the interpreter has read ahead count too.
- **The controller's own IK**: a target is converted to joints when it is taken, with the program's
  :class:`~vr_driver.kinematics.solver.Kinematics` (default: the model's, its own instance; it may
  differ from the arm's, as a real G2's model differs from the robot), choosing the solution nearest
  the joints of the previous target still in the ring or the arm (or the arm's joints when none is):
  the G2 behaviour §7 assumes (the arm's ``configuration``: ``current_joints`` takes the arm's joints
  always). A pose it cannot solve within the joint limits is refused
  UNREACHABLE (4); a kind other than MOVEP is refused BAD_SLOT (5): this program runs MOVEP only.
- **The interpreter look-ahead** (``arm.look_ahead``, set from ``interpreter_lookahead``): the
  arm holds the MOVE it runs and that many more from the ring; the program hands the ring's next
  target over whenever the arm has room. 0: the next MOVE is read only once the current one has
  ended, so the arm stops at every point whatever the smooth level; >= 1: it blends as v2's arm.
- **Sending ahead** (``send_ahead``, :class:`SendAhead`; an assumption, §10.4 rule 7): a slot one
  number beyond ``accepted_seq + 1`` waits (``accepted``, the default: neither taken nor refused,
  the master repeats it) or is refused OUT_OF_ORDER (``refused``: a program that takes only the
  next number; the feedback shows ``rejected_seq`` = that seq, code 1, and a driver that sends
  ahead ends every stream at its second target).
- STOP and a link loss drop the ring (each target ``stopped``, "dropped before it started") and
  brake the arm; a fault (e-stop, drives off, error) drops the ring too.
- The feedback is a :class:`~vr_driver.protocol.v3.FeedbackV3` (no joints, no I/O); the execution
  log entries carry the seq and the Cartesian target as on the wire (X Y Z 0.1 mm, Rx Ry Rz
  0.01 deg), move type ``MOVEP``.
"""
from __future__ import annotations

import collections
import enum
import logging
from dataclasses import dataclass
from typing import Any, Callable, Deque, Optional, Sequence, Tuple

from pyprofibus_vendor.dp_slave import DpSlave

from .. import validate
from ..errors import KinematicsError, MotionError, PoseError
from ..kinematics.solver import Kinematics
from ..protocol.common import SEQ_MAX, ByteOrder, RejectCode, joints_to_wire
from ..protocol.v3 import V3, CartesianKind, CartesianSlot, CommandV3, FeedbackV3, pose_from_wire, pose_to_wire
from .arm import ExecutionLog, Outcome
from .program_v2 import ControllerProgramV2
from .session import Unreachable, arm_status_bits
from .stream_arm import SimStreamArm, StreamLogEntry, StreamTarget

__all__ = ["ControllerProgramV3", "CartesianTarget", "SendAhead", "DEFAULT_RING_SIZE",
           "DEFAULT_INTERPRETER_LOOKAHEAD"]

#: positions the G2 program's ring holds (targets taken and not yet passed, reached or dropped)
DEFAULT_RING_SIZE = 4
#: MOVEs the G2's interpreter reads beyond the running one (an assumption to check on a real G2)
DEFAULT_INTERPRETER_LOOKAHEAD = 1

log = logging.getLogger(__name__)


class SendAhead(enum.Enum):
    """What the G2 program does with a target one number ahead of the next it takes (§10.4 rule 7,
    an assumption): ``accepted`` -- it waits (the default, the rule); ``refused`` -- refused
    OUT_OF_ORDER."""

    ACCEPTED = "accepted"
    REFUSED = "refused"

    parse = validate.choice_parser(MotionError, "send_ahead must be {words}, got {value!r}")


@dataclass(frozen=True)
class CartesianTarget(StreamTarget):
    """A v3 target taken: the pose as received and the joints the controller's IK chose for it
    (``wire_joints`` is those joints in 0.001 deg, as v2's targets)."""

    solved: Tuple[float, ...] = ()          # rad: the controller's IK solution (what the arm moves to)
    wire_target: Tuple[int, ...] = ()       # the pose as received: X Y Z 0.1 mm, Rx Ry Rz 0.01 deg
    kind: str = CartesianKind.MOVEP.name

    @property
    def joints(self) -> Tuple[float, ...]:
        return self.solved

    @property
    def log_target(self) -> Tuple[int, ...]:
        return self.wire_target

    @property
    def move_type(self) -> str:
        return self.kind


class ControllerProgramV3(ControllerProgramV2):
    """The v3 program loop on one DP slave (``CHK_CFG_V3``) and one :class:`SimStreamArm` (whose
    ``look_ahead`` is the interpreter look-ahead). Call :meth:`step` once per loop with the clock
    time; it returns the FeedbackV3 it wrote."""

    waits_ahead = V3.send_ahead - V3.look_ahead_slots      # 1: the master sends one target ahead

    def __init__(self, slave: DpSlave, arm: SimStreamArm, *, kinematics: Optional[Kinematics] = None,
                 ring_size: int = DEFAULT_RING_SIZE, byte_order: Any = ByteOrder.LITTLE,
                 execution_log: Optional[ExecutionLog] = None, confirm_records: bool = False,
                 data_exchange_bit: bool = True, loop_blocks_during_move: bool = False,
                 unreachable: Any = Unreachable.SKIP, send_ahead: Any = SendAhead.ACCEPTED) -> None:
        if isinstance(ring_size, bool) or not isinstance(ring_size, int) or ring_size < 1:
            raise MotionError("ring_size must be an integer >= 1, got %r" % (ring_size,))
        self.byte_order = ByteOrder.parse(byte_order)     # before the slave's hooks may decode
        super().__init__(slave, arm, execution_log=execution_log, confirm_records=confirm_records,
                         data_exchange_bit=data_exchange_bit, loop_blocks_during_move=loop_blocks_during_move,
                         unreachable=unreachable)
        self.send_ahead = SendAhead.parse(send_ahead)
        if self.send_ahead is SendAhead.REFUSED:
            self.waits_ahead = 0                   # only accepted_seq + 1 is taken, anything else refused
        self.ring_size = ring_size
        self.kin = kinematics if kinematics is not None else Kinematics.default()
        self.ring: Deque[CartesianTarget] = collections.deque()
        self._newest: Optional[Tuple[float, ...]] = None     # joints of the newest target taken

    # ------------------------------------------------------------------- built by the virtual G2
    @classmethod
    def make_arm(cls, kinematics: Any, options: Any, clock: Callable[[], float], **extra: Any) -> SimStreamArm:
        """The streaming arm, reading ``interpreter_lookahead`` MOVEs ahead as the G2's interpreter."""
        return super().make_arm(kinematics, options, clock, look_ahead=options.interpreter_lookahead, **extra)

    @classmethod
    def from_options(cls, slave: DpSlave, arm: SimStreamArm, options: Any, *, execution_log: Any,
                     confirm_records: bool, kinematics: Any = None) -> "ControllerProgramV3":
        return cls(slave, arm, kinematics=kinematics, ring_size=options.ring_size, byte_order=options.byte_order,
                   execution_log=execution_log, confirm_records=confirm_records, send_ahead=options.send_ahead,
                   **cls.loop_options(options))

    # ------------------------------------------------------------------- SessionProgram hooks
    def decode_record(self, raw: bytes) -> CommandV3:
        return CommandV3.decode(raw, self.byte_order)

    def is_idle_command(self, command: CommandV3) -> bool:
        return command.slot.empty

    # ---------------------------------------------------------------------------- read-outs
    @property
    def occupancy(self) -> int:
        """Targets in the ring: taken and not yet passed, reached or dropped."""
        return len(self.ring) + len(self.arm.queued)

    # ----------------------------------------------------------------- ControllerProgramV2 hooks
    def command_slots(self, command: CommandV3) -> Sequence[CartesianSlot]:
        return (command.slot,)

    def command_outputs(self, command: CommandV3) -> Optional[int]:
        return None                          # v3 carries no controller I/O

    def room(self) -> int:
        if self.arm.braking:
            return 0
        return max(0, self.ring_size - self.occupancy)

    def stream_idle(self) -> bool:
        return super().stream_idle() and not self.ring

    def prepare(self, slot: CartesianSlot, now: float) -> Tuple[Optional[StreamTarget], RejectCode, str]:
        if slot.kind is not CartesianKind.MOVEP:
            return None, RejectCode.BAD_SLOT, "this program runs MOVEP targets only, not %s" % slot.kind.name
        seed = self.arm.configuration_seed(self._newest if self.occupancy else None)   # the rule (§7)
        try:
            joints = self.kin.ik_pose(pose_from_wire(slot.pose), seed=seed)
        except (KinematicsError, PoseError) as exc:
            return None, RejectCode.UNREACHABLE, "%s: %s" % (slot.describe(), exc)
        bad = self.arm.limit_violation(joints)
        if bad is not None:
            return None, RejectCode.UNREACHABLE, bad
        target = CartesianTarget(slot.seq, joints_to_wire(joints), slot.speed, slot.smooth, now,
                                 solved=tuple(joints), wire_target=slot.pose, kind=slot.kind.name)
        return target, RejectCode.NONE, ""

    def queue(self, target: StreamTarget, now: float) -> None:
        assert isinstance(target, CartesianTarget)
        self.ring.append(target)
        self._newest = target.solved
        self._feed(now)

    def brake(self, reason: str, now: float) -> bool:
        moved = super().brake(reason, now)
        self._log_entries(self.arm.collect())      # the arm's targets first: they came first
        self._drop_ring(reason, now)
        return moved

    def on_halt(self, reason: str, now: float) -> None:
        super().on_halt(reason, now)
        self._drop_ring("alarm: %s" % reason, now)

    def on_restart(self, now: float) -> None:
        super().on_restart(now)
        self._newest = None

    def on_arm_advanced(self, now: float) -> None:
        blocked = self.arm.blocked_reason()
        if blocked is not None:
            self._drop_ring(blocked, now)          # a fault drops the queue (the arm's went already)
        else:
            self._feed(now)

    def make_feedback(self, now: float) -> Tuple[FeedbackV3, bytes]:
        feedback = FeedbackV3(
            state=self.arm.state, status=arm_status_bits(self.arm), reject_code=self.reject_code,
            accepted_seq=self.accepted_seq, done_seq=self.arm.done_seq, active_seq=self.arm.active_seq,
            rejected_seq=self.rejected_seq, tcp=pose_to_wire(self.arm.pose),
            heartbeat=self.loops % (SEQ_MAX + 1), armed=self.armed)
        return feedback, feedback.encode(self.byte_order)

    def refusal_entry(self, slot: CartesianSlot, code: RejectCode, now: float, reason: str) -> StreamLogEntry:
        return StreamLogEntry(slot.seq, slot.pose, slot.speed, slot.smooth, Outcome.REJECTED, reason, now,
                              None, now, joints_to_wire(self.arm.joints), reject_code=int(code),
                              move_type=slot.kind.name)

    # ------------------------------------------------------------------------------- helpers
    def _feed(self, now: float) -> None:
        """The interpreter reads the ring's next MOVEs while the arm has room for them."""
        while self.ring and self.arm.room() > 0 and self.arm.blocked_reason() is None:
            self.arm.push(self.ring.popleft(), now)

    def _drop_ring(self, reason: str, now: float) -> None:
        if not self.ring:
            return
        joints = joints_to_wire(self.arm.joints)
        while self.ring:
            t = self.ring.popleft()
            self.log.append(StreamLogEntry(
                t.seq, t.wire_target, t.speed, t.smooth, Outcome.STOPPED,
                "dropped before it started: %s" % reason, t.taken_time, None, now, joints,
                move_type=t.kind))
