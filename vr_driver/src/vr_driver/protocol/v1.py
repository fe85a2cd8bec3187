"""The 14-byte controller protocol of doc/controller_program.md and its request handshake. ROS-free, no I/O.

Records (one PROFIBUS-DP data telegram each way, six signed 16-bit words then two single bytes)::

    master -> controller  Command   X Y Z Rx Ry Rz (int16, mm / deg) | flag (0/1) | move type
    controller -> master  Feedback  X Y Z Rx Ry Rz (int16, mm / deg) | state      | status bits

Byte numbers in messages are 1-based as in the thesis' Table 5.1 (byte 13 = flag, byte 14 = type).
The words are little-endian by default; ``byte_order="big"`` swaps the two bytes of every word
(bytes 13 and 14 are single bytes and never swapped).

Resolution: the G2 exchanges integers only, so a target is rounded to 1 mm / 1 deg before sending:
round half away from zero (0.5 -> 1, -0.5 -> -1, 2.5 -> 3), the same on both sides of zero, unlike
Python's ``round`` (half to even). The rounded value is what is range- and workspace-checked.

Feedback status byte: bits 0-5 are defined (:class:`~vr_driver.protocol.common.StatusBits`, every
protocol's); bits 6-7 are reserved and a feedback record with either set is refused with
ProtocolError. Our controller program never sets them, so a set bit means the output mapping on
the controller is wrong (shifted bytes, swapped words) and nothing else in that record can be
trusted either.

Handshake (doc/controller_program.md): the controller starts a motion only when its state is READY and the flag
is 1, reports BUSY, then DONE or REJECTED, holds that until the flag is 0, then returns to READY.
:class:`ControllerHandshake` is the robot-side logic (what ``doc/controller_program.md`` asks the
real program to do, and what the virtual controller runs); :class:`MasterHandshake` is the driver
side, with an injected clock, guaranteeing that every target is requested exactly once.
"""
from __future__ import annotations

import enum
import math
import struct
import time
from dataclasses import dataclass, replace
from typing import Any, Callable, ClassVar, List, Optional, Tuple, Union

from .. import validate
from ..errors import HandshakeError, HandshakeTimeout, PoseError, ProtocolError, TargetRejected
from ..poses import CONTROLLER_FIELDS, ControllerPose, MoveType, Workspace, finite_number
from .base import Protocol
from .common import (INT16_MAX, INT16_MIN, STATUS_RESERVED_MASK, ByteOrder, FeedbackRecord, StatusBits,
                     parse_byte_order, round_half_away)

__all__ = [
    "V1",
    "ProtocolV1",
    "RECORD_SIZE",
    "FLAG_NONE",
    "FLAG_REQUEST",
    "FLAG_STOP",
    "WireMoveType",
    "ControllerState",
    "to_wire_int",
    "Command",
    "Feedback",
    "commands_for",
    "ControllerHandshake",
    "MasterPhase",
    "HandshakeEvent",
    "Accepted",
    "Done",
    "Rejected",
    "TimedOut",
    "Aborted",
    "MasterHandshake",
    "DEFAULT_ACCEPT_TIMEOUT",
    "DEFAULT_RELEASE_TIMEOUT",
    "DEFAULT_SETTLE_TIME",
    # the shared vocabulary (vr_driver.protocol.common), importable from here as before it moved
    "INT16_MIN", "INT16_MAX", "STATUS_RESERVED_MASK", "StatusBits", "ByteOrder", "parse_byte_order",
    "round_half_away",
]

#: byte 13 of a command: no request / execute this target / stop the motion in progress
FLAG_NONE = 0
FLAG_REQUEST = 1
FLAG_STOP = 2

#: bytes per record, each direction
RECORD_SIZE = 14

#: default time for the controller to answer a raised flag (BUSY, DONE or REJECTED) [s]
DEFAULT_ACCEPT_TIMEOUT = 1.0
#: default time for the controller to return to READY after the flag was cleared [s]
DEFAULT_RELEASE_TIMEOUT = 1.0
#: default time READY must be seen with the flag cleared, when a raised flag may still be picked
#: up late (after start / reset, or a target given up before BUSY was seen) [s]
DEFAULT_SETTLE_TIME = DEFAULT_ACCEPT_TIMEOUT

_LABELS = ("X", "Y", "Z", "Rx", "Ry", "Rz")
_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")


# ------------------------------------------------------------------------------------------ enums

#: [m/min] the documented v1 program's move speeds (doc/controller_program.md section 5, ROSLINK):
#: MOVEP 10 m/min, MOVEL and MOVEC 5 m/min -- constants of the program, the protocol carries no
#: speed; the driver's ``controller/program_speed`` / ``program_path_speed`` and the virtual G2's
#: options of the same names say what the G2's program really uses (section 10.9)
PROGRAM_SPEED = 10.0
PROGRAM_PATH_SPEED = 5.0


def program_speed(move_type: Any, movep: float = PROGRAM_SPEED, movel: float = PROGRAM_PATH_SPEED) -> float:
    """[mm/s] the TCP speed the v1 program moves ``move_type`` at: ``movep`` [m/min] for a PTP (its
    MOVEP), ``movel`` [m/min] for a LIN or a CIRC (MOVEL, MOVEC)."""
    return (movep if MoveType.parse(move_type) is MoveType.PTP else movel) * 1000.0 / 60.0


