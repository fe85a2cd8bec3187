"""The vocabulary the controller protocols share (:mod:`vr_driver.protocol`), in one module that is no
protocol's own: what the driver, the virtual G2 and the tools use whatever the protocol, and what
one protocol's module takes from another's. ROS-free, no I/O.

- Words on the wire: :class:`ByteOrder` (the ``byte_order`` parameter), :func:`round_half_away`
  (every protocol rounds a value to its unit so), the int16 range.
- The status byte every feedback record carries (:class:`StatusBits`: the same six bits in v1, v2
  and v3).
- The streaming protocols' conventions (v2, v3, doc/controller_program.md §9 and §10): sequence
  numbers (:data:`SEQ_MAX`, :func:`next_seq`, :func:`seq_offset`, :func:`seq_after`), the control
  bits (:class:`Control`), the stream's state and why a target was refused (:class:`StreamState`,
  :class:`RejectCode`), the speed and smooth ranges and the blend a smooth level asks for
  (:func:`blend_window`), a feedback record in words (:func:`describe_stream_feedback`), joint
  angles in 0.001 deg (:func:`joints_to_wire`: v2's unit and the virtual G2's execution log's).
- One target slot (:class:`Slot`): a sequence number, a move kind, a smooth level, a speed and six
  integers, validated once; what the six integers are and the kinds a protocol knows are the
  protocol's data (:class:`SlotFormat`): v2's joint slot, v3's Cartesian slot.
- The record types a driver holds whatever the protocol: :class:`FeedbackRecord` (every protocol's
  feedback record is one; :class:`StreamFeedback` the fields the streaming protocols' share).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Sequence, Tuple, Type

from ..errors import PoseError, ProtocolError
from ..poses import ControllerPose

__all__ = [
    "ByteOrder", "parse_byte_order", "round_half_away", "INT16_MIN", "INT16_MAX", "INT32_MIN", "INT32_MAX",
    "StatusBits", "STATUS_RESERVED_MASK", "FeedbackRecord",
    "SEQ_MAX", "next_seq", "seq_offset", "seq_after", "SPEED_MAX", "SMOOTH_MAX", "BLEND_PER_LEVEL", "BLEND_MAX",
    "blend_window", "Control", "StreamState", "RejectCode", "StreamFeedback", "describe_stream_feedback",
    "JOINT_UNIT_DEG", "joints_to_wire", "joints_from_wire", "SlotFormat", "Slot",
]

INT16_MIN = -32768
INT16_MAX = 32767
INT32_MIN = -(2 ** 31)
INT32_MAX = 2 ** 31 - 1
#: status bits 6 and 7: reserved, must be 0
STATUS_RESERVED_MASK = 0xC0


# ------------------------------------------------------------------------------------ words on the wire

class ByteOrder(str, enum.Enum):
    """Order of the two bytes of each int16 word: ``little`` (the default of doc/controller_program.md) or ``big``."""

    LITTLE = "little"
    BIG = "big"

    @classmethod
    def parse(cls, value: Any, name: str = "byte_order") -> "ByteOrder":
        """``value`` as a ByteOrder; ProtocolError naming the parameter ``name`` otherwise."""
        if isinstance(value, ByteOrder):
            return value
        if isinstance(value, str):
            text = value.strip().lower()
            for member in cls:
                if member.value == text:
                    return member
        raise ProtocolError("parameter %s must be 'little' or 'big', got %r" % (name, value))

    @property
    def struct_prefix(self) -> str:
        return "<" if self is ByteOrder.LITTLE else ">"


def parse_byte_order(value: Any, name: str = "byte_order") -> ByteOrder:
    """Validate a byte order parameter ("little" / "big"); the error names ``name``."""
    return ByteOrder.parse(value, name)


def round_half_away(value: float) -> int:
    """Round to the nearest integer, halves away from zero (2.5 -> 3, -2.5 -> -3). Exact for every
    float (no ``floor(x + 0.5)`` error at 0.49999999999999994)."""
    magnitude = abs(value)
    whole = math.floor(magnitude)
    if magnitude - whole >= 0.5:   # exact: whole <= magnitude, same binade or zero
        whole += 1
    return int(-whole if value < 0 else whole)


# ----------------------------------------------------------------------------------- the status byte

class StatusBits(enum.IntFlag):
    """The status byte of every protocol's feedback (v1: byte 14). Bits 6-7 are reserved (0)."""

    DRIVES_POWERED = 1
    ESTOP = 2
    ERROR = 4
    IN_MOTION = 8
    PROGRAM_RUNNING = 16
    VIA_STORED = 32

    def describe(self) -> str:
        """The set bits in words, in bit order ("drives powered, in motion"); "none" when 0."""
        words = [_STATUS_WORDS[bit] for bit in _STATUS_ORDER if self & bit]
        extra = int(self) & ~0x3F
        if extra:
            words.append("reserved bits 0x%02X" % extra)
        return ", ".join(words) if words else "none"


