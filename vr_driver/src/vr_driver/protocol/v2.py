"""Controller protocol v2: joint targets with sequence numbers and a look-ahead slot, joint feedback.
ROS-free, no I/O, no kinematics. The byte layouts, units and the controller program's rules are in
``doc/controller_program.md`` ("Protocol v2"); v1 (the thesis' 14 bytes, :mod:`vr_driver.protocol.v1`)
stays the default for an unchanged robot program. One parameter chooses the version on both ends;
the frames differ in length (72 bytes each way), so a v1 card configuration refuses a v2 master at
Chk_Cfg (Cfg_Fault) before a single record is exchanged.

Records (little-endian; one PROFIBUS-DP data telegram each way)::

    master -> controller  CommandV2   version | control | reserved | slot 0 | slot 1 | reserved | CRC
    controller -> master  FeedbackV2  version | state | status | reject code | accepted / done /
                                      active / rejected seq | joints | pose | heartbeat | CRC

A slot (:class:`TargetSlot`) carries one joint target: its sequence number (1..65535, 0 = empty),
the move kind, the smooth (blending) level, the speed (0.1 % of the joint speed limits) and the six
joint angles in 0.001 degree (int32: J6's +-360 deg and every other range fit with room to spare).
Slot 0 is the next target the controller has not taken yet; slot 1 the one after it (look-ahead),
so that the controller can blend into it. The controller takes a target exactly once: only the
sequence number that follows the last one it took (or, with the START bit, the first of a new
stream), and it reports the newest one taken (``accepted_seq``), the one it moves to
(``active_seq``) and the newest one passed or reached (``done_seq``).

Every record ends in a CRC-16 (CCITT, polynomial 0x1021, initial value 0xFFFF) over the bytes
before it: a record corrupted on the line in a way the 8-bit PROFIBUS checksum misses, or torn
between the card's modules, is refused (ProtocolError) instead of being acted on.
"""
from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Any, Sequence, Tuple

from ..errors import ProtocolError
from ..poses import ControllerPose
from .base import Protocol, WireTarget, framed_record
from .common import (BLEND_MAX, BLEND_PER_LEVEL, INT32_MAX, INT32_MIN, JOINT_UNIT_DEG, SEQ_MAX, SMOOTH_MAX, Control,
                     RejectCode, Slot, SlotFormat, StatusBits, StreamFeedback, StreamState, blend_window,
                     describe_stream_feedback, joints_from_wire, joints_to_wire, next_seq, seq_after, seq_offset)
from .v1 import move_targets

__all__ = [
    "V2", "ProtocolV2", "VERSION", "RECORD_SIZE_V2", "POSITION_UNIT_MM", "SPEED_UNIT", "TargetKind", "crc16",
    "JOINT_SLOT", "TargetSlot", "EMPTY", "CommandV2", "FeedbackV2", "GSD_MODULES_V2", "CHK_CFG_V2",
    # the shared vocabulary (vr_driver.protocol.common), importable from here as before it moved
    "SEQ_MAX", "JOINT_UNIT_DEG", "SMOOTH_MAX", "BLEND_PER_LEVEL", "BLEND_MAX", "blend_window", "Control",
    "StreamState", "RejectCode", "next_seq", "seq_offset", "describe_stream_feedback", "seq_after",
    "joints_to_wire", "joints_from_wire",
]

VERSION = 2
#: bytes per record, each direction
RECORD_SIZE_V2 = 72
#: Cartesian feedback: X, Y, Z in 0.01 mm; Rx, Ry, Rz in 0.001 deg
POSITION_UNIT_MM = 0.01
#: speed on the wire: 0.1 % of the joint speed limits (1..1000)
SPEED_UNIT = 0.001
#: Chk_Cfg modules of a v2 card configuration, inputs first like v1: 32 + 32 + 8 bytes each way
#: (general identifier format: 0x5F = 16 words in, 0x17 = 8 bytes in, 0x6F / 0x27 the outputs)
GSD_MODULES_V2 = ("32 Bytes In", "32 Bytes In", "8 Bytes In", "32 Bytes Out", "32 Bytes Out",
                  "8 Bytes Out")
#: the Chk_Cfg bytes of those modules
CHK_CFG_V2 = bytes([0x5F, 0x5F, 0x17, 0x6F, 0x6F, 0x27])