class WireMoveType(enum.IntEnum):
    """Byte 14 of a command: the G2 motion instruction to run."""

    NONE = 0       # no motion (only valid with the flag at 0)
    PTP = 1        # MOVEP: joint-interpolated
    LIN = 2        # MOVEL: straight line
    CIRC_END = 3   # MOVEC end point (needs a stored via point)
    CIRC_VIA = 4   # circular via point: stored, acknowledged DONE without motion

    @classmethod
    def parse(cls, value: Any) -> "WireMoveType":
        """From a WireMoveType, its number (0-4), its name ("ptp", "circ_via", ...) or a
        ``poses.MoveType`` PTP/LIN (CIRC is ambiguous: use :meth:`from_move_type`)."""
        if isinstance(value, WireMoveType):
            return value
        if isinstance(value, MoveType):
            return cls.from_move_type(value, via=None)
        if isinstance(value, str):
            try:
                return cls[value.strip().upper()]
            except KeyError:
                pass
        elif isinstance(value, int) and not isinstance(value, bool):
            try:
                return cls(value)
            except ValueError:
                pass
        raise ProtocolError("unknown move type %r (0 none, 1 PTP, 2 LIN, 3 CIRC end, 4 CIRC via)"
                            % (value,))

    @classmethod
    def from_move_type(cls, move_type: Any, via: Optional[bool] = False) -> "WireMoveType":
        """The wire type of a ``poses.MoveType``: PTP -> PTP, LIN -> LIN, CIRC -> CIRC_END, or
        CIRC_VIA with ``via=True``. ``via=None`` refuses CIRC (the caller did not say which)."""
        kind = MoveType.parse(move_type) if not isinstance(move_type, MoveType) else move_type
        if kind is MoveType.PTP:
            return cls.PTP
        if kind is MoveType.LIN:
            return cls.LIN
        if via is None:
            raise ProtocolError("a CIRC move is two wire commands (CIRC_VIA, then CIRC_END): "
                                "say which one, or use commands_for()")
        return cls.CIRC_VIA if via else cls.CIRC_END

    def to_move_type(self) -> MoveType:
        """PTP -> PTP, LIN -> LIN, CIRC_END / CIRC_VIA -> CIRC; NONE has none (ProtocolError)."""
        if self is WireMoveType.NONE:
            raise ProtocolError("move type NONE is not a motion")
        return {WireMoveType.PTP: MoveType.PTP, WireMoveType.LIN: MoveType.LIN}.get(self, MoveType.CIRC)

    @property
    def instruction(self) -> Optional[str]:
        """The G2 instruction this type runs: MOVEP, MOVEL, MOVEC (end point), or None."""
        return {WireMoveType.PTP: "MOVEP", WireMoveType.LIN: "MOVEL",
                WireMoveType.CIRC_END: "MOVEC"}.get(self)


class ControllerState(enum.IntEnum):
    """Byte 13 of the feedback: where the controller is in the request handshake."""

    READY = 0      # waiting for a flag 1
    BUSY = 1       # request accepted, moving
    DONE = 2       # target reached (or via point stored); held until the flag is 0
    REJECTED = 3   # target refused or motion failed; held until the flag is 0


_STRUCTS = {order: struct.Struct(order.struct_prefix + "6hBB") for order in ByteOrder}


# ------------------------------------------------------------------------------------ conversions

def to_wire_int(value: Any, name: str) -> int:
    """A pose value rounded to the controller's integer resolution (:func:`round_half_away`),
    PoseError naming ``name`` when it is not finite or falls outside int16."""
    number = finite_number(value, name)
    wire = round_half_away(number)
    if not INT16_MIN <= wire <= INT16_MAX:
        raise PoseError("%s = %g is outside the wire format's int16 range [%d, %d]"
                        % (name, number, INT16_MIN, INT16_MAX))
    return wire


def _check_word(value: Any, name: str) -> int:
    """An int16 field of a record: a true integer in range, ProtocolError otherwise. (Per record on
    the bus cycle: the range check is inline rather than through validate.integer's ``fail``.)"""
    number = validate.as_integer(value)
    if number is None:
        raise ProtocolError("%s must be an integer (the wire carries whole mm / deg), got %r" % (name, value))
    if not INT16_MIN <= number <= INT16_MAX:
        raise ProtocolError("%s = %d is outside the int16 range [%d, %d]" % (name, number, INT16_MIN, INT16_MAX))
    return number


def _as_bytes(data: Any, what: str) -> bytes:
    if isinstance(data, (bytes, bytearray, memoryview)):
        raw = bytes(data)
    else:
        try:
            raw = bytes(data)
        except (TypeError, ValueError) as exc:
            raise ProtocolError("%s record must be bytes, got %r" % (what, data)) from exc
    if len(raw) != RECORD_SIZE:
        raise ProtocolError("%s record must be %d bytes, got %d" % (what, RECORD_SIZE, len(raw)))
    return raw


def _fmt_values(values: Tuple[int, ...]) -> str:
    return "(%d, %d, %d mm, %d, %d, %d deg)" % values


# --------------------------------------------------------------------------------------- records

def _unpack(data: Any, byte_order: Any, what: str) -> Tuple[int, ...]:
    """A record's eight fields: the six pose words, bytes 13 and 14 (``what``: "command" /
    "feedback", for the length error)."""
    return _STRUCTS[ByteOrder.parse(byte_order)].unpack(_as_bytes(data, what))