_STATUS_ORDER = (StatusBits.DRIVES_POWERED, StatusBits.ESTOP, StatusBits.ERROR, StatusBits.IN_MOTION,
                 StatusBits.PROGRAM_RUNNING, StatusBits.VIA_STORED)
_STATUS_WORDS = {
    StatusBits.DRIVES_POWERED: "drives powered",
    StatusBits.ESTOP: "e-stop",
    StatusBits.ERROR: "error",
    StatusBits.IN_MOTION: "in motion",
    StatusBits.PROGRAM_RUNNING: "program running",
    StatusBits.VIA_STORED: "via point stored",
}


class FeedbackRecord:
    """What every protocol's feedback record is (v1 ``Feedback``, v2 ``FeedbackV2``, v3
    ``FeedbackV3`` derive from it), and all a module that is no protocol's own may rely on: ``state``
    (the protocol's state enum: v1 the handshake's, the streams :class:`StreamState`), ``status``
    (:class:`StatusBits`), ``values`` (the reported pose as on the wire: a tuple that changes exactly
    when the reported pose changes), ``pose`` (a ControllerPose in mm / deg) and ``describe()``.
    Anything else a record carries (the joints, the sequence numbers, the heartbeat) the protocol
    object reads out of it (:meth:`vr_driver.protocol.base.Protocol.feedback_joints`, ...)."""

    __slots__ = ()

    state: Any
    status: StatusBits

    @property
    def values(self) -> Tuple[int, ...]:
        raise NotImplementedError

    @property
    def pose(self) -> ControllerPose:
        raise NotImplementedError

    def describe(self) -> str:
        raise NotImplementedError


# ------------------------------------------------------------------------ the streaming protocols

#: sequence numbers run 1..SEQ_MAX and wrap to 1 (0 marks an empty slot / "none yet")
SEQ_MAX = 0xFFFF
#: a target's speed: 0.1 % of the joint speed limits, 1..SPEED_MAX
SPEED_MAX = 1000
#: a target's smooth (blending) level: 0 (an exact stop) .. SMOOTH_MAX
SMOOTH_MAX = 10
#: the blend through a point of smooth level k (doc/controller_program.md §6, the G2 behaviour this
#: design assumes): a window of BLEND_PER_LEVEL * k of the shorter of the two move times, at most
#: BLEND_MAX of it (the windows at a segment's two ends never overlap); the driver sizes the level
#: at a corner from it, the virtual controller moves by it
BLEND_PER_LEVEL = 0.05
BLEND_MAX = 0.5
#: joint angles as integers: this many degrees (0.001 deg; int32 fits J6's +-360 deg with room)
JOINT_UNIT_DEG = 0.001


def blend_window(smooth: int, move_time: float, next_move_time: float) -> float:
    """The blend window [s] through a point of smooth level ``smooth`` between two segments of those
    move times; the arm passes the point at about ``|v1 - v2| * window / 8`` from it."""
    if smooth <= 0:
        return 0.0
    return min(BLEND_PER_LEVEL * smooth, BLEND_MAX) * min(move_time, next_move_time)


def next_seq(seq: int) -> int:
    """The sequence number after ``seq`` (1..SEQ_MAX, wrapping to 1; after 0 comes 1)."""
    return 1 if seq >= SEQ_MAX else seq + 1


def seq_offset(seq: int, base: int) -> int:
    """How many numbers ``seq`` lies after ``base`` in the wrapping sequence 1..SEQ_MAX (0 for
    ``base`` itself; SEQ_MAX - 1 for the number just before it)."""
    return ((seq - 1) - (base - 1)) % SEQ_MAX