_INT32 = (INT32_MIN, INT32_MAX)
_HEADER = struct.Struct("<BBH")                  # version, control, reserved
_SLOT = struct.Struct("<HBBHH6i")                # seq, kind, smooth, speed, reserved, joints
_COMMAND = struct.Struct("<BBH32s32sHH")         # header, slot 0, slot 1, outputs, CRC
_FEEDBACK = struct.Struct("<BBBBHHHH6i6iHHHB3sH")  # see FeedbackV2
assert _SLOT.size == 32 and _COMMAND.size == RECORD_SIZE_V2 and _FEEDBACK.size == RECORD_SIZE_V2


class TargetKind(enum.IntEnum):
    NONE = 0
    JOINT = 1      # MOVEP to the six joint angles (joint-interpolated)


# ---------------------------------------------------------------------------------------- helpers

def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: polynomial 0x1021, initial 0xFFFF, no reflection, no final XOR
    (check value of b"123456789": 0x29B1)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def _check_crc(raw: bytes, what: str) -> None:
    want = struct.unpack_from("<H", raw, RECORD_SIZE_V2 - 2)[0]
    got = crc16(raw[:RECORD_SIZE_V2 - 2])
    if want != got:
        raise ProtocolError("%s record: CRC 0x%04X does not match its bytes (0x%04X): corrupted "
                            "or torn; ignored" % (what, want, got))


def _as_record(data: Any, what: str) -> bytes:
    raw = framed_record(data, RECORD_SIZE_V2, VERSION, what)
    _check_crc(raw, what)
    return raw