@dataclass(frozen=True)
class _PoseWords:
    """The first six int16 words of either record: a pose in whole mm / deg (a Command's target, a
    Feedback's position), ``values`` as a tuple and ``pose`` as a ControllerPose."""

    x: int
    y: int
    z: int
    rx: int
    ry: int
    rz: int

    def _check_words(self, record: str) -> None:
        """Each word an int16 (ProtocolError naming ``record`` and the field otherwise)."""
        for name, label in zip(CONTROLLER_FIELDS, _LABELS):
            object.__setattr__(self, name, _check_word(getattr(self, name), "%s %s" % (record, label)))

    @property
    def values(self) -> Tuple[int, int, int, int, int, int]:
        return (self.x, self.y, self.z, self.rx, self.ry, self.rz)

    @property
    def pose(self) -> ControllerPose:
        return ControllerPose(*self.values)


@dataclass(frozen=True)
class Command(_PoseWords):
    """Master -> controller record: the target (whole mm / deg), the request flag, the move type."""

    request: bool
    move_type: WireMoveType
    stop: bool = False

    def __post_init__(self) -> None:
        self._check_words("command")
        if not isinstance(self.stop, bool):
            raise ProtocolError("command stop must be True/False, got %r" % (self.stop,))
        request = self.request
        if isinstance(request, bool):
            flag = request
        elif validate.as_integer(request) in (0, 1):
            flag = bool(int(request))
        else:
            raise ProtocolError("command request flag must be True/False (1/0), got %r" % (request,))
        object.__setattr__(self, "request", flag)
        if flag and self.stop:
            raise ProtocolError("a command cannot request a motion and a stop at once")
        kind = WireMoveType.parse(self.move_type)
        if kind is WireMoveType.NONE and flag:
            raise ProtocolError("a command with the request flag set needs a move type (1-4), got 0 (none)")
        object.__setattr__(self, "move_type", kind)

    # ------------------------------------------------------------------ construction
    @classmethod
    def idle(cls) -> "Command":
        """All zero: no request, no move type (what the master sends when it has nothing to do)."""
        return cls(0, 0, 0, 0, 0, 0, False, WireMoveType.NONE)

    @classmethod
    def from_pose(cls, pose: Any, move_type: Any, workspace: Optional[Workspace] = None,
                  request: bool = True) -> "Command":
        """A target command from a controller pose (ControllerPose or 6 numbers, mm / deg).

        Every value is rounded to whole mm / deg, halves away from zero (:func:`round_half_away`);
        the rounded values must fit int16 and, when ``workspace`` is given, lie in its box (the box
        is checked on what is actually sent). Angles are not wrapped. PoseError names the field and
        the limit; NaN / inf are refused. ``move_type``: anything :meth:`WireMoveType.parse` takes
        except NONE.
        """
        kind = WireMoveType.parse(move_type)
        if kind is WireMoveType.NONE:
            raise ProtocolError("a target needs a move type (PTP, LIN, CIRC_END, CIRC_VIA), not NONE")
        if isinstance(pose, ControllerPose):
            values = pose.as_tuple()
        else:
            try:
                values = tuple(pose)
            except TypeError as exc:
                raise PoseError("a controller pose is 6 numbers (X, Y, Z, Rx, Ry, Rz), got %r" % (pose,)) from exc
            if len(values) != 6:
                raise PoseError("a controller pose must have 6 values (X, Y, Z, Rx, Ry, Rz), got %d"
                                % len(values))
        ints = tuple(to_wire_int(v, "%s [%s]" % (label, unit))
                     for v, label, unit in zip(values, _LABELS, _UNITS))
        if workspace is not None:
            try:
                workspace.check(ControllerPose(*ints))
            except PoseError as exc:
                raise PoseError("%s target %s (rounded to 1 mm / 1 deg): %s"
                                % (kind.name, _fmt_values(ints), exc)) from exc
        return cls(*ints, request=request, move_type=kind)

    # ------------------------------------------------------------------ wire
    def encode(self, byte_order: Any = ByteOrder.LITTLE) -> bytes:
        order = ByteOrder.parse(byte_order)
        flag = FLAG_STOP if self.stop else (FLAG_REQUEST if self.request else FLAG_NONE)
        return _STRUCTS[order].pack(self.x, self.y, self.z, self.rx, self.ry, self.rz,
                                    flag, int(self.move_type))

    @classmethod
    def decode(cls, data: Any, byte_order: Any = ByteOrder.LITTLE) -> "Command":
        """From 14 bytes; ProtocolError on a wrong length, a flag byte not 0/1/2, an unknown move
        type, or move type NONE with the flag 1."""
        x, y, z, rx, ry, rz, flag, kind = _unpack(data, byte_order, "command")
        if flag not in (FLAG_NONE, FLAG_REQUEST, FLAG_STOP):
            raise ProtocolError("command byte 13 (request flag) must be 0, 1 or 2 (stop), got 0x%02X"
                                % flag)
        try:
            move_type = WireMoveType(kind)
        except ValueError:
            raise ProtocolError("command byte 14 (move type) = %d is unknown (0 none, 1 PTP, 2 LIN, "
                                "3 CIRC end, 4 CIRC via)" % kind) from None
        if move_type is WireMoveType.NONE and flag == FLAG_REQUEST:
            raise ProtocolError("command byte 14 (move type) is 0 (none) but byte 13 requests a motion")
        return cls(x, y, z, rx, ry, rz, flag == FLAG_REQUEST, move_type, stop=flag == FLAG_STOP)

    # ------------------------------------------------------------------ views
    def with_request(self, request: bool) -> "Command":
        return replace(self, request=request, stop=False)

    def with_stop(self) -> "Command":
        """The same bytes with flag 2: stop the motion in progress (and release the answer)."""
        return replace(self, request=False, stop=True)

    def describe(self) -> str:
        flag = FLAG_STOP if self.stop else int(self.request)
        return "%s %s flag %d" % (self.move_type.name, _fmt_values(self.values), flag)