def seq_after(a: int, b: int) -> bool:
    """True if ``a`` comes after ``b`` in the wrapping sequence (within half the range)."""
    if a == 0:
        return False
    if b == 0:
        return True
    return 0 < (a - b) % SEQ_MAX < SEQ_MAX // 2


class Control(enum.IntFlag):
    """The control bits of a streaming protocol's command (v2, v3: byte 2)."""

    STOP = 1       # decelerate to rest now and drop every target taken but not yet moved to
    START = 2      # slot 0 starts a new stream (taken only when the controller is idle, queue empty)


class StreamState(enum.IntEnum):
    """The stream's state in a streaming protocol's feedback (v2, v3: byte 2)."""

    IDLE = 0       # at rest, nothing queued
    MOVING = 1     # moving to active_seq (a look-ahead target may be queued)
    STOPPING = 2   # decelerating after STOP, a fault or a link loss
    WAITING = 3    # at rest at done_seq's point: the next target did not come in time (a gap)


class RejectCode(enum.IntEnum):
    """Why a streaming protocol's controller refused ``rejected_seq`` (v2, v3: byte 4)."""

    NONE = 0
    OUT_OF_ORDER = 1    # not the sequence number after accepted_seq (a gap or a stale repeat)
    NOT_ARMED = 2       # raised before the controller saw an empty record after (re)start / loss
    FAULT = 3           # e-stop, drives off or an error
    UNREACHABLE = 4     # outside the joint limits or the reach; the controller's own check
    BAD_SLOT = 5        # unknown kind, speed 0 or above 100 %, smooth above SMOOTH_MAX


@dataclass(frozen=True)
class StreamFeedback(FeedbackRecord):
    """What every streaming protocol's feedback record starts with (v2 ``FeedbackV2``, v3
    ``FeedbackV3`` add their own fields after these): the stream's state, the status bits, why
    ``rejected_seq`` was refused, and the sequence numbers taken, passed, moved to and refused."""

    state: StreamState = StreamState.IDLE
    status: StatusBits = StatusBits(0)
    reject_code: RejectCode = RejectCode.NONE
    accepted_seq: int = 0
    done_seq: int = 0
    active_seq: int = 0
    rejected_seq: int = 0

    def _check_codes(self, record: str) -> None:
        """``state`` and ``reject_code`` as their enums; ProtocolError "<record>: ..." for a number
        neither knows."""
        try:
            object.__setattr__(self, "state", StreamState(self.state))
            object.__setattr__(self, "reject_code", RejectCode(self.reject_code))
        except ValueError as exc:
            raise ProtocolError("%s: %s" % (record, exc)) from None


def describe_stream_feedback(fb: Any, where: str = "") -> str:
    """A streaming protocol's feedback in words (its state, sequence numbers, status bits, a
    refusal, arming); ``where``: the arm's position as text, if the record has one to show."""
    text = "%s, taken %d, at %d, done %d%s; status: %s" % (
        fb.state.name, fb.accepted_seq, fb.active_seq, fb.done_seq, ", " + where if where else "",
        fb.status.describe())
    if fb.rejected_seq:
        text += "; refused %d (%s)" % (fb.rejected_seq, fb.reject_code.name)
    if not fb.armed:
        text += "; not armed"
    return text


def joints_to_wire(joints: Sequence[float]) -> Tuple[int, ...]:
    """Six joint angles [rad] as int32 in 0.001 deg (rounded half away from zero); PoseError
    naming the joint for a value that is not a finite number or does not fit int32."""
    values = tuple(joints)
    if len(values) != 6:
        raise PoseError("a joint target has 6 angles, got %d" % len(values))
    out = []
    for i, value in enumerate(values):
        name = "joint_%d" % (i + 1)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise PoseError("%s must be a finite number of radians, got %r" % (name, value))
        wire = round_half_away(math.degrees(value) / JOINT_UNIT_DEG)
        if not INT32_MIN <= wire <= INT32_MAX:
            raise PoseError("%s = %g rad does not fit the wire's int32 of 0.001 deg" % (name, value))
        out.append(wire)
    return tuple(out)