def _seq(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= SEQ_MAX:
        raise ProtocolError("%s must be an integer 0..%d, got %r" % (name, SEQ_MAX, value))
    return value


# ------------------------------------------------------------------------------------------ records

def _describe_joints(values: Tuple[int, ...]) -> str:
    return "joints %s deg" % " ".join("%.3f" % (v * JOINT_UNIT_DEG) for v in values)


#: v2's part of a target slot (:class:`~vr_driver.protocol.common.Slot`): joint targets, six int32
#: in 0.001 deg
JOINT_SLOT = SlotFormat(kinds=TargetKind, labels=tuple("joint_%d [0.001 deg]" % (i + 1) for i in range(6)),
                        value_range=_INT32, describe_values=_describe_joints)


class TargetSlot(Slot):
    """One joint target of a v2 command (or an empty slot: seq 0): the shared slot
    (:class:`~vr_driver.protocol.common.Slot`, validated there) whose six values are the joints in
    0.001 deg (``joints``)."""

    FORMAT = JOINT_SLOT

    @classmethod
    def joint_target(cls, seq: int, joints_rad: Sequence[float], speed_fraction: float,
                     smooth: int = 0) -> "TargetSlot":
        """A joint target from radians and a speed as a fraction (0, 1] of the joint speed limits
        (rounded up to the next 0.1 %: the arm is never asked to be slower than planned)."""
        if not (isinstance(speed_fraction, (int, float)) and math.isfinite(speed_fraction)
                and 0.0 < speed_fraction <= 1.0):
            raise ProtocolError("speed fraction must be in (0, 1], got %r" % (speed_fraction,))
        speed = min(1000, max(1, int(math.ceil(speed_fraction / SPEED_UNIT - 1e-9))))
        return cls(seq, TargetKind.JOINT, smooth, speed, joints_to_wire(joints_rad))

    @property
    def joints(self) -> Tuple[int, ...]:
        """The joint target in 0.001 deg (the slot's values)."""
        return self.values

    @property
    def joints_rad(self) -> Tuple[float, ...]:
        return joints_from_wire(self.values)

    def pack(self) -> bytes:
        return _SLOT.pack(self.seq, int(self.kind), self.smooth, self.speed, 0, *self.values)

    @classmethod
    def unpack(cls, raw: bytes) -> "TargetSlot":
        seq, kind, smooth, speed, _reserved, *joints = _SLOT.unpack(raw)
        return cls(seq, kind, smooth, speed, tuple(joints))


EMPTY = TargetSlot()


def _word(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
        raise ProtocolError("%s must be an integer 0..65535 (16 bits), got %r" % (name, value))
    return value


@dataclass(frozen=True)
class CommandV2:
    """Master -> controller: control bits, two target slots (next, look-ahead) and the controller's
    general-purpose outputs 1..16 (bit k = output k + 1; the controller's own I/O, §9.5)."""

    control: Control = Control(0)
    slot0: TargetSlot = EMPTY
    slot1: TargetSlot = EMPTY
    outputs: int = 0

    def __post_init__(self) -> None:
        _word(self.outputs, "outputs")
        try:
            object.__setattr__(self, "control", Control(int(self.control)))
        except ValueError:
            raise ProtocolError("control bits %r: only STOP (1) and START (2) are defined"
                                % (self.control,)) from None
        if int(self.control) & ~0x03:
            raise ProtocolError("control bits 0x%02X: only STOP (1) and START (2) are defined"
                                % int(self.control))
        if self.slot0.empty and not self.slot1.empty:
            raise ProtocolError("slot 1 (look-ahead) without slot 0")
        if not self.slot1.empty and self.slot1.seq != next_seq(self.slot0.seq):
            raise ProtocolError("slot 1 must carry the sequence number after slot 0's (%d), got %d"
                                % (next_seq(self.slot0.seq), self.slot1.seq))
        if Control.START in self.control and self.slot0.empty:
            raise ProtocolError("START needs a target in slot 0")
        if Control.STOP in self.control and not self.slot0.empty:
            raise ProtocolError("STOP carries no target")

    def encode(self) -> bytes:
        body = _COMMAND.pack(VERSION, int(self.control), 0, self.slot0.pack(), self.slot1.pack(),
                             self.outputs, 0)
        return body[:-2] + struct.pack("<H", crc16(body[:-2]))

    @classmethod
    def decode(cls, data: Any) -> "CommandV2":
        raw = _as_record(data, "v2 command")
        _version, control, reserved, s0, s1, outputs, _crc = _COMMAND.unpack(raw)
        if reserved:
            raise ProtocolError("v2 command: reserved bytes must be 0")
        return cls(control, TargetSlot.unpack(s0), TargetSlot.unpack(s1), outputs)


@dataclass(frozen=True)
class FeedbackV2(StreamFeedback):
    """Controller -> master: the stream's progress, the joints and the pose."""

    joints: Tuple[int, ...] = (0, 0, 0, 0, 0, 0)   # 0.001 deg
    tcp: Tuple[int, ...] = (0, 0, 0, 0, 0, 0)      # X Y Z 0.01 mm, Rx Ry Rz 0.001 deg
    heartbeat: int = 0                              # +1 every program loop (mod 65536)
    inputs: int = 0                                 # general-purpose inputs 1..16 (bit k = k + 1)
    outputs: int = 0                                # general-purpose outputs 1..16 as set
    armed: bool = False                             # the program takes targets (byte 67 bit 0):
    #                                                 set once an empty record of this session came

    def __post_init__(self) -> None:
        self._check_codes("v2 feedback")
        status = int(self.status)
        if status & ~0x3F or status < 0:
            raise ProtocolError("v2 feedback: reserved status bits set (0x%02X)" % status)
        object.__setattr__(self, "status", StatusBits(status))
        for name in ("accepted_seq", "done_seq", "active_seq", "rejected_seq", "heartbeat"):
            _seq(getattr(self, name), name)
        _word(self.inputs, "inputs")
        _word(self.outputs, "outputs")
        if not isinstance(self.armed, bool):
            raise ProtocolError("v2 feedback: armed must be a bool, got %r" % (self.armed,))
        for name in ("joints", "tcp"):
            values = tuple(getattr(self, name))
            if len(values) != 6 or not all(isinstance(v, int) and _INT32[0] <= v <= _INT32[1]
                                           for v in values):
                raise ProtocolError("v2 feedback: %s must be 6 int32 values" % name)
            object.__setattr__(self, name, values)

    @property
    def joints_rad(self) -> Tuple[float, ...]:
        return joints_from_wire(self.joints)

    @property
    def values(self) -> Tuple[int, ...]:
        """The TCP pose as on the wire (X Y Z 0.01 mm, Rx Ry Rz 0.001 deg); as v1's ``values``, a
        tuple that changes exactly when the reported pose changes."""
        return self.tcp

    @property
    def pose(self) -> ControllerPose:
        """The reported TCP pose in controller units (mm, deg)."""
        x, y, z, rx, ry, rz = self.tcp
        return ControllerPose(x * POSITION_UNIT_MM, y * POSITION_UNIT_MM, z * POSITION_UNIT_MM,
                              rx * JOINT_UNIT_DEG, ry * JOINT_UNIT_DEG, rz * JOINT_UNIT_DEG)

    def encode(self) -> bytes:
        body = _FEEDBACK.pack(VERSION, int(self.state), int(self.status), int(self.reject_code),
                              self.accepted_seq, self.done_seq, self.active_seq, self.rejected_seq,
                              *self.joints, *self.tcp, self.heartbeat, self.inputs, self.outputs,
                              int(self.armed), bytes(3), 0)
        return body[:-2] + struct.pack("<H", crc16(body[:-2]))

    @classmethod
    def decode(cls, data: Any) -> "FeedbackV2":
        raw = _as_record(data, "v2 feedback")
        fields = _FEEDBACK.unpack(raw)
        (_version, state, status, reject, accepted, done, active, rejected) = fields[:8]
        joints, pose = fields[8:14], fields[14:20]
        heartbeat, inputs, outputs, flags, reserved = fields[20:25]
        if flags & ~0x01:
            raise ProtocolError("v2 feedback: reserved flag bits set (0x%02X)" % flags)
        if any(reserved):
            raise ProtocolError("v2 feedback: reserved bytes must be 0")
        return cls(state, status, reject, accepted, done, active, rejected, tuple(joints),
                   tuple(pose), heartbeat, inputs, outputs, bool(flags & 0x01))

    def describe(self) -> str:
        return describe_stream_feedback(self)


# ---------------------------------------------------------------------------------- the seam

class ProtocolV2(Protocol):
    """Protocol v2 as one object (:mod:`vr_driver.protocol.base`): streamed joint targets."""

    name = "v2"
    move_commands = move_targets             # a move: planned to the handshake's targets (whole mm / deg)
    version = VERSION
    record_length = RECORD_SIZE_V2
    gsd_modules = GSD_MODULES_V2
    chk_cfg = CHK_CFG_V2
    streams = True
    joint_targets = True
    reports_joints = True
    controller_io = True
    confirm_records = False         # the CRC-16 does the two-telegram rule's job (section 9.3)
    pose_resolution = (POSITION_UNIT_MM, JOINT_UNIT_DEG)
    joint_resolution = JOINT_UNIT_DEG
    target_error = math.radians(JOINT_UNIT_DEG / 2.0)
    summary = "streamed joint targets in 0.001 deg with a look-ahead slot and a CRC-16 (needs a controller that takes joint targets)"

    def encode(self, command: CommandV2, byte_order: Any = "little") -> bytes:
        return command.encode()

    def idle_command(self) -> CommandV2:
        return CommandV2()

    def idle_record(self, byte_order: Any = "little") -> bytes:
        return CommandV2().encode()

    def decode_feedback(self, data: Any, byte_order: Any = "little") -> FeedbackV2:
        return FeedbackV2.decode(data)

    def feedback_joints(self, feedback: FeedbackV2) -> Tuple[float, ...]:
        return feedback.joints_rad

    def feedback_heartbeat(self, feedback: Any) -> int:
        return feedback.heartbeat

    look_ahead_slots = 2
    send_ahead = 2                  # its two slots
    send_changes_at_once = True

    def stream_command(self, targets: Sequence[WireTarget], start: bool = False, stop: bool = False,
                       outputs: int = 0) -> CommandV2:
        if stop:
            return CommandV2(Control.STOP, outputs=outputs)
        slots = [TargetSlot(t.seq, TargetKind.JOINT, t.smooth, t.speed, joints_to_wire(t.joints))
                 for t in list(targets)[:self.look_ahead_slots]]
        slots += [EMPTY] * (2 - len(slots))
        return CommandV2(Control.START if start and not slots[0].empty else Control(0), slots[0], slots[1],
                         outputs)

    def decode_command(self, data: Any, byte_order: Any = "little") -> CommandV2:
        return CommandV2.decode(data)


V2 = ProtocolV2()