@dataclass(frozen=True)
class Feedback(_PoseWords, FeedbackRecord):
    """Controller -> master record: the current pose (whole mm / deg), the state, the status bits."""

    state: ControllerState
    status: StatusBits = StatusBits(0)

    def __post_init__(self) -> None:
        self._check_words("feedback")
        state = self.state
        if validate.as_integer(state) is None:
            raise ProtocolError("feedback state must be a ControllerState (0-3), got %r" % (state,))
        try:
            state = ControllerState(int(state))
        except ValueError:
            raise ProtocolError("feedback state %d is unknown (0 ready, 1 busy, 2 done, 3 rejected)"
                                % int(state)) from None
        object.__setattr__(self, "state", state)
        status = self.status
        byte = validate.as_integer(status)
        if byte is None or not 0 <= byte <= 0xFF:
            raise ProtocolError("feedback status must be a byte of StatusBits, got %r" % (status,))
        if int(status) & STATUS_RESERVED_MASK:
            raise ProtocolError("feedback status 0x%02X has reserved bit(s) 6-7 set (0x%02X): the "
                                "controller's output mapping is wrong" % (int(status), int(status) & 0xC0))
        object.__setattr__(self, "status", StatusBits(int(status)))

    @classmethod
    def from_pose(cls, pose: Any, state: Any, status: Any = StatusBits(0)) -> "Feedback":
        """A feedback record from a (float) controller pose, rounded like :meth:`Command.from_pose`
        (the controller side of the virtual controller)."""
        values = pose.as_tuple() if isinstance(pose, ControllerPose) else tuple(pose)
        if len(values) != 6:
            raise PoseError("a controller pose must have 6 values (X, Y, Z, Rx, Ry, Rz), got %d" % len(values))
        ints = tuple(to_wire_int(v, "%s [%s]" % (label, unit))
                     for v, label, unit in zip(values, _LABELS, _UNITS))
        return cls(*ints, state=state, status=status)

    def encode(self, byte_order: Any = ByteOrder.LITTLE) -> bytes:
        order = ByteOrder.parse(byte_order)
        return _STRUCTS[order].pack(self.x, self.y, self.z, self.rx, self.ry, self.rz,
                                    int(self.state), int(self.status))

    @classmethod
    def decode(cls, data: Any, byte_order: Any = ByteOrder.LITTLE) -> "Feedback":
        """From 14 bytes; ProtocolError on a wrong length, an unknown state (byte 13 > 3) or a
        reserved status bit (byte 14, bits 6-7)."""
        x, y, z, rx, ry, rz, state, status = _unpack(data, byte_order, "feedback")
        if state > max(ControllerState):
            raise ProtocolError("feedback byte 13 (state) = %d is unknown (0 ready, 1 busy, 2 done, "
                                "3 rejected)" % state)
        if status & STATUS_RESERVED_MASK:
            raise ProtocolError("feedback byte 14 (status) = 0x%02X has reserved bit(s) 6-7 set: the "
                                "controller's output mapping is wrong" % status)
        return cls(x, y, z, rx, ry, rz, ControllerState(state), StatusBits(status))

    def describe(self) -> str:
        return "%s at %s, status: %s" % (self.state.name, _fmt_values(self.values), self.status.describe())


def commands_for(move_type: Any, target: Any, via: Any = None,
                 workspace: Optional[Workspace] = None) -> List[Command]:
    """The wire commands of one move, in sending order, each with the flag set: PTP / LIN -> one
    command; CIRC -> [CIRC_VIA at ``via``, CIRC_END at ``target``]. ``move_type`` is a
    ``poses.MoveType`` (or "ptp" / "lin" / "circ"). A via for PTP / LIN, or none for CIRC, is a
    ProtocolError; poses are rounded and checked as in :meth:`Command.from_pose`."""
    if isinstance(move_type, WireMoveType):
        if move_type in (WireMoveType.NONE, WireMoveType.CIRC_VIA):
            raise ProtocolError("commands_for() takes PTP, LIN or CIRC, got %s" % move_type.name)
        kind = move_type.to_move_type()
    else:
        try:
            kind = MoveType.parse(move_type)
        except Exception as exc:  # MotionError: convert at the boundary
            raise ProtocolError(str(exc)) from exc
    if kind is MoveType.CIRC:
        if via is None:
            raise ProtocolError("a CIRC move needs a via pose")
        return [Command.from_pose(via, WireMoveType.CIRC_VIA, workspace),
                Command.from_pose(target, WireMoveType.CIRC_END, workspace)]
    if via is not None:
        raise ProtocolError("a via pose is only used by CIRC moves, not %s" % kind.name)
    return [Command.from_pose(target, WireMoveType.from_move_type(kind), workspace)]


def move_targets(wire: Protocol, move_type: Union[MoveType, WireMoveType, str], target: ControllerPose,
                 via: Optional[ControllerPose] = None, workspace: Optional[Workspace] = None) -> Tuple[Command, ...]:
    """``wire.move_commands`` of every built-in protocol (:meth:`Protocol.move_commands`): a
    move planned to the handshake's targets, :func:`commands_for` (whole mm / deg)."""
    return tuple(commands_for(move_type, target, via, workspace))


# ----------------------------------------------------------------------------- controller side