def joints_from_wire(values: Sequence[int]) -> Tuple[float, ...]:
    """int32 0.001 deg -> radians."""
    return tuple(math.radians(v * JOINT_UNIT_DEG) for v in values)


# ------------------------------------------------------------------------------------ the target slot

def _whole(value: Any, lo: int, hi: int) -> bool:
    return not isinstance(value, bool) and isinstance(value, int) and lo <= value <= hi


@dataclass(frozen=True)
class SlotFormat:
    """The part of a target slot (:class:`Slot`) that is a protocol's own, as data: the move kinds
    it knows (an IntEnum whose 0 is NONE), what its six integers are (``labels``, one each, with
    the unit: they name the field in an error), their range, and how a slot's target reads in
    words (``describe_values``)."""

    kinds: Type[enum.IntEnum]
    labels: Tuple[str, ...]
    value_range: Tuple[int, int]
    describe_values: Callable[[Tuple[int, ...]], str]
    speed_max: int = SPEED_MAX
    smooth_max: int = SMOOTH_MAX

    def kind_names(self) -> str:
        """The kinds in words: "0 none, 1 joint"."""
        return ", ".join("%d %s" % (int(k), k.name.lower()) for k in self.kinds)


@dataclass(frozen=True)
class Slot:
    """One target of a streaming protocol's command (or an empty slot: seq 0): its sequence number
    (1..SEQ_MAX), its move kind, its smooth level (0..``smooth_max``), its speed (0.1 % of the joint
    speed limits, 1..``speed_max``) and six integers in the protocol's units -- v2 the joints in
    0.001 deg (:class:`vr_driver.protocol.v2.TargetSlot`), v3 the pose in 0.1 mm / 0.01 deg
    (:class:`vr_driver.protocol.v3.CartesianSlot`). Validated here, once, by the subclass's
    :class:`SlotFormat` (``FORMAT``); a subclass adds no field and no check, only its protocol's
    conversions. ProtocolError names the field that is wrong."""

    seq: int = 0
    kind: Any = 0
    smooth: int = 0
    speed: int = 0
    values: Tuple[int, ...] = (0, 0, 0, 0, 0, 0)

    FORMAT: ClassVar[SlotFormat]

    def __post_init__(self) -> None:
        fmt = self.FORMAT
        if not _whole(self.seq, 0, SEQ_MAX):
            raise ProtocolError("slot seq must be an integer 0..%d, got %r" % (SEQ_MAX, self.seq))
        try:
            kind = fmt.kinds(self.kind)
        except (ValueError, TypeError):
            raise ProtocolError("slot kind %r is unknown (%s)" % (self.kind, fmt.kind_names())) from None
        object.__setattr__(self, "kind", kind)
        try:
            values = tuple(self.values)
        except TypeError:
            values = ()
        if len(values) != len(fmt.labels):
            raise ProtocolError("slot values must be %d integers (%s), got %r"
                                % (len(fmt.labels), ", ".join(fmt.labels), self.values))
        lo, hi = fmt.value_range
        for value, label in zip(values, fmt.labels):
            if not _whole(value, lo, hi):
                raise ProtocolError("slot %s must be an integer %d..%d, got %r" % (label, lo, hi, value))
        object.__setattr__(self, "values", values)
        if self.seq == 0:
            if int(kind) or any(values) or self.speed or self.smooth:
                raise ProtocolError("an empty slot (seq 0) carries nothing")
            return
        if not int(kind):
            raise ProtocolError("slot %d has no kind" % self.seq)
        if not _whole(self.speed, 1, fmt.speed_max):
            raise ProtocolError("slot %d: speed must be 1..%d (0.1 %% of the joint speed limits), got %r"
                                % (self.seq, fmt.speed_max, self.speed))
        if not _whole(self.smooth, 0, fmt.smooth_max):
            raise ProtocolError("slot %d: smooth must be 0..%d, got %r" % (self.seq, fmt.smooth_max, self.smooth))

    @property
    def empty(self) -> bool:
        return self.seq == 0

    def describe(self) -> str:
        if self.empty:
            return "(empty)"
        return "#%d %s speed %.1f %% smooth %d %s" % (self.seq, self.kind.name, self.speed / 10.0, self.smooth,
                                                      self.FORMAT.describe_values(self.values))