class ControllerHandshake:
    """The robot-side program's handshake logic, with no arm inside (doc/controller_program.md).

    Call :meth:`step` once per program loop with the latest decoded command (None when there is
    none, e.g. the bus watchdog expired: treated as flag 0) and whether the arm stands still and
    could move (drives on, no e-stop, no error). It returns the command whose motion must start now
    (at most once per request), else None; the via point of a CIRC_END is :attr:`active_via`. When
    that motion ends call :meth:`finish`. Write :attr:`state` and :meth:`status_bits` (with the
    arm's own bits) to the outputs every loop; :meth:`feedback` builds the record.

        READY --flag 1, CIRC_VIA--------------------------------> DONE (via stored, no motion)
        READY --flag 1, CIRC_END without via / arm not ready----> REJECTED
        READY --flag 1, PTP / LIN / CIRC_END with via-----------> BUSY (step() returns the command)
        BUSY  --finish(True)--> DONE      BUSY --finish(False)--> REJECTED
        BUSY  --flag 2 (stop)--> stop_requested: the program halts the arm, then finish(False)
        DONE / REJECTED --flag 0 or 2--> READY

    A stored via is used by the next request only: a CIRC_END consumes it, any other request (and a
    new CIRC_VIA replaces it) discards it. A request in READY with the arm not ready is REJECTED.
    """

    def __init__(self) -> None:
        self._state = ControllerState.READY
        self._via: Optional[Command] = None
        self._active: Optional[Command] = None
        self._active_via: Optional[Command] = None
        self._reason = ""
        self._stop_seen = False
        self.accepted = 0      # motions started
        self.completed = 0     # DONE answers (motions and via points)
        self.rejected = 0      # REJECTED answers

    # ----------------------------------------------------------------------- views
    @property
    def state(self) -> ControllerState:
        return self._state

    @property
    def via_stored(self) -> bool:
        return self._via is not None

    @property
    def stored_via(self) -> Optional[Command]:
        return self._via

    @property
    def active(self) -> Optional[Command]:
        """The command being executed (BUSY) or last answered (DONE / REJECTED), else None."""
        return self._active

    @property
    def active_via(self) -> Optional[Command]:
        """The via point of the CIRC_END being executed, else None."""
        return self._active_via

    @property
    def reason(self) -> str:
        """Why the last request was REJECTED ("" otherwise)."""
        return self._reason

    @property
    def stop_requested(self) -> bool:
        """True while BUSY and the master's flag is 2: halt the arm now, then finish(False)."""
        return self._stop_seen and self._state is ControllerState.BUSY

    def status_bits(self) -> StatusBits:
        """The handshake's own status bits (VIA_STORED); OR them with the arm's."""
        return StatusBits.VIA_STORED if self._via is not None else StatusBits(0)

    def feedback(self, pose: Any, arm_status: Any = StatusBits(0)) -> Feedback:
        """The output record: ``pose`` (rounded), the state, the arm's bits plus VIA_STORED."""
        status = (int(arm_status) & ~int(StatusBits.VIA_STORED)) | int(self.status_bits())
        return Feedback.from_pose(pose, self._state, status)

    # ------------------------------------------------------------------- program loop
    def step(self, command: Optional[Command], arm_idle: bool = True) -> Optional[Command]:
        """One program loop. Returns the command to start a motion for, else None."""
        flag = command is not None and command.request
        self._stop_seen = command is not None and command.stop
        if self._state is ControllerState.READY:
            if not flag:
                return None
            assert command is not None
            return self._request(command, arm_idle)
        if self._state is ControllerState.BUSY:
            return None                     # the motion runs until finish()
        if not flag:                        # DONE / REJECTED held until the flag drops
            self._state = ControllerState.READY
            self._active = None
        return None

    def _request(self, command: Command, arm_idle: bool) -> Optional[Command]:
        kind = command.move_type
        via, self._via = self._via, None    # a stored via serves the very next request only
        self._active = command
        self._reason = ""
        if not arm_idle:
            return self._reject("the arm is not ready to move (drives off, e-stop or error)")
        if kind is WireMoveType.CIRC_VIA:
            self._via = command
            self._state = ControllerState.DONE
            self.completed += 1
            return None
        if kind is WireMoveType.CIRC_END:
            if via is None:
                return self._reject("CIRC end point without a stored via point")
            self._active_via = via
        self._state = ControllerState.BUSY
        self.accepted += 1
        return command

    def _reject(self, reason: str) -> None:
        self._state = ControllerState.REJECTED
        self._reason = reason
        self.rejected += 1
        return None

    def finish(self, success: bool, reason: str = "") -> None:
        """The motion started by :meth:`step` ended: reached (DONE) or failed (REJECTED)."""
        if self._state is not ControllerState.BUSY:
            raise ProtocolError("finish() without a motion in progress (state %s)" % self._state.name)
        self._active_via = None
        if success:
            self._state = ControllerState.DONE
            self.completed += 1
        else:
            self._reject(reason or "the motion failed")

    def reset(self) -> None:
        """Program restart: READY, no via, nothing active (the caller stops the arm)."""
        self._stop_seen = False
        self._state = ControllerState.READY
        self._via = None
        self._active = None
        self._active_via = None
        self._reason = ""


# --------------------------------------------------------------------------------- master side

class MasterPhase(enum.Enum):
    SYNC = "sync"                  # after start / reset: flag 0, waiting to see READY
    IDLE = "idle"                  # READY seen with the flag 0: submit() allowed
    WAIT_ACCEPT = "wait_accept"    # flag 1 with the target, waiting for BUSY / DONE / REJECTED
    EXECUTING = "executing"        # BUSY seen, waiting for DONE / REJECTED
    WAIT_RELEASE = "wait_release"  # DONE / REJECTED seen, flag 0, waiting for READY
    RECOVER = "recover"            # target given up (timeout, abort): flag 0, waiting for READY


#: the handshake's phases with a time limit: the phase -> (the MasterHandshake attribute holding
#: the limit [s], the TimedOut's stage, its message: ``target`` in words and ``limit`` filled in)
_TIME_LIMITS = {
    MasterPhase.WAIT_ACCEPT: ("accept_timeout", "accept",
                              "the controller did not accept {target} within {limit:.3g} s (is its program running?)"),
    MasterPhase.EXECUTING: ("_motion_timeout", "motion", "the controller did not finish {target} within {limit:.3g} s"),
    MasterPhase.WAIT_RELEASE: ("release_timeout", "release",
                               "the controller did not return to READY within {limit:.3g} s after the flag was cleared"),
}


@dataclass(frozen=True)
class HandshakeEvent:
    """Something :class:`MasterHandshake` observed about target number ``seq``."""

    seq: int
    target: Command
    time: float
    reason: str = ""
    feedback: Optional[Feedback] = None

    #: True when the target's outcome is settled by this event
    final: ClassVar[bool] = True


@dataclass(frozen=True)
class Accepted(HandshakeEvent):
    """The controller reported BUSY: the motion started."""

    final: ClassVar[bool] = False


@dataclass(frozen=True)
class Done(HandshakeEvent):
    """The controller reported DONE: target reached (or via point stored)."""


@dataclass(frozen=True)
class Rejected(HandshakeEvent):
    """The controller reported REJECTED (or broke the handshake); never re-sent."""

    def error(self) -> TargetRejected:
        return TargetRejected(self.reason, self.target)


@dataclass(frozen=True)
class TimedOut(HandshakeEvent):
    """A time limit passed. ``stage``: "accept" / "motion" (the target is given up, never re-sent)
    or "release" (after DONE / REJECTED the controller did not return to READY: not final, the
    target's outcome was already reported)."""

    stage: str = ""

    @property
    def final(self) -> bool:  # type: ignore[override]
        return self.stage != "release"

    def error(self) -> HandshakeTimeout:
        return HandshakeTimeout(self.reason, self.target, self.stage)


@dataclass(frozen=True)
class Aborted(HandshakeEvent):
    """The master gave the target up (abort(), reset() after a link loss); never re-sent."""


def _seconds(value: Any, name: str, allow_zero: bool = False) -> float:
    what = "a non-negative" if allow_zero else "a positive"
    return validate.number(value, lambda _: HandshakeError("%s must be %s number of seconds, got %r"
                                                           % (name, what, value)), 0.0, lo_open=not allow_zero)


class MasterHandshake:
    """The driver side of the handshake: one target at a time, each requested exactly once.

    Each bus cycle: send :meth:`outputs`, then feed the decoded inputs to :meth:`update` (or None
    when no fresh record arrived; timeouts are still checked). Times come from ``now`` or the
    injected ``clock`` (seconds, monotonic); nothing sleeps.

        SYNC / RECOVER --READY (settled, see below)--> IDLE --submit()--> WAIT_ACCEPT
        WAIT_ACCEPT --BUSY--> EXECUTING (Accepted)      --DONE--> WAIT_RELEASE (Done)
        WAIT_ACCEPT / EXECUTING --DONE / REJECTED--> WAIT_RELEASE (Done / Rejected)
        WAIT_RELEASE --READY--> IDLE
        WAIT_ACCEPT --accept_timeout--> RECOVER (TimedOut "accept")
        EXECUTING --motion_timeout--> RECOVER (TimedOut "motion")
        EXECUTING --READY (no DONE)--> RECOVER (Rejected: the controller broke the handshake)
        WAIT_RELEASE --release_timeout--> RECOVER (TimedOut "release", not final)
        IDLE --anything but READY--> SYNC
        abort(): WAIT_ACCEPT / EXECUTING --> RECOVER (Aborted)     reset(): any --> SYNC
        abort(stop=True): the same, and the flag is 2 (stop) instead of 0 until READY is seen

    Exactly once: the flag is 1 only in WAIT_ACCEPT and EXECUTING, which are entered only by
    :meth:`submit` with a new sequence number, and only from IDLE; IDLE is reached only by seeing
    READY while the flag is 0, after the previous target's answer. So a DONE seen for a target comes
    after a READY that followed the previous target's DONE: it cannot be the previous one's.

    Settling: after start / :meth:`reset`, and after giving a target up before BUSY was seen
    (accept timeout, abort in WAIT_ACCEPT), the controller may still pick up the raised flag late
    (its program read it just before we cleared it). There READY alone proves nothing, so it must
    be seen ``settle_time`` (default: ``accept_timeout``) after the flag was cleared, unless BUSY /
    DONE / REJECTED shows first (then the next READY is after the controller saw the flag at 0).
    Without that, a late pick-up's BUSY / DONE could be taken for the next target's.
    """

    def __init__(self, accept_timeout: float = DEFAULT_ACCEPT_TIMEOUT,
                 release_timeout: float = DEFAULT_RELEASE_TIMEOUT,
                 settle_time: Optional[float] = None,
                 clock: Callable[[], float] = time.monotonic):
        self.accept_timeout = _seconds(accept_timeout, "accept_timeout")
        self.release_timeout = _seconds(release_timeout, "release_timeout")
        self.settle_time = self.accept_timeout if settle_time is None else \
            _seconds(settle_time, "settle_time", allow_zero=True)
        self._clock = clock
        self._phase = MasterPhase.SYNC
        self._need_settle = True                       # a flag 1 may still be picked up late
        self._target: Optional[Command] = None        # the target in flight / last answered
        self._seq = 0                                  # sequence number of _target
        self._motion_timeout = 0.0
        self._stopping = False                          # flag 2 until READY
        self._since: Optional[float] = None            # when the current phase was entered
                                                       # (None: at the first update())
        self.last_feedback: Optional[Feedback] = None
        self.last_event: Optional[HandshakeEvent] = None

    # ----------------------------------------------------------------------- views
    @property
    def phase(self) -> MasterPhase:
        return self._phase

    @property
    def ready(self) -> bool:
        """True when :meth:`submit` would be accepted."""
        return self._phase is MasterPhase.IDLE

    @property
    def in_flight(self) -> Optional[Command]:
        """The target whose flag is raised (WAIT_ACCEPT / EXECUTING), else None."""
        if self._phase in (MasterPhase.WAIT_ACCEPT, MasterPhase.EXECUTING):
            return self._target
        return None

    @property
    def seq(self) -> int:
        """Sequence number of the last submitted target (0: none yet)."""
        return self._seq

    @property
    def phase_since(self) -> Optional[float]:
        """When the current phase was entered (None before the first update())."""
        return self._since

    # ----------------------------------------------------------------------- actions
    def submit(self, command: Command, motion_timeout: float, now: Optional[float] = None) -> int:
        """Raise the flag for ``command`` (its flag is set here); returns its sequence number.
        HandshakeError unless IDLE (READY seen after the flag was cleared, nothing in flight)."""
        if not isinstance(command, Command):
            raise HandshakeError("submit() takes a Command, got %r" % (command,))
        if command.move_type is WireMoveType.NONE:
            raise HandshakeError("submit(): a target needs a move type, got NONE")
        timeout = _seconds(motion_timeout, "motion_timeout")
        if self._phase is not MasterPhase.IDLE:
            raise HandshakeError(self._not_ready_reason())
        t = self._now(now)
        self._seq += 1
        self._target = command.with_request(True)
        self._motion_timeout = timeout
        self._enter(MasterPhase.WAIT_ACCEPT, t)
        return self._seq

    def outputs(self) -> Command:
        """What to send now: the target with the flag 1 while it is in flight; afterwards the same
        target bytes with the flag 0; all zero (Command.idle()) before the first target / after a
        reset."""
        if self._target is None:
            return Command.idle()
        flag = self._phase in (MasterPhase.WAIT_ACCEPT, MasterPhase.EXECUTING)
        if flag:
            return self._target
        if self._stopping:
            return self._target.with_stop()
        return self._target.with_request(False)

    def update(self, feedback: Optional[Feedback], now: Optional[float] = None) -> Optional[HandshakeEvent]:
        """Advance on a decoded feedback record (None: nothing new, check the timers only)."""
        t = self._now(now)
        if self._since is None:
            self._since = t
        event: Optional[HandshakeEvent] = None
        if feedback is not None:
            if not isinstance(feedback, Feedback):
                raise HandshakeError("update() takes a Feedback or None, got %r" % (feedback,))
            self.last_feedback = feedback
            event = self._on_feedback(feedback, t)
        if event is None:
            event = self._check_timers(t)
        if event is not None:
            self.last_event = event
        return event

    def abort(self, reason: str = "aborted", now: Optional[float] = None, stop: bool = False
              ) -> Optional[Aborted]:
        """Clear the flag at once. A target in flight is given up (Aborted, never re-sent).
        ``stop=False``: the controller may still finish a motion it started. ``stop=True``: the
        flag becomes 2 (stop) until the controller is READY again, so it halts the motion (its
        answer is then REJECTED); also sent when nothing is in flight but a motion may run.
        Returns the Aborted event, or None when nothing was in flight."""
        t = self._now(now)
        if stop and self._target is not None and self._phase is not MasterPhase.IDLE:
            self._stopping = True
        if self._phase not in (MasterPhase.WAIT_ACCEPT, MasterPhase.EXECUTING):
            return None
        assert self._target is not None
        event = Aborted(self._seq, self._target, t, reason, self.last_feedback)
        self._recover(t)
        self.last_event = event
        return event

    def reset(self, reason: str = "link lost", now: Optional[float] = None) -> Optional[Aborted]:
        """Forget everything after a link loss: outputs all zero, a target in flight is Aborted
        (returned, never re-sent), and READY must be seen again before the next submit()."""
        t = self._now(now)
        event = None
        if self._phase in (MasterPhase.WAIT_ACCEPT, MasterPhase.EXECUTING):
            assert self._target is not None
            event = Aborted(self._seq, self._target, t, reason, self.last_feedback)
            self.last_event = event
        self._target = None
        self.last_feedback = None
        self._need_settle = True
        self._enter(MasterPhase.SYNC, t)
        return event

    # ----------------------------------------------------------------------- internals
    def _now(self, now: Optional[float]) -> float:
        return float(self._clock() if now is None else now)

    def _enter(self, phase: MasterPhase, t: float) -> None:
        self._phase = phase
        self._since = t
        if phase in (MasterPhase.IDLE, MasterPhase.SYNC):
            self._stopping = False

    def _recover(self, t: float) -> None:
        """Give the target in flight up: flag 0, wait for READY. Before BUSY was seen the
        controller may still pick the flag up late, so READY must then last ``settle_time``."""
        self._need_settle = self._phase is MasterPhase.WAIT_ACCEPT
        self._enter(MasterPhase.RECOVER, t)

    def _not_ready_reason(self) -> str:
        last = self.last_feedback.state.name if self.last_feedback is not None else "nothing yet"
        if self._phase in (MasterPhase.WAIT_ACCEPT, MasterPhase.EXECUTING):
            assert self._target is not None
            return "not ready: target %d (%s) is still in flight (%s)" % (
                self._seq, self._target.describe(), self._phase.value)
        return "not ready: waiting for the controller to report READY with the flag cleared " \
               "(phase %s, last state: %s)" % (self._phase.value, last)

    def _on_feedback(self, fb: Feedback, t: float) -> Optional[HandshakeEvent]:
        phase, state = self._phase, fb.state
        if phase is MasterPhase.WAIT_RELEASE:
            if state is ControllerState.READY:        # it saw our flag 0 after its answer
                self._enter(MasterPhase.IDLE, t)
            return None
        if phase in (MasterPhase.SYNC, MasterPhase.RECOVER):
            if state is not ControllerState.READY:
                self._need_settle = False             # a late pick-up (or old answer) shows: the
            elif not self._need_settle or t - self._since >= self.settle_time:  # next READY is real
                self._enter(MasterPhase.IDLE, t)
            return None
        if phase is MasterPhase.IDLE:
            if state is not ControllerState.READY:   # not our doing: wait for READY again
                self._need_settle = False
                self._enter(MasterPhase.SYNC, t)
            return None
        assert self._target is not None
        if state is ControllerState.DONE:
            self._enter(MasterPhase.WAIT_RELEASE, t)
            return Done(self._seq, self._target, t, "", fb)
        if state is ControllerState.REJECTED:
            self._enter(MasterPhase.WAIT_RELEASE, t)
            return Rejected(self._seq, self._target, t,
                            "the controller rejected %s (status: %s)"
                            % (self._target.describe(), fb.status.describe()), fb)
        if phase is MasterPhase.WAIT_ACCEPT:
            if state is ControllerState.BUSY:
                self._enter(MasterPhase.EXECUTING, t)
                return Accepted(self._seq, self._target, t, "", fb)
            return None                              # READY: the flag is not seen yet
        if state is ControllerState.READY:           # EXECUTING and READY without DONE
            self._recover(t)
            return Rejected(self._seq, self._target, t,
                            "the controller returned to READY without reporting DONE or REJECTED "
                            "(program restarted?); the target is not re-sent", fb)
        return None                                  # EXECUTING, BUSY

    def _check_timers(self, t: float) -> Optional[HandshakeEvent]:
        """TimedOut once the phase has lasted longer than its time limit (:data:`_TIME_LIMITS`):
        the target is given up (:meth:`_recover`)."""
        timer = _TIME_LIMITS.get(self._phase)
        if timer is None:
            return None
        limit_name, stage, message = timer
        limit = getattr(self, limit_name)
        if t - (t if self._since is None else self._since) <= limit:
            return None
        assert self._target is not None
        self._recover(t)
        return TimedOut(self._seq, self._target, t, message.format(target=self._target.describe(), limit=limit),
                        self.last_feedback, stage)


# ---------------------------------------------------------------------------------- the seam

class ProtocolV1(Protocol):
    """Protocol v1 as one object (:mod:`vr_driver.protocol.base`): the thesis' 14-byte records."""

    name = "v1"
    version = 1
    record_length = RECORD_SIZE
    move_commands = move_targets
    streams = False
    joint_targets = False
    reports_joints = False
    controller_io = False
    confirm_records = True          # no integrity check of its own: the two-telegram rule
    byte_order_matters = True
    pose_resolution = (1.0, 1.0)
    #: whole-mm / whole-degree targets solved again by the controller put a joint up to ~1.5 deg
    #: off a planned joint point (measured over random configurations): the scalar defaults (3 deg
    #: goal / 4 deg path, for a caller without the arm's kinematics) and the thinning without them
    #: (driver.motion.trajectories.V1_WIRE_ERROR). With the kinematics the tolerances and the thinning
    #: use the error at each configuration instead (driver.joints.resolution: 0.06 deg for joint_1 at
    #: home, several degrees for joint_4 / joint_6 near joint_5 = 0)
    target_error = math.radians(1.5)
    summary = "the thesis' Cartesian targets in whole mm / deg, one at a time (request / done handshake)"

    def encode(self, command: Command, byte_order: Any = ByteOrder.LITTLE) -> bytes:
        return command.encode(byte_order)

    def idle_command(self) -> Command:
        return Command.idle()

    def idle_record(self, byte_order: Any = ByteOrder.LITTLE) -> bytes:
        return Command.idle().encode(byte_order)

    def stop_record(self, record: bytes, byte_order: Any = ByteOrder.LITTLE) -> bytes:
        """The same target bytes with flag 2 (a controlled stop while the program is BUSY; ignored
        otherwise); a record that is not a command (all zero) stays as it is."""
        command = Command.decode(record, byte_order)
        return command.with_stop().encode(byte_order) if record != self.idle_record(byte_order) else record

    def decode_feedback(self, data: Any, byte_order: Any = ByteOrder.LITTLE) -> Feedback:
        return Feedback.decode(data, byte_order)

    def program_speed(self, move_type: Any, movep: float, movel: float) -> float:
        return program_speed(move_type, movep, movel)

    def decode_command(self, data: Any, byte_order: Any = ByteOrder.LITTLE) -> Command:
        return Command.decode(data, byte_order)


V1 = ProtocolV1()
